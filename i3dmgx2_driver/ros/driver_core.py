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

The supervisor's reader thread calls :meth:`DriverCore._on_record` for
every valid record, which stamps it, packs its messages and publishes at
once. The executor is left free for parameters, services and diagnostics,
and nothing it does can delay a sample.

The first-contact checks live here too, so that both executables run them:
:func:`load_config` names every parameter override the node does not
declare, and the core refuses a port path that can never work
(:class:`~..device.port.PortUnusable`, before anything is started), and
keeps in :attr:`DriverCore.fatal_error` the one the supervisor finds later.
"""

from collections.abc import Callable
import sys
import threading
import time
from typing import NamedTuple

from rclpy._rclpy_pybind11 import RCLError
from rclpy.node import Node
from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, MagneticField, Temperature
from std_msgs.msg import Bool

from .conversions import mag_is_valid, MessageFactory
from .parameters import declare_parameters, driver_config, DriverConfig, SPECS
from .qos import create_publisher, override_names
from .raw_capture import RawCapture
from .sensor_set import SensorSetting, SINGLE_NAME
from .services import DeviceServices
from .temperature import TemperaturePoller
from .unknown_parameters import warn_unknown_parameters
from ..codec import line_budget
from ..codec.data_rate import ticks_per_cycle
from ..codec.framing import DataPacket
from ..device.hot_path import HotPathObserver
from ..device.port import check_port_path, PortError, SerialPort
from ..device.port_opener import PortParts
from ..device.realtime import ThreadPolicy
from ..device.sample_clock import ClockStatus, Restart, SampleClock
from ..device.settings import DeviceConfig
from ..device.shared_port import SharedPort
from ..device.supervisor import DeviceSupervisor

#: Whether ready-serialized messages read back right, by the message factory's
#: settings: checked once per process, because a managed node makes a core at
#: every configure and rclpy's deserialize_message keeps a little memory per call.
_SERIALIZED_MATCHES: dict[tuple, bool] = {}


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


class SensorTopics(NamedTuple):
    """The topics one sensor's publishers use, named once for the node and its QoS names."""

    imu: str
    mag: str
    temperature: str
    is_calibrated: str

    @classmethod
    def of(cls, name: str, several: bool) -> 'SensorTopics':
        """Return the topics of the sensor called ``name`` (sensor_set.py: ``imu`` alone)."""
        return cls(f'{name}/raw_data', f'{name}/mag', f'{name}/temperature',
                   f'~/{name}/is_calibrated' if several else '~/is_calibrated')

    @staticmethod
    def of_every_sensor(config: DriverConfig) -> list[str]:
        """Return every topic the node may publish with ``config``, /diagnostics too."""
        several = len(config.sensors) > 1
        return [*(topic for sensor in config.sensors
                  for topic in SensorTopics.of(sensor.name, several)), '/diagnostics']


#: The topics of a node with one sensor: what is checked when the parameters fail.
ALONE_TOPICS = [*SensorTopics.of(SINGLE_NAME, several=False), '/diagnostics']


class StreamStats:
    """What the node saw of the stream: for diagnostics and tests."""

    def __init__(self) -> None:
        self.published = 0
        self.unpublished = 0
        self.mag_published = 0
        self.lost = 0
        self.other_records = 0
        self.device_resets = 0
        self.first_time = 0.0
        self.last_time = 0.0
        #: Whether the next record's timer step counts packet loss: not across a
        #: reconnect or a deliberate pause (deactivate, a capture).
        self.counting = False


class Publishers(NamedTuple):
    """The publishers; None where the parameters turn a topic off."""

    imu: Publisher
    mag: Publisher | None
    temperature: Publisher | None
    #: ``~/is_calibrated``: a plain publisher even on a managed node, so that
    #: its latched value holds in every state.
    is_calibrated: Publisher


