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
The managed driver node (REP-2004): a bringup manager brings the sensor up in steps.

Same parameters, topics, services and diagnostics as the plain node, from
the same :class:`~.driver_core.DriverCore`; what differs is when things
happen. Each transition is one call into the core, bounded in time, and
logged in one line:

- configure: check the parameters (a bad one fails with the plain node's
  words; a name the node does not know is warned about once, at start) and
  the port path (one that exists but is no serial port fails with the plain
  node's words), make the core (lifecycle publishers: silent until active),
  open the port exclusively, quiet the device, read its identity, set the
  data rate if asked. A missing or busy port, or a silent sensor (with what
  the line carries instead of answers), fails the transition with the
  reason and leaves nothing open; configure again later.
- activate: start the stream and return once records arrive; from then on
  stalls and unplugs are recovered as the plain node recovers them, and
  the node stays active throughout (diagnostics say it is recovering).
- deactivate: stop publishing and the stream (0xFA); the port stays open;
  the services answer that the node is inactive.
- cleanup: close the port (another process may open it at once) and remove
  the core's services; the publishers stay for the next configure
  (:func:`~.publishers.create_publishers` says why).
- shutdown, from any state: stop the stream, close the port; the process
  then exits 0. SIGINT and SIGTERM do the same through the shutdown
  transition, within 2 s, even in the middle of a configure.

``/diagnostics`` runs in every state and reports the lifecycle state first.

With several sensors (``addresses``) every step is taken for each sensor at
once (DriverSet, driver_core.py): configure fails only if no listed sensor answers, and
says which did not; a sensor that did not answer, or whose stream does not
start at activate, is retried in the background while the others stream
(as the plain node retries it); activate fails only if no sensor streams.
"""

from collections.abc import Callable
import functools
import gc
import sys
import threading
import time
import traceback
from typing import Any

from rclpy._rclpy_pybind11 import RCLError
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn

from .diagnostics import DiagnosticsPublisher
from .driver_core import DriverCore, DriverSet, load_config
from .main import run
from .parameters import declare_parameters, driver_config, ParameterError
from .publishers import create_publishers, Publishers
from .. import lifetime
from ..device.port import check_port_path, PortUnusable

SUCCESS = TransitionCallbackReturn.SUCCESS
FAILURE = TransitionCallbackReturn.FAILURE
ERROR = TransitionCallbackReturn.ERROR
#: How long a signal waits for a transition under way to end (s); the
#: device was cut off first, so it ends within milliseconds.
TRANSITION_WAIT = 1.0
#: How long a signal waits for every sensor's supervisor to stop (s); each
#: stop is bounded by its own joins (about 1.5 s), the process by its deadline.
STOP_WAIT = 2.0
#: How long the process stays up after a signal's shutdown transition (s), so
#: that its transition events reach the subscribers before the middleware
#: goes: a sample still in shared memory when the writer's process exits is
#: lost, and a bringup manager would never see ``finalized``.
EVENT_GRACE = 0.25

Transition = Callable[[Any, LifecycleState], TransitionCallbackReturn]


def transition(name: str) -> Callable[[Transition], Transition]:
    """
    Run a transition callback under the node's transition lock; log a crash.

    rclpy turns an exception in a callback into ERROR without a word; here
    the traceback is logged first, so that the error processing that follows
    has a cause anyone can read.
    """
    def wrap(method: Transition) -> Transition:
        @functools.wraps(method)
        def run(self: 'LifecycleDriverNode', state: LifecycleState) -> TransitionCallbackReturn:
            with self._transition_lock:
                try:
                    return method(self, state)
                except Exception:  # noqa: B902 - logged, then rclpy's error processing
                    self.get_logger().error(
                        f'{name} failed unexpectedly:\n{traceback.format_exc()}')
                    return ERROR
        return run
    return wrap


class LifecycleDriverNode(LifecycleNode):
    """The 3DM-GX2 driver as a managed node; the cores exist from configure to cleanup."""

    def __init__(self, node_name: str = 'i3dmgx2_driver', **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        #: Every sensor's core, from a successful configure to cleanup or shutdown.
        self.drivers: DriverSet | None = None
        #: Made at the first configure and kept (create_publishers says why), per sensor.
        self._data_publishers: list[Publishers] | None = None
        self._transition_lock = threading.RLock()
        self._finished = threading.Event()
        #: Called once finished (main.run wakes its thread with it).
        self.on_done: Callable[[], None] = lambda: None
        #: Set by a signal's shutdown(): a transition under way does not start the device again.
        self._stopping = threading.Event()
        try:
            # Declared now so that ``ros2 param`` shows them before configure, and
            # names the node does not know are said once; configure checks them
            # again and reports what is wrong.
            names = [s.name for s in load_config(self).sensors]
        except ParameterError:
            names = []
        several = len(names) > 1
        self.diagnostics = [
            DiagnosticsPublisher(self, lambda i=i: self._core(i),
                                 lifecycle=self.state_label if i == 0 else None,
                                 sensor=name if several else '')
            for i, name in enumerate(names if several else [''])]

    @property
    def core(self) -> DriverCore | None:
        """Return the (first) sensor's core while configured, else None."""
        return self._core(0)

    def _core(self, index: int) -> DriverCore | None:
        drivers = self.drivers
        return drivers.cores[index] if drivers is not None else None

    # -- state ---------------------------------------------------------------

    def state_label(self) -> str:
        """Return the label of the current lifecycle state ('unconfigured', 'active', ...)."""
        # rclpy (Jazzy) has no public getter; the state machine is rcl's own.
        return self._state_machine.current_state[1]

    @property
    def finished(self) -> bool:
        """Whether the shutdown transition has run: the process may exit."""
        return self._finished.is_set()

    def _refusal(self) -> str:
        """Why the services must refuse now ('' when active)."""
        label = self.state_label()
        return '' if label == 'active' else f'the node is {label}: activate it first'

    # -- transitions -----------------------------------------------------------

    @transition('configure')
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Check the parameters, open the port, bring the device to a known state."""
        start = time.monotonic()
        log = self.get_logger()
        try:
            config = driver_config(declare_parameters(self))
            check_port_path(config.device.port)  # the words of the plain node's exit 2
            if self._data_publishers is None:  # (a bad qos_overrides parameter raises)
                self._data_publishers = [create_publishers(self, config, lifecycle=True, sensor=s)
                                         for s in config.sensors]
        except (ParameterError, PortUnusable) as exc:
            log.error(f'configure failed: {exc}')
            return FAILURE
        self.drivers = drivers = DriverSet(self, config, publishers=self._data_publishers,
                                           publishing=False, refusal=self._refusal)
        if self._stopping.is_set():
            # A signal came while the set was made, before shutdown() could see it.
            self._release()
            return FAILURE
        failed = drivers.each(lambda core: core.supervisor.connect())
        # A sensor that can never give what is asked (its firmware lacks the stream):
        # the words of the plain node's exit 2, whatever the other sensors answered.
        never = [exc for _, exc in failed if isinstance(exc, PortUnusable)]
        if never or len(failed) == len(drivers.cores):
            self._release()
            why = never[0] if never else failed[0][1] if not drivers.several else (
                'no listed sensor answers: ' + '; '.join(
                    f'node {core.sensor.address}: {exc}' for core, exc in failed))
            log.error(f'configure failed: {why}')
            return FAILURE
        for core, exc in failed:
            log.warning(f'configure: node {core.sensor.address} does not answer ({exc}); '
                        f'the others go on, and it is retried once active')
        ready = [core for core in drivers.cores if core not in {c for c, _ in failed}]
        expected_hz = ready[0].supervisor.status().expected_rate_hz
        rate = f', {expected_hz:.1f} Hz' if expected_hz else ''
        nodes = ', '.join(str(core.sensor.address) for core in ready)
        log.info(f'configure: {config.device.port} open, node{"s" if len(ready) > 1 else ""} '
                 f'{nodes} ready{rate} ({time.monotonic() - start:.2f} s)')
        return SUCCESS

    @transition('activate')
    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Enable the publishers, start the stream; fail if no record comes."""
        start = time.monotonic()
        drivers = self.drivers
        # After a signal stopped the device meanwhile, it stays stopped.
        if self._stopping.is_set() or super().on_activate(state) != SUCCESS or drivers is None:
            return FAILURE
        for core in drivers.cores:
            core.records.forget_last_sample()  # the pause since the last activation is no loss
        drivers.set_publishing(True)
        failed = drivers.each(lambda core: core.supervisor.start_streaming())
        if len(failed) == len(drivers.cores):
            drivers.set_publishing(False)
            if drivers.several:
                drivers.each(lambda core: core.supervisor.stop_streaming())
            super().on_deactivate(state)
            self.get_logger().error('activate failed: ' + '; '.join(
                (f'node {core.sensor.address}: ' if drivers.several else '') + str(exc)
                for core, exc in failed))
            return FAILURE
        for core, exc in failed:
            self.get_logger().warning(
                f'activate: node {core.sensor.address} does not stream ({exc}): retried '
                f'in the background while the others stream')
            core.supervisor.start_retrying()
        self.get_logger().info(f'activate: streaming ({time.monotonic() - start:.2f} s)')
        return SUCCESS

    @transition('deactivate')
    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop publishing and the stream (0xFA); keep the port."""
        start = time.monotonic()
        drivers = self.drivers
        if drivers is not None:
            # Before the publishers go inactive: a record read in between would
            # otherwise be counted as published while the inactive publisher drops it.
            drivers.set_publishing(False)
        super().on_deactivate(state)
        if drivers is not None:
            drivers.each(lambda core: core.supervisor.stop_streaming())
            for core in drivers.cores:
                core.device_services.wait_idle(1.0)
        self.get_logger().info(f'deactivate: stream stopped (0xFA), port kept open '
                               f'({time.monotonic() - start:.2f} s)')
        return SUCCESS

    @transition('cleanup')
    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the port and drop the core."""
        self._release('cleanup')
        return SUCCESS

    @transition('shutdown')
    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the stream and close the port, whatever the state; then the process exits."""
        self._release(f'shutdown (from {state.label})')
        self._finished.set()
        self.on_done()
        return SUCCESS

    @transition('error processing')
    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release everything after a failed transition: back to unconfigured."""
        self._release(f'error processing (after {state.label})')
        return SUCCESS

    def _release(self, what: str | None = None) -> None:
        """Stop the core and remove it; log one line saying so when ``what`` is given."""
        drivers, self.drivers = self.drivers, None
        start = time.monotonic()
        if drivers is None:
            if what:
                self.get_logger().info(f'{what}: nothing open')
            return
        drivers.set_publishing(False)
        published = sum(core.records.stats.published for core in drivers.cores)
        drivers.shutdown(report=False)
        drivers.destroy()
        del drivers
        # The core just dropped is held in reference cycles (its callbacks, threads and
        # links refer back to it), which only a full collection frees; with the start-up
        # heap frozen (realtime.py) one comes seldom, so each cleanup's core waited for it:
        # a managed node's memory rose by thousands of objects a cycle, then fell in steps.
        gc.collect()
        if what:
            self.get_logger().info(
                f'{what}: stream stopped, port closed, {published} records published '
                f'({time.monotonic() - start:.2f} s)')

    # -- process end -------------------------------------------------------------

    def shutdown(self) -> None:
        """
        On SIGINT or SIGTERM: release the device at once, then take the shutdown transition.

        The device goes first, without waiting for the transition lock: a
        configure or activate under way then fails within milliseconds
        instead of finishing its retries. The shutdown transition follows
        (so that ``transition_event`` tells a bringup manager), unless it
        has run already. The diagnostics end first, whatever the state.
        """
        for diagnostics in self.diagnostics:
            diagnostics.stop()
        if self._finished.is_set():
            return
        self._stopping.set()
        drivers = self.drivers
        if drivers is not None:
            drivers.set_publishing(False)
            drivers.each(lambda core: core.supervisor.stop(), timeout=STOP_WAIT)
        if self._transition_lock.acquire(timeout=TRANSITION_WAIT):
            try:
                if not self._finished.is_set():
                    self.trigger_shutdown()
                    time.sleep(EVENT_GRACE)
            except RCLError:
                pass  # in a transition state: release below without the state machine
            finally:
                self._transition_lock.release()
        if not self._finished.is_set():
            self._release('shutdown')
            self._finished.set()
            self.on_done()


def main(args: list[str] | None = None) -> int:
    """Entry point of ``ros2 run i3dmgx2_driver lifecycle_node``: run until shut down."""
    lifetime.die_with_parent()
    return run(LifecycleDriverNode, args)


if __name__ == '__main__':
    sys.exit(main())
