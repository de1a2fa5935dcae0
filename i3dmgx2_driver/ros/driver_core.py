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

:class:`DriverCore` is everything the driver does for one configuration:
the publishers, the message factory, stamping and loss counting, the
device supervisor, the services, the temperature poller and the raw
capture. It lives on an rclpy node it does not own: the plain node
(``imu_node.py``) makes one at start and starts its supervisor at once; the
managed node (``lifecycle_node.py``) makes one at each configure, with
lifecycle publishers, drives the supervisor's phases from its transitions
and destroys the core at cleanup. Neither holds a copy of this code.

The supervisor's reader thread calls the core's
:meth:`~.record_publisher.RecordPublisher.on_record` for every valid
record, which stamps it, packs its messages and publishes at once. The
executor is left free for parameters, services and diagnostics, and nothing
it does can delay a sample.

The first-contact checks live here too, so that both executables run them:
:func:`load_config` names every parameter override the node does not
declare, and the core refuses a port path that can never work
(:class:`~..device.port.PortUnusable`, before anything is started), and
keeps in :attr:`DriverCore.fatal_error` the one the supervisor finds later.
"""

from collections.abc import Callable
from dataclasses import dataclass
import sys
import time

from rclpy.node import Node

from .parameters import declare_parameters, driver_config, DriverConfig, SPECS
from .publishers import ALONE_TOPICS, create_publishers, Publishers, SensorTopics
from .qos import override_names
from .record_publisher import packing, RecordPublisher, Stamping
from .sensor_set import SensorSetting
from .services import DeviceServices
from .temperature import TemperaturePoller
from .unknown_parameters import warn_unknown_parameters
from ..capture import RawCapture
from ..codec.data_rate import ticks_per_cycle
from ..device.hot_path import HotPathObserver
from ..device.port import check_port_path, PortError, SerialPort
from ..device.port_opener import PortParts
from ..device.realtime import ThreadPolicy
from ..device.sample_clock import ClockStatus
from ..device.settings import DeviceConfig
from ..device.shared_port import SharedPort
from ..device.supervisor import DeviceSupervisor


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
        topics = (SensorTopics.of_every_sensor(config) if config is not None
                  else ALONE_TOPICS)
        warn_unknown_parameters(node, [*(spec.name for spec in SPECS),
                                       *override_names(node, topics)])
    return config


def device_config(config: DriverConfig, sensor: SensorSetting) -> DeviceConfig:
    """Return how the device side reaches and treats ``sensor``, from the parameters."""
    return DeviceConfig(
        port=config.port, address=sensor.address, baud=config.baud, wireless=config.wireless,
        low_latency=config.low_latency, stall_timeout=config.read_timeout,
        reconnect_interval=config.reconnect_interval, data_rate_hz=sensor.data_rate_hz,
        stream=sensor.stream_choice.code, thread_policy=ThreadPolicy(config.realtime_priority))


@dataclass(frozen=True)
class CoreRole:
    """
    What the owning node decides for its core.

    ``publishers``: the data publishers to use (a managed node's lifecycle
    publishers, see :func:`create_publishers`); None: the core makes plain
    ones. ``publishing`` False: records are counted, not published, until
    the owner turns publishing on. ``refusal`` tells the services why they
    must refuse now ('' to serve).
    """

    publishers: Publishers | None = None
    publishing: bool = True
    refusal: Callable[[], str] | None = None


@dataclass(frozen=True)
class Probes:
    """
    What a test or benchmark injects; the defaults are what the node runs with.

    ``timings``, if given, is told every stage boundary of every sample's
    path (device/hot_path.py); None costs nothing. ``port_factory`` opens
    the port (SerialPort; a subclass to observe it).
    """

    timings: HotPathObserver | None = None
    port_factory: Callable[..., SerialPort] = SerialPort


@dataclass(frozen=True)
class SensorSlot:
    """
    Which sensor a core serves, and what it shares with the others on its port.

    ``sensor``: default the one the parameters name. With several behind
    one base station (driver_set.py) each has a core, ``shared`` is the port
    they share and ``raw_capture`` the port's one capture, which the set
    closes.
    """

    sensor: SensorSetting | None = None
    shared: SharedPort | None = None
    raw_capture: RawCapture | None = None


class DriverCore:
    """
    Publish the records of the chosen stream as sensor_msgs/Imu and MagneticField.

    ``node`` is the rclpy node the services and logs belong to; ``config``
    the validated parameters; ``role`` what the owning node decides,
    ``probes`` what a test injects, ``slot`` the sensor served and what it
    shares (each class says more). The core starts nothing: its owner drives
    :attr:`supervisor`. A port path that exists but is no serial port raises
    PortUnusable here, before anything is made. The records themselves go
    through :attr:`records` (record_publisher.py), which the supervisor's
    reader thread calls.

    With several sensors on one port the core's services are under its
    sensor's name (``~/<name>/self_test``).
    """

    def __init__(self, node: Node, config: DriverConfig, role: CoreRole = CoreRole(),
                 probes: Probes = Probes(), slot: SensorSlot = SensorSlot()) -> None:
        check_port_path(config.port)
        timings, port_factory, shared = probes.timings, probes.port_factory, slot.shared
        self.node = node
        self.config = cfg = config
        #: The sensor this core serves: address, name (topic prefix), frame, stream.
        self.sensor = sensor = slot.sensor if slot.sensor is not None else cfg.sensors[0]
        #: Why the port can never work, once the supervisor found out.
        self.fatal_error: PortError | None = None
        self.stream = sensor.stream_choice
        self.publishers = role.publishers or create_publishers(node, cfg, sensor=sensor)
        packers = packing((sensor.frame_id, cfg.frame_convention, cfg.orientation_stddev,
                           cfg.angular_velocity_stddev, cfg.linear_acceleration_stddev,
                           cfg.magnetic_field_stddev, self.stream))
        self.messages = packers.messages
        #: Stamping, counting and publishing of each record, in the reader thread.
        self.records = RecordPublisher(
            self.publishers, packers, self.stream.record_type, Stamping.of(cfg, self.stream),
            self._expected_ticks, node.get_logger(), role.publishing, timings)
        self.stats = self.records.stats
        # The reader thread and the supervisor call the record publisher itself.
        self._on_record = self.records.on_record
        self._on_connect = self.records.link_changed
        #: Whether this core's sensor shares its port with others (driver_set.py).
        self._shared = shared is not None
        #: The port's raw capture: this core's own, or the one the sensors share.
        self._owns_capture = slot.raw_capture is None
        self.raw_capture = slot.raw_capture if slot.raw_capture is not None else RawCapture(
            cfg.capture_file, node.get_logger(), port=cfg.port, address=sensor.address,
            baud=cfg.baud, wireless=cfg.wireless, node=node.get_fully_qualified_name())
        #: How the device side reaches and treats the sensor.
        self.device_config = device_config(cfg, sensor)
        capture = self.raw_capture.on_bytes if self.raw_capture.active else None
        self.supervisor = DeviceSupervisor(
            self.device_config,
            on_record=self._on_record, log=node.get_logger(), on_connect=self._on_connect,
            on_fatal=self._on_fatal, port=PortParts(
                port_factory, capture if shared is None else None, timings),
            shared=shared)
        self.records.announce_calibrated(False)
        self.device_services = DeviceServices(
            node, self.supervisor, self.records.published, self.records.forget_last_sample,
            capture_on_start=cfg.capture_gyro_bias_on_start, refusal=role.refusal,
            calibrated=self.records.announce_calibrated,
            prefix='~/' if shared is None else f'~/{sensor.name}/')
        self.temperature = TemperaturePoller(
            node, self.supervisor.streaming_link, self.messages.frame_id,
            cfg.temperature_period, self.publishers.temperature, cfg.time_offset)
        node.get_logger().info(
            f'i3dmgx2_driver: port {cfg.port}, node address {sensor.address}, '
            + (f'topics {sensor.name}/..., ' if shared is not None else '')
            + f'stream {self.stream.label}, frame {self.messages.frame_id} '
            f'({cfg.frame_convention}), '
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

    def clock_status(self) -> ClockStatus:
        """Return a snapshot of the stamping clock (from any thread)."""
        return self.records.clock_status()

    def set_publishing(self, on: bool) -> None:
        """Publish the records (a managed node while active), or only count them."""
        self.records.set_publishing(on)

    def forget_last_sample(self) -> None:
        """Let the next record start afresh: a deliberate pause is no packet loss."""
        self.records.forget_last_sample()

    def _expected_ticks(self) -> int | None:
        divider = self.supervisor.divider
        return ticks_per_cycle(divider) if divider else None

    def shutdown(self, report: bool = True) -> None:
        """Stop the device stream and close the port (bounded in time); log it if ``report``."""
        start = time.monotonic()
        self.device_services.stop()
        self.temperature.stop()
        self.supervisor.stop()
        self.device_services.wait_idle(1.0)
        if self._owns_capture:
            self.raw_capture.close()
        if not report:
            return
        of = f' of node {self.sensor.address}' if self._shared else ''
        message = (f'stopped: {self.stats.published} records{of} published, port closed '
                   f'({time.monotonic() - start:.2f} s)')
        if self.node.context.ok():
            self.node.get_logger().info(message)
        else:
            # After SIGINT the context is gone and /rosout with it: plain stderr.
            print(f'[i3dmgx2_driver] {message}', file=sys.stderr, flush=True)

    def destroy(self) -> None:
        """
        Remove the core's services from the node (after shutdown).

        For the managed node's cleanup: a later configure makes a new core.
        The publishers stay: they belong to whoever made them (see
        :func:`create_publishers` for why a managed node keeps them).
        """
        self.device_services.destroy()