def calibrated_qos() -> QoSProfile:
    """Return the QoS of ``~/is_calibrated``: the last value kept for late subscribers."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)


def publisher_qos(config: DriverConfig) -> QoSProfile:
    """
    Return the data publishers' QoS before rclpy's ``qos_overrides`` parameters.

    The deprecated ``qos_reliability`` and ``qos_depth`` still set it (for
    one release); a ``qos_overrides`` parameter wins over them.
    """
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=config.qos_depth,
        reliability=(ReliabilityPolicy.RELIABLE if config.qos_reliability == 'reliable'
                     else ReliabilityPolicy.BEST_EFFORT))


def create_publishers(node: Node, config: DriverConfig, lifecycle: bool = False,
                      sensor: SensorSetting | None = None) -> Publishers:
    """
    Make the data publishers of ``sensor`` (default: the one sensor) on ``node``.

    Lifecycle publishers if ``lifecycle``. The topics are under the sensor's
    name: ``imu/raw_data`` for the one sensor, ``<name>/raw_data`` for each
    of several (sensor_set.py).

    A managed node makes them once and keeps them across configure/cleanup
    cycles: destroying a publisher while a multi-threaded executor builds
    its wait set can crash the executor in rclpy (Jazzy), because the
    publisher's QoS event handlers are waitables whose invalid handles it
    does not skip (ros2/rclpy#1284). Its parameters are read-only, so the
    publishers it made first are the ones every later configure needs.
    """
    sensor = sensor if sensor is not None else config.sensors[0]
    topics = SensorTopics.of(sensor.name, several=len(config.sensors) > 1)
    make = node.create_lifecycle_publisher if lifecycle else node.create_publisher

    def create(kind: type, topic: str) -> Publisher:
        # A profile each: rclpy writes the overrides into the one it is given.
        return create_publisher(node, kind, topic, publisher_qos(config), make)

    return Publishers(
        create(Imu, topics.imu),
        # Only streams with a field (named 'mag' in each layout) have a magnetometer topic.
        create(MagneticField, topics.mag)
        if config.publish_mag and sensor.stream_choice.mag else None,
        create(Temperature, topics.temperature) if config.temperature_period > 0
        else None,
        create_publisher(node, Bool, topics.is_calibrated, calibrated_qos()))


def device_config(config: DriverConfig, sensor: SensorSetting) -> DeviceConfig:
    """Return how the device side reaches and treats ``sensor``, from the parameters."""
    return DeviceConfig(
        port=config.port, address=sensor.address, baud=config.baud, wireless=config.wireless,
        low_latency=config.low_latency, stall_timeout=config.read_timeout,
        reconnect_interval=config.reconnect_interval, data_rate_hz=sensor.data_rate_hz,
        stream=sensor.stream_choice.code, thread_policy=ThreadPolicy(config.realtime_priority))


class DriverCore:
    """
    Publish the records of the chosen stream as sensor_msgs/Imu and MagneticField.

    ``node`` is the rclpy node the services and logs belong to; ``config``
    the validated parameters. ``publishers``: the data publishers to use
    (a managed node's lifecycle publishers, see :func:`create_publishers`);
    by default the core makes plain ones. ``publishing`` False: records are
    counted, not published, until the owner turns :attr:`publishing` on.
    ``refusal`` tells the services why they must refuse now ('' to serve).
    The core starts nothing: its owner drives :attr:`supervisor`. A port
    path that exists but is no serial port raises PortUnusable here, before
    anything is made. ``timings``, if given, is told every stage boundary
    of every sample's path (device/hot_path.py); None costs nothing.
    ``port_factory`` opens the port (SerialPort; a subclass to observe it).

    One core serves one sensor: ``sensor`` (default: the one the parameters
    name). With several behind one base station (driver_set.py) each has a
    core, ``shared`` is the port they share and ``raw_capture`` the port's
    one capture, which the set closes; the core's services are then under
    its sensor's name (``~/<name>/self_test``).
    """

    def __init__(self, node: Node, config: DriverConfig,
                 publishers: Publishers | None = None, publishing: bool = True,
                 refusal: Callable[[], str] | None = None,
                 timings: HotPathObserver | None = None,
                 port_factory: Callable[..., SerialPort] = SerialPort,
                 sensor: SensorSetting | None = None, shared: SharedPort | None = None,
                 raw_capture: RawCapture | None = None) -> None:
        check_port_path(config.port)
        self.node = node
        self.config = cfg = config
        #: The sensor this core serves: address, name (topic prefix), frame, stream.
        self.sensor = sensor = sensor if sensor is not None else cfg.sensors[0]
        #: Why the port can never work, once the supervisor found out.
        self.fatal_error: PortError | None = None
        self.stream = sensor.stream_choice
        self._record_type = self.stream.record_type
        self.publishers = publishers or create_publishers(node, cfg, sensor=sensor)
        self.imu_pub = self.publishers.imu
        self.mag_pub = self.publishers.mag
        settings = (sensor.frame_id, cfg.frame_convention, cfg.orientation_stddev,
                    cfg.angular_velocity_stddev, cfg.linear_acceleration_stddev,
                    cfg.magnetic_field_stddev, self.stream)
        self.messages = MessageFactory(*settings)
        self.stats = StreamStats()
        #: Device timer -> system-clock stamps, through resets, rollovers and gaps.
        self.sample_clock = SampleClock()
        #: Whether records are published: always for the plain node; while
        #: active for the managed one (records still in flight after a
        #: deactivate are counted as unpublished, not as published).
        self.publishing = publishing
        self._use_device_time = cfg.time_source == 'device'
        self._time_offset = cfg.time_offset
        self._wire_time = line_budget.wire_time(self.stream.code, cfg.baud, cfg.wireless)
        self._publish_lock = threading.Lock()
        # Publish the messages ready-serialized (conversions.py says why) when they read
        # back right with this middleware; otherwise as message objects.
        if settings not in _SERIALIZED_MATCHES:
            _SERIALIZED_MATCHES[settings] = self.messages.serialized_matches()
        if _SERIALIZED_MATCHES[settings]:
            self._imu_message, self._mag_message = (self.messages.imu_cdr,
                                                    self.messages.mag_cdr)
        else:
            self._imu_message, self._mag_message = (self.messages.fill_imu,
                                                    self.messages.fill_mag)
        self._timings = timings
        #: Whether this core's sensor shares its port with others (driver_set.py).
        self._shared = shared is not None
        #: The port's raw capture: this core's own, or the one the sensors share.
        self._owns_capture = raw_capture is None
        self.raw_capture = raw_capture if raw_capture is not None else RawCapture(
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
        self.announce_calibrated(False)
        self.device_services = DeviceServices(
            node, self.supervisor, self._published, self.forget_last_sample,
            capture_on_start=cfg.capture_gyro_bias_on_start, refusal=refusal,
            calibrated=self.announce_calibrated,
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

    def announce_calibrated(self, calibrated: bool) -> None:
        """
        Publish on ``~/is_calibrated`` whether the device uses a gyro bias captured still.

        False from the start (a bias captured by an earlier process may be
        gone with a power cycle), True after a capture the driver accepted,
        False again after one refused (the device uses the moved bias) and
        when the sensor's timer shows a power cycle (the bias lives in RAM).
        """
        try:
            self.publishers.is_calibrated.publish(Bool(data=calibrated))
        except RCLError:
            pass  # ROS is shutting down: nobody is left to tell

    def _on_fatal(self, error: PortError) -> None:
        """
        Say once that the port can never work; the supervisor has stopped.

        The plain node's run loop then exits with code 2; a managed node stays
        up, its connection ERROR on /diagnostics, for its manager to act on.
        """
        self.fatal_error = error
        self.node.get_logger().fatal(str(error))

    def _on_connect(self) -> None:
        """
        Check the next record's time against the clock fit: a new link is up.

        The sensor may have kept streaming (a wireless one, while the base
        station was unplugged), been power-cycled, or be another sensor: its
        first record's timer tells which (device/sample_clock.py). What the
        outage cost is not counted as lost records.
        """
        with self._publish_lock:
            self.sample_clock.link_changed()
            self.stats.counting = False

    def clock_status(self) -> ClockStatus:
        """Return a snapshot of the stamping clock (from any thread)."""
        with self._publish_lock:
            return self.sample_clock.status()

    def _published(self) -> tuple[int, float]:
        """Return (records published, read time of the last), for the self test's rate."""
        return self.stats.published, self.stats.last_time

    def set_publishing(self, on: bool) -> None:
        """
        Publish the records (a managed node while active), or only count them.

        Under the publish lock: once this returns False no record is between
        the check and its publish, so none goes to a publisher about to be
        deactivated (which would drop it while it counted as published).
        """
        with self._publish_lock:
            self.publishing = on

    def forget_last_sample(self) -> None:
        """Let the next record start afresh: a deliberate pause is no packet loss."""
        with self._publish_lock:
            self.stats.counting = False

    def _expected_ticks(self) -> int | None:
        divider = self.supervisor.divider
        return ticks_per_cycle(divider) if divider else None

    def _on_record(self, packet: DataPacket, read_time: float, read_mono: float) -> None:
        """Stamp and publish one record (runs in the reader thread)."""
        record = packet.record
        if type(record) is not self._record_type:
            self.stats.other_records += 1
            return
        with self._publish_lock:
            stats = self.stats
            if not self.publishing:
                stats.unpublished += 1
                return
            clock = self.sample_clock
            stamp = clock.stamp(record.timer, read_mono, self._wire_time)
            timings = self._timings
            if timings is not None:
                timings.stamped()
            if clock.restarted and clock.last_restart == Restart.RESET.value:
                stats.device_resets += 1
                self.announce_calibrated(False)
                self.node.get_logger().warning(
                    "the sensor's timer restarted (a power cycle or brown-out): "
                    'timestamps start afresh from its new clock')
            # The timer's step since the record before, when it ran on (across a resync
            # of the fit too): the records in between were lost.
            since = clock.ticks_since_last
            if since is not None and stats.counting:
                expected = self._expected_ticks()
                if expected:
                    gap = round(since / expected) - 1
                    if gap > 0:
                        stats.lost += gap
            stats.counting = True
            if not self._use_device_time:
                stamp = read_time
            stamp += self._time_offset
            message = self._imu_message(record, stamp)
            if timings is not None:
                timings.packed()
            try:
                self.imu_pub.publish(message)
            except RCLError:
                # ROS is shutting down under the reader: nothing left to publish to.
                stats.unpublished += 1
                return
            if timings is not None:
                timings.published(record, stamp)
            stats.published += 1
            if not stats.first_time:
                stats.first_time = read_time
            stats.last_time = read_time
            # mag_pub exists only for streams with a field (named 'mag' in each layout).
            if self.mag_pub is not None and mag_is_valid(record.mag):
                self.mag_pub.publish(self._mag_message(record.mag, stamp))
                stats.mag_published += 1

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
