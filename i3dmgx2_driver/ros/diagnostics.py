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
The driver's health on ``/diagnostics``, once a second.

:class:`DiagnosticsPublisher` ticks once a second: it reads the node's
counters, keeps what the previous tick saw (to measure rates and growth
over the last period), builds the statuses (diagnostic_statuses.py) and
publishes one ``DiagnosticArray``. ``diagnostic_updater`` is not used: it is
not available as a wheel, and the few lines it would save are these.

The tick runs in a thread of its own (``gx2-diagnostics``), not as an
executor timer: a timer's callback wakes the multi-threaded executor three
times (ready, taken, done) and a worker besides, which was most of what the
idle node woke for beside the reader (docs/cpu.md). The thread sleeps
between ticks and keeps ticking during a long service call.
"""

from collections.abc import Callable
import threading
import time
import traceback
from typing import Any
import weakref

from diagnostic_msgs.msg import DiagnosticArray
from rclpy._rclpy_pybind11 import RCLError
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node

from .diagnostic_statuses import (calibration_status, connection_status, device_status,
                                  lifecycle_status, parser_status, radio_status, Status,
                                  stream_status, StreamPeriod, time_status, to_message)
from .mag_calibration import is_loaded
from .publishers import create_publisher
from ..device.record_rate import RateMeter
from ..device.status import DeviceStatus, RadioStats, State

#: Period of the diagnostics (s).
PERIOD = 1.0
#: How long a stop waits for a tick under way (s).
STOP_WAIT = 0.5


class DiagnosticsPublisher:
    """
    Publish the driver's diagnostics on ``/diagnostics`` every :data:`PERIOD` s.

    ``driver`` returns the DriverCore to report on (of the device side only
    its supervisor's one ``DeviceStatus`` snapshot is read; its stream stats,
    clock status, services, temperature and capture too, never changed), or
    None while there is none (a managed node before configure).
    ``lifecycle``, for a managed node, returns its lifecycle state's label,
    reported first. :meth:`stop` ends its thread (before the node is
    destroyed).
    ``sensor``, one of several sensors' names, goes into every status name
    (``i3dmgx2_driver: left_arm: stream``, the node's name first): one
    publisher per sensor.
    """

    def __init__(self, node: Node, driver: Callable[[], Any],
                 lifecycle: Callable[[], str] | None = None, period: float = PERIOD,
                 sensor: str = '') -> None:
        self.node = node
        # The node's own name first, so that two drivers side by side are told apart.
        self.prefix = f'{node.get_name()}: ' + (f'{sensor}: ' if sensor else '')
        self.period = period
        self._driver = driver
        self._lifecycle = lifecycle
        #: The core the last tick reported on (weakly: a core dropped at cleanup goes).
        self._core: Callable[[], Any] = lambda: None
        self._last_tick = time.monotonic()
        self._forget()
        self.publisher = create_publisher(node, DiagnosticArray, '/diagnostics', 10)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='gx2-diagnostics', daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """End the ticks; a tick under way finishes first (it takes milliseconds)."""
        self._stop.set()
        if self._thread is not threading.current_thread():
            self._thread.join(STOP_WAIT)

    def _run(self) -> None:
        due = time.monotonic() + self.period
        failed = False
        while not self._stop.wait(max(due - time.monotonic(), 0.0)):
            due = max(due + self.period, time.monotonic())
            try:
                self.tick()
            except InvalidHandle:
                return  # the node was destroyed without stop(): nothing is left to report to
            except Exception:  # noqa: BLE001 - said once; the stream goes on without it
                if not failed:
                    failed = True
                    self.node.get_logger().error(f'diagnostics failed:\n{traceback.format_exc()}')

    def _forget(self) -> None:
        """Start the per-period comparisons afresh (a new core counts from zero)."""
        self._rate = RateMeter()
        #: What the last tick saw: records published and lost, good frames, parser, radio.
        self._last: tuple[int, int, int, dict[str, int] | None, RadioStats | None] = (
            0, 0, 0, None, None)

    def collect(self, device: DeviceStatus | None = None) -> list[Status]:
        """
        Build every status from one snapshot of the device (advances the period).

        ``device`` is the supervisor's snapshot for this tick (taken here if
        not given): every device-side figure of one tick comes from it, so
        that no two statuses can disagree about the same moment.
        """
        core = self._driver()
        statuses = []
        if device is None and core is not None:
            device = core.supervisor.status()
        if self._lifecycle is not None:
            statuses.append(lifecycle_status(
                self._lifecycle(), device.state if device is not None else None))
        if core is not self._core():
            self._core = weakref.ref(core) if core is not None else (lambda: None)
            self._forget()
        now = time.monotonic()
        period, self._last_tick = now - self._last_tick, now
        if core is None or device is None:
            return statuses
        cfg, stats, parser = core.config, core.records.stats, device.parser
        published, lost, good_frames = stats.published, stats.lost, parser.get('good_frames', 0)
        last_published, last_lost, last_good_frames, last_parser, last_radio = self._last
        # Disconnected: show the last link's numbers.
        radio = device.radio if device.radio is not None else last_radio
        seen = StreamPeriod(
            label=core.stream.label, received=published - last_published, period=period,
            measured_hz=self._rate.update(published, stats.last_time,
                                          device.state is State.STREAMING),
            silent_for=time.time() - stats.last_time if stats.last_time else None,
            published=published, lost=lost, lost_in_period=lost - last_lost,
            device_resets=stats.device_resets, other_records=device.other_records,
            mag_published=stats.published_on.get('mag', 0),
            operation=core.device_services.operation)
        self._last = (published, lost, good_frames, parser, radio)
        bias = core.device_services.gyro_bias
        return [*statuses,
                connection_status(device, core.raw_capture.describe(),
                                  core.fault_capture.describe()),
                stream_status(device, seen),
                radio_status(device.wireless, radio, good_frames > last_good_frames),
                parser_status(parser, last_parser, device.strays),
                device_status(device, core.sensor.address, core.temperature.latest,
                              core.temperature.unavailable),
                time_status(cfg.time_source, core.records.clock_status(), now,
                            time_offset=cfg.time_offset),
                calibration_status(bias.last_capture, bias.good_capture, time.time(),
                                   is_loaded(cfg.messages_for(core.sensor)))]

    def tick(self) -> None:
        """Build and publish one DiagnosticArray (the timer callback)."""
        array = DiagnosticArray()
        array.header.stamp = self.node.get_clock().now().to_msg()
        core = self._driver()
        device = core.supervisor.status() if core is not None else None
        info = device.info if device is not None else None
        # The hardware id: the device's serial number once known.
        serial = info.serial_number if info is not None and info.serial_number else ''
        array.status = to_message(self.collect(device), serial, self.prefix)
        try:
            self.publisher.publish(array)
        except RCLError:
            pass  # ROS is shutting down: nobody is left to tell
