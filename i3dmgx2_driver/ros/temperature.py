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
Temperatures: poll 0xD1 while the stream runs, publish sensor_msgs/Temperature.

The poll is a request in combined mode: it is sent while the device streams
and its reply, interleaved with the stream, is claimed by the pending
request rather than published as IMU data. A request can take a few
round trips over a lossy radio, so it runs in a worker thread of its own
that sleeps for the period between polls: neither the executor (parameters,
services, diagnostics) nor the reader thread (the IMU stream) ever waits
for it. Polls are skipped while the stream is not running (connecting, or
paused for a capture or the self test), and never sent to a sensor whose
firmware lacks 0xD1 (before 2.1.12): one warning names both versions, and
diagnostics say the temperature is unavailable on this firmware.
"""

from collections.abc import Callable
import threading
import time

from rclpy._rclpy_pybind11 import RCLError
from rclpy.node import Node
from rclpy.publisher import Publisher
from sensor_msgs.msg import Temperature

from .conversions import set_stamp
from ..codec import layouts
from ..device import timeouts
from ..device.link import DeviceError, DeviceLink
from ..device.port import PortError
from ..device.sensor_firmware import SensorFirmware
from ..device.throttle import Throttle

#: Seconds between two warnings about failed polls.
WARN_PERIOD = 60.0
#: How long stopping waits for a poll under way (s): shutdown has a time budget.
STOP_WAIT = 0.1


class TemperaturePoller:
    """
    Publish the accelerometer temperature on ``imu/temperature`` every ``period`` s.

    ``node`` logs; ``publisher`` publishes (the driver core makes it, a
    lifecycle publisher on a managed node); ``streaming_link()`` returns the
    device link while the device streams (None otherwise: no poll then);
    ``frame_id`` is the IMU frame. ``period`` 0 disables it: no thread (and
    no publisher is needed). ``time_offset`` (s) is added to every stamp, as
    to the IMU's. ``firmware``, if given, is the sensor's (read at each
    connection): a firmware without 0xD1 is never polled.
    """

    def __init__(self, node: Node, streaming_link: Callable[[], DeviceLink | None],
                 frame_id: str, period: float, publisher: Publisher | None,
                 time_offset: float = 0.0, firmware: SensorFirmware | None = None) -> None:
        self.node = node
        self._firmware = firmware or SensorFirmware()
        #: Why the temperature is not polled on this sensor's firmware ('' while it is).
        self.unavailable = ''
        self._time_offset = time_offset
        self._streaming_link = streaming_link
        self.period = period
        #: The last temperature read (deg C), None before the first.
        self.latest: float | None = None
        self._stop = threading.Event()
        self._throttle = Throttle(WARN_PERIOD)
        self._thread: threading.Thread | None = None
        self.publisher = publisher
        if period > 0 and publisher is not None:
            self._msg = Temperature()  # variance 0.0: unknown (sensor_msgs)
            self._msg.header.frame_id = frame_id
            self._thread = threading.Thread(target=self._run, name='gx2-temperature', daemon=True)
            self._thread.start()

    def stop(self) -> None:
        """
        Stop polling, without waiting long: shutdown has a time budget.

        A poll under way ends when the supervisor aborts the link, which
        the node does right after this.
        """
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=STOP_WAIT)

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            self.poll()

    def poll(self) -> bool:
        """Read the temperatures once and publish; False if skipped or failed."""
        link = self._streaming_link()
        if link is None:
            return False
        why = self._firmware.refusal('the temperature poll', layouts.TEMPERATURES)
        if why and why != self.unavailable:
            self.node.get_logger().warning(
                f'temperature_period {self.period:g} s: {why}: the temperature is not '
                f'polled (imu/temperature stays silent)')
        self.unavailable = why
        if why:
            return False
        try:
            reply = link.request(bytes((layouts.TEMPERATURES,)), layouts.TEMPERATURES,
                                 timeouts.TEMPERATURE_TIMEOUT, timeouts.TEMPERATURE_RETRIES)
        except (DeviceError, PortError) as exc:
            if self._throttle.allow('poll') and not self._stop.is_set():
                self.node.get_logger().warning(f'temperature poll failed: {exc}')
            return False
        self.latest = self._msg.temperature = reply.accel_celsius
        set_stamp(self._msg.header, time.time() + self._time_offset)
        try:
            self.publisher.publish(self._msg)
        except RCLError:
            return False  # ROS is shutting down
        return True
