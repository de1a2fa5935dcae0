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
A sample's path from the reader thread to its publishers: stamp, count, pack, publish.

:class:`RecordPublisher` holds what the reader thread changes for every
record (the stamping clock, the stream's counters) and what the other
threads may touch of it (a new link, a deliberate pause, publishing on or
off, a snapshot of the clock), all under one lock. It is a room of its own
so that the hot path can be read, timed and changed without the rest of the
driver core (driver_core.py), which builds it and hands its
:meth:`RecordPublisher.on_record` to the supervisor's reader.
"""

from dataclasses import dataclass, field
import threading

from rclpy._rclpy_pybind11 import RCLError
from rclpy.impl.rcutils_logger import RcutilsLogger
from std_msgs.msg import Bool

from .conversions import MessageFactory, MessageSettings
from .parameters import DriverConfig
from .publishers import Publishers
from ..codec import line_budget
from ..codec.framing import DataPacket
from ..codec.streams import Stream
from ..device import hot_path
from ..device.sample_clock import ClockStatus, Restart, SampleClock

#: Whether ready-serialized messages read back right, by the message factory's
#: settings: checked once per process, because a managed node makes a core at
#: every configure and rclpy's deserialize_message keeps a little memory per call.
_SERIALIZED_MATCHES: dict[MessageSettings, bool] = {}


@dataclass
class StreamStats:
    """What the node saw of the stream: for diagnostics and tests."""

    published: int = 0
    unpublished: int = 0
    #: Messages published on each record topic after the first (publishers.RECORD_TOPICS).
    published_on: dict[str, int] = field(default_factory=dict)
    lost: int = 0
    device_resets: int = 0
    first_time: float = 0.0
    last_time: float = 0.0

    @property
    def mag_published(self) -> int:
        """Magnetic field messages published (diagnostics)."""
        return self.published_on.get('mag', 0)


@dataclass(frozen=True)
class Stamping:
    """How a record's stamp is made: which clock, the offset, the packet's time on the wire."""

    device_time: bool
    offset: float
    wire_time: float

    @classmethod
    def of(cls, config: DriverConfig, stream: Stream) -> 'Stamping':
        """Return the stamping the parameters ask for, for ``stream``'s packets."""
        return cls(config.time_source == 'device', config.time_offset,
                   line_budget.wire_time(stream.code, config.device.baud,
                                         config.device.wireless))


class RecordPublisher:
    """
    Stamp and publish each record of the stream the link hands on; count those lost.

    ``messages`` says how the records become messages on ``publishers``
    (frame, axes, covariances, stream); ``stamping`` how they are stamped.
    The device side hands it what it learns (:meth:`stream_known`): the
    timer ticks between two records once the rate divider is known (a
    larger step counts the records in between as lost), and whether it
    keeps a gyro bias it writes back after a power cycle (so that a power
    cycle seen in the timer leaves ``~/is_calibrated`` true). ``publishing``
    False: records are counted, not published, until :meth:`set_publishing`.
    The hot path's observer (device/hot_path.py), when on, is told the
    stamp, the pack and the publish of every sample; off, it costs one test
    each.
    """

    def __init__(self, publishers: Publishers, messages: MessageSettings,
                 stamping: Stamping, log: RcutilsLogger, publishing: bool = True) -> None:
        self.publishers = publishers
        #: The message factory (its ``frame_id`` is the one published, _ned and all).
        self.messages = factory = MessageFactory(messages)
        # Published ready-serialized (conversions.py says why) when the bytes read
        # back right with this middleware; otherwise as message objects.
        if messages not in _SERIALIZED_MATCHES:
            _SERIALIZED_MATCHES[messages] = factory.serialized_matches()
        serialized = _SERIALIZED_MATCHES[messages]
        (first, self.imu_pub), *others = publishers.records
        self._imu_message = factory.packer(first.packer, serialized)
        self.stats = StreamStats()
        #: Whether the next record's timer step counts packet loss: not across a
        #: reconnect or a deliberate pause (deactivate, a capture).
        self._counting = False
        #: The other topics of each record: publisher, packer, the count it adds to.
        self._also = tuple((publisher, factory.packer(row.packer, serialized), row.suffix)
                           for row, publisher in others)
        for _, _, suffix in self._also:
            self.stats.published_on[suffix] = 0
        #: Device timer -> system-clock stamps, through resets, rollovers and gaps.
        self.sample_clock = SampleClock()
        #: Whether records are published: always for the plain node; while
        #: active for the managed one (records still in flight after a
        #: deactivate are counted as unpublished, not as published).
        self.publishing = publishing
        self._use_device_time = stamping.device_time
        self._time_offset = stamping.offset
        self._wire_time = stamping.wire_time
        #: Timer ticks between two records (None: the divider not known yet).
        self._expected_ticks: int | None = None
        #: Whether the device side writes a kept gyro bias back after a power cycle.
        self._bias_kept = False
        self._log = log
        self._publish_lock = threading.Lock()

    def announce_calibrated(self, calibrated: bool) -> None:
        """
        Publish on ``~/is_calibrated`` whether the device uses a gyro bias captured still.

        False from the start (a bias captured by an earlier process may be
        gone with a power cycle), True after a capture the driver accepted,
        False again after one refused (the device uses the moved bias) and
        when the sensor's timer shows a power cycle (the bias lives in RAM),
        unless the driver keeps a bias it wrote back (a parameter's, or an
        accepted capture's): True again whenever that one is written.
        """
        try:
            self.publishers.is_calibrated.publish(Bool(data=calibrated))
        except RCLError:
            pass  # ROS is shutting down: nobody is left to tell

    def stream_known(self, expected_ticks: int | None, bias_kept: bool) -> None:
        """Take what the device side learned: the ticks between records, whether a bias is kept."""
        with self._publish_lock:
            self._expected_ticks = expected_ticks
            self._bias_kept = bias_kept

    def link_changed(self) -> None:
        """
        Check the next record's time against the clock fit: a new link is up.

        The sensor may have kept streaming (a wireless one, while the base
        station was unplugged), been power-cycled, or be another sensor: its
        first record's timer tells which (device/sample_clock.py). What the
        outage cost is not counted as lost records.
        """
        with self._publish_lock:
            self.sample_clock.link_changed()
            self._counting = False

    def clock_status(self) -> ClockStatus:
        """Return a snapshot of the stamping clock (from any thread)."""
        with self._publish_lock:
            return self.sample_clock.status()

    def published(self) -> tuple[int, float]:
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
            self._counting = False

    def on_record(self, packet: DataPacket, read_time: float, read_mono: float) -> None:
        """
        Stamp and publish one record of the stream (runs in the reader thread).

        Only records of the stream come here: the link keeps back replies and
        counts any other record (device/link.py, ``set_streamed``).
        """
        record = packet.record
        with self._publish_lock:
            stats = self.stats
            if not self.publishing:
                stats.unpublished += 1
                return
            clock = self.sample_clock
            stamp = clock.stamp(record.timer, read_mono, self._wire_time)
            timings = hot_path.timings
            if timings is not None:
                timings.stamped()
            if clock.restarted and clock.last_restart == Restart.RESET.value:
                stats.device_resets += 1
                self.announce_calibrated(self._bias_kept)
                self._log.warning(
                    "the sensor's timer restarted (a power cycle or brown-out): "
                    'timestamps start afresh from its new clock')
            # The timer's step since the record before, when it ran on (across a resync
            # of the fit too): the records in between were lost.
            since = clock.ticks_since_last
            if since is not None and self._counting:
                expected = self._expected_ticks
                if expected:
                    gap = round(since / expected) - 1
                    if gap > 0:
                        stats.lost += gap
            self._counting = True
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
            for publisher, pack, suffix in self._also:
                message = pack(record, stamp)
                if message is not None:
                    publisher.publish(message)
                    stats.published_on[suffix] += 1
