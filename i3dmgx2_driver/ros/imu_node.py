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
The driver node: device records in, sensor_msgs out, on time.

The node owns the ROS side only. A ``DeviceSupervisor`` (device layer)
keeps the sensor streaming; its reader thread calls :meth:`_on_record` for
every valid record, which stamps it, packs its messages and publishes at
once. The executor is left free for parameters, services and
diagnostics, and nothing it does can delay a sample.
"""

import sys
import threading
import time

from rclpy._rclpy_pybind11 import RCLError
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu, MagneticField

from .conversions import mag_is_valid, MessageFactory
from .diagnostics import DiagnosticsPublisher
from .parameters import declare_parameters, driver_config, DriverConfig
from .raw_capture import RawCapture
from .services import DeviceServices
from .temperature import TemperaturePoller
from ..codec.framing import DATA_TRAILER_SIZE, DataPacket, HEADER_SIZE
from ..codec.layouts import ACCEL_ANG_RATE_MAG_ORIENTATION, LAYOUTS
from ..codec.records import AccelAngRateMagOrientation
from ..codec.timer import TimerUnwrapper
from ..device.clock import DeviceClock
from ..device.realtime import ThreadPolicy
from ..device.supervisor import DeviceSupervisor, SupervisorConfig

#: Bits per byte on the line: start, 8 data, stop.
_BITS_PER_BYTE = 10


def wire_time(baud: int, wireless: bool) -> float:
    """Seconds the 0xCC packet (or wired record) takes on the serial line."""
    record = LAYOUTS[ACCEL_ANG_RATE_MAG_ORIENTATION].record_size
    size = HEADER_SIZE + record + DATA_TRAILER_SIZE if wireless else record + 2
    return size * _BITS_PER_BYTE / baud


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
        self.last_ticks: int | None = None


class ImuDriverNode(Node):
    """Publish the 3DM-GX2's 0xCC records as sensor_msgs/Imu and MagneticField."""

    def __init__(self, node_name: str = 'i3dmgx2_driver', **kwargs) -> None:
        super().__init__(node_name, **kwargs)
        self.values = declare_parameters(self)
        self.config: DriverConfig = driver_config(self.values)
        cfg = self.config
        qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=cfg.qos_depth,
            reliability=(ReliabilityPolicy.RELIABLE if cfg.qos_reliability == 'reliable'
                         else ReliabilityPolicy.BEST_EFFORT))
        self.imu_pub = self.create_publisher(Imu, 'imu/raw_data', qos)
        self.mag_pub = (self.create_publisher(MagneticField, 'imu/mag', qos)
                        if cfg.publish_mag else None)
        self.messages = MessageFactory(
            cfg.frame_id, cfg.frame_convention, cfg.orientation_stddev,
            cfg.angular_velocity_stddev, cfg.linear_acceleration_stddev,
            cfg.magnetic_field_stddev)
        self.stats = StreamStats()
        self.unwrapper = TimerUnwrapper()
        self.clock_model = DeviceClock()
        self._use_device_time = cfg.time_source == 'device'
        self._wire_time = wire_time(cfg.baud, cfg.wireless)
        self._publish_lock = threading.Lock()
        # Publish the messages ready-serialized (conversions.py says why) when they read
        # back right with this middleware; otherwise as message objects.
        if self.messages.serialized_matches():
            self._imu_message, self._mag_message = (self.messages.imu_cdr,
                                                    self.messages.mag_cdr)
        else:
            self._imu_message, self._mag_message = (self.messages.fill_imu,
                                                    self.messages.fill_mag)
        #: Called in the reader thread right after each Imu message is published, with
        #: (record, read time, stamp): for benchmarks and tests. None costs nothing.
        self.on_published = None
        self.raw_capture = RawCapture(
            cfg.capture_file, self.get_logger(), port=cfg.port, address=cfg.address,
            baud=cfg.baud, wireless=cfg.wireless, node=self.get_fully_qualified_name())
        self.supervisor = DeviceSupervisor(
            SupervisorConfig(
                port=cfg.port, address=cfg.address, baud=cfg.baud, wireless=cfg.wireless,
                low_latency=cfg.low_latency, stall_timeout=cfg.read_timeout,
                reconnect_interval=cfg.reconnect_interval, data_rate_hz=cfg.data_rate_hz,
                thread_policy=ThreadPolicy(cfg.realtime_priority, cfg.cpu_affinity)),
            on_record=self._on_record, log=self.get_logger(), on_connect=self._on_connect,
            on_bytes=self.raw_capture.on_bytes if self.raw_capture.active else None)
        self.device_services = DeviceServices(self)
        self.temperature = TemperaturePoller(self, cfg.temperature_period, qos)
        self.diagnostics = DiagnosticsPublisher(
            self, calibration=self.device_services.calibration,
            temperature=lambda: self.temperature.latest, capture=self.raw_capture.describe,
            operation=lambda: self.device_services.operation)
        self.get_logger().info(
            f'i3dmgx2_driver: port {cfg.port}, node address {cfg.address}, '
            f'frame {self.messages.frame_id} ({cfg.frame_convention}), '
            f'time source {cfg.time_source}')
        self.supervisor.start()

    def _on_connect(self) -> None:
        """Re-anchor time on a new link: the device may have been power-cycled."""
        with self._publish_lock:
            self.unwrapper.reset()
            self.clock_model.reset()
            self.stats.last_ticks = None

    def forget_last_sample(self) -> None:
        """Let the next record start afresh: a deliberate pause is no packet loss."""
        with self._publish_lock:
            self.stats.last_ticks = None

    def _expected_ticks(self) -> int | None:
        divider = self.supervisor.divider
        return 384 * divider if divider else None

    def _on_record(self, packet: DataPacket, read_time: float) -> None:
        """Stamp and publish one record (runs in the reader thread)."""
        record = packet.record
        if type(record) is not AccelAngRateMagOrientation:
            self.stats.other_records += 1
            return
        with self._publish_lock:
            stats = self.stats
            ticks = self.unwrapper.update(record.timer, read_time)
            if self.unwrapper.last_was_reset:
                stats.device_resets += 1
                self.clock_model.reset()
            elif stats.last_ticks is not None:
                expected = self._expected_ticks()
                if expected:
                    gap = round((ticks - stats.last_ticks) / expected) - 1
                    if gap > 0:
                        stats.lost += gap
            stats.last_ticks = ticks
            if self._use_device_time:
                stamp = self.clock_model.stamp(ticks, read_time, self._wire_time)
            else:
                stamp = read_time
            try:
                self.imu_pub.publish(self._imu_message(record, stamp))
            except RCLError:
                # ROS is shutting down under the reader: nothing left to publish to.
                stats.unpublished += 1
                return
            on_published = self.on_published
            if on_published is not None:
                on_published(record, read_time, stamp)
            stats.published += 1
            if not stats.first_time:
                stats.first_time = read_time
            stats.last_time = read_time
            if self.mag_pub is not None and mag_is_valid(record.mag):
                self.mag_pub.publish(self._mag_message(record.mag, stamp))
                stats.mag_published += 1

    def shutdown(self) -> None:
        """Stop the device stream and close the port (bounded in time)."""
        start = time.monotonic()
        self.device_services.stop()
        self.temperature.stop()
        self.supervisor.stop()
        self.device_services.wait_idle(1.0)
        self.raw_capture.close()
        message = (f'stopped: {self.stats.published} records published, port closed '
                   f'({time.monotonic() - start:.2f} s)')
        if self.context.ok():
            self.get_logger().info(message)
        else:
            # After SIGINT the context is gone and /rosout with it: plain stderr.
            print(f'[i3dmgx2_driver] {message}', file=sys.stderr, flush=True)
