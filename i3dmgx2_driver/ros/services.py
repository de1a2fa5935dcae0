# Copyright 2026 The i3dmgx2_driver Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
The node's services: their names, types and callback groups, requests to answers.

``~/capture_gyro_bias``, ``~/store_gyro_bias`` and ``~/self_test`` are
std_srvs/Trigger (a yes or no and a text); the self test is also served as
``~/diagnostic_self_test``, a diagnostic_msgs/SelfTest, the ROS message for
exactly this (the sensor's serial number, passed, one DiagnosticStatus per
step), from the same steps. The operations themselves know no ROS: the gyro
bias capture in device/gyro_bias.py, the self test in device/self_test.py;
an accepted capture's parameter file is ros/calibration_file.py.

Each needs the device to itself, so they run through the supervisor's
``run_paused``: the stream stops, the exchange runs, the stream restarts.
The reader thread keeps running throughout (it claims the replies), so
nothing waits on the executor but the service call itself; the services sit
in their own callback group, so that with a multi-threaded executor the
diagnostics keep ticking during a 30-second capture. Only one device
operation runs at a time; a second call is refused at once, not queued.

Last, in its own section, ``~/save_capture`` (:class:`SaveCaptureService`):
the fault capture's last seconds written on demand. It borrows nothing from
the device, so it is not one of the operations above.
"""

from collections.abc import Callable
import threading
from typing import Any

from diagnostic_msgs.srv import SelfTest
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from std_srvs.srv import Trigger

from .calibration_file import write_calibration_file
from .diagnostic_statuses import ERROR, OK, Status, to_message
from .parameter_table import CALIBRATION_FILE, GYRO_BIAS, GYRO_BIAS_SAMPLING_MS
from .parameters import declared_value
from ..capture.fault_capture import FaultCapture
from ..device.gyro_bias import GyroBiasCapture
from ..device.operation import Device
from ..device.self_test import format_report, SelfTestRun, Step
from ..device.status import State

#: How often the capture at start looks whether the stream runs yet (s).
STREAM_LOOK_S = 0.1


# -- the device operations' services -----------------------------------------------

def _trigger(answer: Callable[..., tuple[bool, str]], *args: Any
             ) -> Callable[..., Trigger.Response]:
    """Serve ``answer(*args)``, a (success, message), as a std_srvs/Trigger callback."""
    def callback(request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = answer(*args)
        return response
    return callback


class DeviceServices:
    """
    The ``~/capture_gyro_bias``, ``~/store_gyro_bias`` and ``~/self_test`` services.

    ``node`` provides the services, the logger and the
    ``gyro_bias_sampling_ms`` parameter; ``device`` the status and the
    exclusive operations; ``published()`` returns (records published, read
    time of the last), for the self test's rate; ``forget_last_sample()``
    keeps a pause from counting as lost records; ``capture_on_start`` asks
    for one capture once streaming. ``refusal``, if given, returns why a
    call must be refused now ('' to serve it): a managed node that is not
    active answers so at once. ``calibrated(flag)``, if given, is told
    whether the device uses a good gyro bias after every capture that
    reached the device (``~/is_calibrated``). ``prefix`` goes before the
    services' names (``~/<name>/`` for each of several sensors). With one
    sensor, an accepted capture is written to the ``calibration_file``
    parameter's file when it names one, and a configured ``gyro_bias`` (the
    dialogue writes it at every start) makes the device calibrated from the
    start.
    """

    def __init__(self, node: Node, device: Device, published: Callable[[], tuple[int, float]],
                 forget_last_sample: Callable[[], None], capture_on_start: bool = False,
                 refusal: Callable[[], str] | None = None,
                 calibrated: Callable[[bool], None] | None = None,
                 prefix: str = '~/') -> None:
        self.node = node
        self._calibrated = calibrated or (lambda flag: None)
        self._device = device
        self._refusal = refusal or (lambda: '')
        self._log = node.get_logger()
        self._busy = threading.Lock()
        self._stop = threading.Event()
        #: What is running now ('' when idle), for diagnostics.
        self.operation = ''
        #: The capture (and what the last ones came to), and the self test.
        self.gyro_bias = GyroBiasCapture(device, forget_last_sample, self._calibrated, self._log)
        self.self_test_run = SelfTestRun(device, published, forget_last_sample, self._stop,
                                         self._log)
        group = MutuallyExclusiveCallbackGroup()
        #: Every service made, so that destroy() removes what was made, whatever it is. Each
        #: Trigger runs its operation one at a time: the gyro bias capture (0xCD, the stream
        #: paused), the store of the last accepted one on the sensor (0xD0), the self test
        #: (all steps passed, one line per step).
        self.services = [
            node.create_service(Trigger, f'{prefix}{name}', _trigger(self._exclusive, what, body),
                                callback_group=group)
            for name, what, body in (('capture_gyro_bias', 'gyro bias capture', self._capture),
                                     ('store_gyro_bias', 'gyro bias store', self.gyro_bias.store),
                                     ('self_test', 'self test', self._self_test))]
        self.services.append(node.create_service(
            SelfTest, f'{prefix}diagnostic_self_test', self._on_diagnostic_self_test,
            callback_group=group))
        #: One sensor's node: the calibration file and a known bias are its (parameters.py).
        self._single = prefix == '~/'
        if self._single and declared_value(self.node, GYRO_BIAS):
            self._calibrated(True)
        if capture_on_start:
            threading.Thread(target=self._capture_on_start, name='gx2-bias-on-start',
                             daemon=True).start()

    def stop(self) -> None:
        """Stop waiting (the capture at start, the rate window); the link aborts the rest."""
        self._stop.set()

    def destroy(self) -> None:
        """Stop, and remove the services from the node (the managed node's cleanup)."""
        self.stop()
        for service in self.services:
            self.node.destroy_service(service)

    def wait_idle(self, timeout: float) -> bool:
        """
        Wait until no operation runs (after the supervisor stopped); True if none does.

        At shutdown, so that a call cut short by the link's abort still gets
        its answer out before the node (and its service) is destroyed.
        """
        if idle := self._busy.acquire(timeout=timeout):
            self._busy.release()
        return idle

    # -- service callbacks (executor) ---------------------------------------

    def _on_diagnostic_self_test(self, request: SelfTest.Request,
                                 response: SelfTest.Response) -> SelfTest.Response:
        ran, steps = self._exclusive('self test', lambda: (True, self.self_test_run.steps()))
        steps = steps if ran else [Step('self test', False, steps)]  # refused: one failed step
        info = self._device.status().info
        response.id = info.serial_number if info is not None and info.serial_number else ''
        response.passed = bytes((all(step.passed for step in steps),))
        response.status = to_message(
            [Status(OK if step.passed else ERROR, step.name, step.detail,
                    (('result', step.verdict),)) for step in steps],
            response.id, f'{self.node.get_name()}: ')
        return response

    # -- operations -----------------------------------------------------------

    def _exclusive(self, name: str, body: Callable[[], tuple[bool, Any]]) -> tuple[bool, Any]:
        """Run one operation at a time; refuse at once when another runs."""
        if refusal := self._refusal():
            return False, f'refused: {refusal}'
        if not self._busy.acquire(blocking=False):
            return False, f'refused: {self.operation or "another operation"} is in progress'
        self.operation = name
        try:
            return body()
        finally:
            self.operation = ''
            self._busy.release()

    def _capture(self) -> tuple[bool, str]:
        ok, message = self.gyro_bias.run(int(declared_value(self.node, GYRO_BIAS_SAMPLING_MS)))
        path = declared_value(self.node, CALIBRATION_FILE) if self._single else ''
        if ok and path:
            bias = self.gyro_bias.good_capture.bias
            try:
                write_calibration_file(path, self.node.get_fully_qualified_name(), bias)
            except OSError as exc:
                note = f'calibration_file {path} not written: {exc}'
                self._log.error(note)
                return False, f'{message}; but {note}'
            note = (f'written to {path} (gyro_bias): load it with --params-file {path} at '
                    f'the next start')
            self._log.info(f'gyro bias {note}')
            message = f'{message}; {note}'
        return ok, message

    def _capture_on_start(self) -> None:
        """Wait for the first streaming start, then capture once (own thread)."""
        while self._device.status().state is not State.STREAMING:
            if self._stop.wait(STREAM_LOOK_S):
                return
        ok, message = self._exclusive('gyro bias capture', self._capture)
        if not ok:
            self._log.warning(f'capture_gyro_bias_on_start: {message}')

    def _self_test(self) -> tuple[bool, str]:
        steps = self.self_test_run.steps()
        return all(step.passed for step in steps), format_report(steps)


# -- ~/save_capture: the fault capture's last seconds, on demand ------------------------

class SaveCaptureService:
    """
    ``~/save_capture`` (std_srvs/Trigger): write the fault capture's last seconds now.

    One per node (the capture is the port's, whichever sensors share it).
    The reply's message is the file's path, or why none was written (the
    fault capture off, nothing read yet, the directory not writable). Its
    own callback group: writing a few hundred kilobytes never waits for a
    30 s gyro bias capture, nor holds one up.
    """

    def __init__(self, node: Node, capture: FaultCapture) -> None:
        self._node = node
        self._capture = capture
        self.service = node.create_service(Trigger, '~/save_capture', _trigger(self._save),
                                           callback_group=MutuallyExclusiveCallbackGroup())

    def _save(self) -> tuple[bool, str]:
        try:
            path = self._capture.save('request')
        except (OSError, ValueError) as exc:
            return False, f'no capture written: {exc}'
        self._node.get_logger().info(f'capture saved on request: {path}')
        return True, path

    def destroy(self) -> None:
        """Remove the service from the node (a managed node's cleanup)."""
        self._node.destroy_service(self.service)
