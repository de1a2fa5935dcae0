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
The driver behind both executables: device records in, sensor_msgs out, on time.

:class:`DriverCore` is everything the driver does for one sensor: the
publishers, the message factory, stamping and loss counting (its
:class:`~.record_publisher.RecordPublisher`), the device supervisor, the
services and the temperature poller. :class:`DriverSet` is every sensor the
node serves, each a core, on one port, with the port's raw capture and its
fault capture (the last seconds, written when a fault is seen; the
``~/save_capture`` service). It lives
on an rclpy node it does not own: the plain node (``imu_node.py``) makes one
at start and starts its supervisors at once; the managed node
(``lifecycle_node.py``) makes one at each configure, with lifecycle
publishers, drives the supervisors' phases from its transitions and
destroys the set at cleanup. Neither holds a copy of this code. Others use
a core's parts themselves (``core.records``, ``core.supervisor``,
``core.device_services``): the core forwards nothing.

The supervisor's reader thread calls the core's
:meth:`~.record_publisher.RecordPublisher.on_record` for every record of
the stream (the link tells which), which stamps it, packs its messages and
publishes at once. The
executor is left free for parameters, services and diagnostics, and nothing
it does can delay a sample.

With one sensor (``address``) the set holds one core that opens its port
itself, exactly as the driver always did: nothing on its hot path changes.
With several (``addresses``) the cores share one
:class:`~..device.shared_port.SharedPort` (one reader thread routing each
packet to its sensor's core) and the raw capture of the port; each core has
its own publishers, clock, counters, supervisor, services and diagnostics
(sensor_set.py says how they are named). Stopping stops them all at once, so
that several sensors stop as fast as one.

The first-contact checks live here too, so that both executables run them:
:func:`load_config` names every parameter override the node does not
declare, and the set refuses a port path that can never work
(:class:`~..device.port.PortUnusable`, before anything is started), and each
core keeps in :attr:`DriverCore.fatal_error` the one its supervisor finds
later.
"""

from collections.abc import Callable
import sys
import threading
import time

from rclpy.node import Node

from .fault_watch import FaultWatch
from .parameter_table import SPECS
from .parameters import declare_parameters, driver_config, DriverConfig, warn_unknown_parameters
from .publishers import ALONE_TOPICS, create_publishers, override_names, Publishers, SensorTopics
from .record_publisher import RecordPublisher, Stamping
from .sensor_set import SensorSetting
from .services import DeviceServices, SaveCaptureService
from .temperature import TemperaturePoller
from ..capture.fault_capture import FaultCapture
from ..capture.raw_capture import bytes_sink, RawCapture
from ..device.link import DeviceError
from ..device.port import check_port_path, PortError
from ..device.shared_port import SharedPort
from ..device.supervisor import DeviceSupervisor


#: How long a stop waits for the sensors together (s); one that hangs is left to the
#: process's deadline (lifetime.py).
STOP_ALL_S = 5.0


def load_config(node: Node) -> DriverConfig:
    """
    Declare and validate the parameters on ``node``; return the configuration.

    Raises ParameterError for a missing or bad one. Every override whose
    name the node does not declare is named in a warning first, with the
    closest real name, also when a required one is missing ('adress'
    explains why 'address' is).
    """
    config = None
    try:
        config = driver_config(declare_parameters(node))
    finally:
        topics = SensorTopics.of_every_sensor(config) if config is not None else ALONE_TOPICS
        warn_unknown_parameters(node, [*(spec.name for spec in SPECS),
                                       *override_names(node, topics)])
    return config


class DriverCore:
    """
    Publish the records of ``sensor``'s stream as sensor_msgs/Imu and MagneticField.

    ``node`` is the rclpy node the services and logs belong to; ``config``
    the validated parameters; ``publishers`` the sensor's data publishers
    (plain ones, or a managed node's lifecycle publishers: see
    :func:`create_publishers`); ``raw_capture`` the port's capture (its
    :class:`DriverSet` closes it), ``fault_capture`` the port's last seconds
    (its :class:`DriverSet` starts and closes it), ``on_bytes`` where the
    port's bytes go for both (a core that opens its own port: see
    ``shared``). What the owning node decides:
    ``publishing`` False: records are counted, not published, until the
    owner turns publishing on (``records.set_publishing``); ``refusal``
    tells the services why they must refuse now ('' to serve). ``shared``:
    the port the sensors behind one base station share (None: the core
    opens its own). ``on_fatal`` is called once the port can never work
    (after :attr:`fatal_error` is set), so the run loop wakes for it.

    The core starts nothing: its owner drives :attr:`supervisor`. The records
    themselves go through :attr:`records` (record_publisher.py), which the
    supervisor's reader thread calls. With several sensors on one port the
    core's services are under its sensor's name (``~/<name>/self_test``).
    """

    def __init__(self, node: Node, config: DriverConfig, sensor: SensorSetting,
                 publishers: Publishers, raw_capture: RawCapture, *,
                 publishing: bool = True, refusal: Callable[[], str] | None = None,
                 shared: SharedPort | None = None, fault_capture: FaultCapture,
                 on_bytes: Callable[[bytes, float], None] | None = None,
                 on_fatal: Callable[[], None] | None = None) -> None:
        self.node = node
        self._told_fatal = on_fatal or (lambda: None)
        self.config = cfg = config
        #: The sensor this core serves: address, name (topic prefix), frame, stream.
        self.sensor = sensor
        #: Why the port can never work, once the supervisor found out.
        self.fatal_error: PortError | None = None
        self.stream = sensor.stream_choice
        #: Stamping, counting and publishing of each record, in the reader thread.
        self.records = records = RecordPublisher(
            publishers, cfg.messages_for(sensor), Stamping.of(cfg, self.stream),
            node.get_logger(), publishing)
        #: Whether this core's sensor shares its port with others.
        self._shared = shared is not None
        #: The port's raw capture and its last seconds (written when a fault is seen),
        #: shown on diagnostics.
        self.raw_capture, self.fault_capture = raw_capture, fault_capture
        self.supervisor = DeviceSupervisor(
            cfg.device_for(sensor), on_record=records.on_record, log=node.get_logger(),
            on_connect=records.link_changed, on_stream_known=records.stream_known,
            on_fatal=self._on_fatal, on_bytes=on_bytes, shared=shared,
            on_gyro_bias=lambda: records.announce_calibrated(True))
        records.announce_calibrated(False)
        self.device_services = DeviceServices(
            node, self.supervisor, records.published, records.forget_last_sample,
            capture_on_start=cfg.capture_gyro_bias_on_start, refusal=refusal,
            calibrated=records.announce_calibrated,
            prefix='~/' if shared is None else f'~/{sensor.name}/')
        #: The faults of this sensor the fault capture is written for.
        self.fault_watch = FaultWatch(self.supervisor.status, lambda: records.stats.device_resets,
                                      prefix='' if shared is None else f'{sensor.name}-')
        frame_id = records.messages.frame_id
        self.temperature = TemperaturePoller(
            node, self.supervisor.streaming_link, frame_id, cfg.temperature_period,
            publishers.temperature, cfg.time_offset, firmware=self.supervisor.firmware)
        node.get_logger().info(
            f'i3dmgx2_driver: port {cfg.device.port}, node address {sensor.address}, '
            + (f'topics {sensor.name}/..., ' if shared is not None else '')
            + f'stream {self.stream.label}, frame {frame_id} ({cfg.messages.frame_convention}), '
            f'time source {cfg.time_source}'
            + (f', time offset {cfg.time_offset:+g} s' if cfg.time_offset else ''))

    def _on_fatal(self, error: PortError) -> None:
        """
        Say once that the port can never work; the supervisor has stopped.

        The plain node's run loop then exits with code 2; a managed node stays
        up, its connection ERROR on /diagnostics, for its manager to act on.
        """
        self.fatal_error = error
        self.node.get_logger().fatal(str(error))
        self._told_fatal()

    def shutdown(self, report: bool = True) -> None:
        """Stop the device stream (bounded in time); log it if ``report``."""
        start = time.monotonic()
        self.device_services.stop()
        self.temperature.stop()
        self.supervisor.stop()
        self.device_services.wait_idle(1.0)
        if not report:
            return
        of = f' of node {self.sensor.address}' if self._shared else ''
        message = (f'stopped: {self.records.stats.published} records{of} published, port closed '
                   f'({time.monotonic() - start:.2f} s)')
        if self.node.context.ok():
            self.node.get_logger().info(message)
        else:
            # After SIGINT the context is gone and /rosout with it: plain stderr.
            print(f'[i3dmgx2_driver] {message}', file=sys.stderr, flush=True)


class DriverSet:
    """
    The cores of every sensor in ``config`` on ``node``, sharing their port if several.

    ``publishers``, if given, holds each sensor's (a managed node's lifecycle
    publishers, in the order of ``config.sensors``; else the set makes plain
    ones); the other arguments are handed to every core (see DriverCore). A
    port path that exists but is no serial port raises PortUnusable here,
    before anything is made.
    """

    def __init__(self, node: Node, config: DriverConfig,
                 publishers: list[Publishers] | None = None, publishing: bool = True,
                 refusal: Callable[[], str] | None = None,
                 on_fatal: Callable[[], None] | None = None) -> None:
        device, sensors = config.device, config.sensors
        check_port_path(device.port)
        publishers = publishers or [create_publishers(node, config, sensor=s) for s in sensors]
        # What both captures record of the port they capture.
        port = {'port': device.port, 'address': sensors[0].address, 'baud': device.baud,
                'wireless': device.wireless, 'node': node.get_fully_qualified_name()}
        #: The port's one raw capture, for every sensor on it; closed after them all.
        self._capture = capture = RawCapture(config.capture_file, node.get_logger(), **port)
        #: The port's last seconds, kept always, written when a fault is seen or on request.
        self.fault_capture = faults = FaultCapture(
            config.fault_capture_dir, config.fault_capture_seconds, config.fault_captures_kept,
            node.get_logger(), **port)
        # Every byte of the port to both captures: from the shared port's reader, or the core's.
        sink = bytes_sink(capture.on_bytes if capture.active else None, faults.on_bytes)
        self.shared = SharedPort(device, node.get_logger(), sink) if len(sensors) > 1 else None
        self.cores = [
            DriverCore(node, config, sensor, sensor_publishers, capture,
                       publishing=publishing, refusal=refusal, shared=self.shared,
                       fault_capture=faults, on_fatal=on_fatal,
                       on_bytes=None if self.shared else sink)
            for sensor, sensor_publishers in zip(sensors, publishers, strict=True)]
        self.save_capture = SaveCaptureService(node, faults)
        if faults.active:
            node.get_logger().info(
                f'fault capture: the last {config.fault_capture_seconds:g} s of the port kept, '
                f'written to {faults.directory} when a fault is seen')
        faults.start(self._faults)

    def _faults(self) -> list[str]:
        """Return what went wrong with any sensor since the last look (the fault capture's)."""
        now = time.monotonic()
        return [cause for core in self.cores for cause in core.fault_watch.look(now)]

    @property
    def several(self) -> bool:
        """Whether the set serves several sensors on a shared port."""
        return self.shared is not None

    @property
    def fatal_error(self) -> PortError | None:
        """Return why the port can never work, once a supervisor found out (else None)."""
        return next((core.fatal_error for core in self.cores if core.fatal_error), None)

    def start(self) -> None:
        """Start every sensor's supervisor (the plain node: stream, recover, forever)."""
        for core in self.cores:
            core.supervisor.start()

    def set_publishing(self, on: bool) -> None:
        """Publish the records (a managed node while active), or only count them."""
        for core in self.cores:
            core.records.set_publishing(on)

    def each(self, step: Callable[[DriverCore], None], timeout: float | None = None,
             name: str = 'gx2-transition') -> list[tuple[DriverCore, Exception]]:
        """
        Take ``step`` for every core at once (one thread each if several); return who failed.

        With several sensors a silent one would otherwise hold up the others by
        its timeouts; one core takes its step in the calling thread, as always.
        Only the device's or the port's errors count as failures; others raise.
        ``timeout`` bounds the wait for the threads (daemons) altogether: a step
        still running then is left to the process's deadline (lifetime.py).
        ``name`` names each thread (``{}``: the sensor's address).
        """
        failed: list[tuple[DriverCore, Exception]] = []

        def take(core: DriverCore) -> None:
            try:
                step(core)
            except (PortError, DeviceError) as exc:  # the device's or the port's doing
                failed.append((core, exc))

        if len(self.cores) == 1:
            take(self.cores[0])
            return failed
        threads = [threading.Thread(target=take, args=(core,), daemon=True,
                                    name=name.format(core.sensor.address)) for core in self.cores]
        for thread in threads:
            thread.start()
        end = None if timeout is None else time.monotonic() + timeout
        for thread in threads:
            thread.join(None if end is None else max(end - time.monotonic(), 0.0))
        return sorted(failed, key=lambda pair: self.cores.index(pair[0]))

    def shutdown(self, report: bool = True) -> None:
        """Stop every stream and close the port, the sensors at once (within 5 s)."""
        self.fault_capture.close()  # our own stop is no fault
        for core, exc in self.each(lambda core: core.shutdown(report), timeout=STOP_ALL_S,
                                   name='gx2-stop-{}'):
            # Said, not raised: the other sensors and the port are still to be let go.
            print(f'[i3dmgx2_driver] stopping node {core.sensor.address}: {exc}',
                  file=sys.stderr, flush=True)
        self._capture.close()

    def destroy(self) -> None:
        """
        Remove every core's services from the node (after shutdown).

        For the managed node's cleanup: a later configure makes a new set.
        The publishers stay: they belong to whoever made them (see
        :func:`create_publishers` for why a managed node keeps them).
        """
        for core in self.cores:
            core.device_services.destroy()
        self.save_capture.destroy()
