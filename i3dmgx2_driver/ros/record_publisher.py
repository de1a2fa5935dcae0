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

:class:`RecordPath` is what becomes of a record of the stream, written once:
its stamp (the sample clock and the parameters' time source and offset),
the records lost before it (the timer's step), and the bytes of each record
topic's message (the packers of ``publishers.RECORD_TOPICS``). The node's
:class:`RecordPublisher` publishes them; ``replay --bag`` (tools/bag_io.py)
writes them to a bag. :class:`RecordPublisher` holds what the other threads
may touch of the path (a new link, a deliberate pause, publishing on or off,
a snapshot of the clock), all under one lock, so that the hot path can be
read, timed and changed without the rest of the driver core (driver_core.py),
which builds it and hands its :meth:`RecordPublisher.on_record` to the
supervisor's reader.
"""

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import math
import threading

from rclpy._rclpy_pybind11 import RCLError
from rclpy.impl.rcutils_logger import RcutilsLogger
from std_msgs.msg import Bool

from .conversions import MessageFactory, MessageSettings
from .parameters import DriverConfig
from .publishers import Publishers, RecordTopic
from ..codec import line_budget
from ..codec.framing import DataPacket
from ..codec.streams import Stream
from ..device import hot_path
from ..device.sample_clock import ClockStatus, records_lost, Restart, SampleClock


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


class RecordPath:
    """
    Stamp a record of the stream, count the records lost before it, pack its messages.

    ``rows`` are the record topics the sensor publishes (the first, the
    Imu, always); :meth:`messages` returns their bytes in that order (None
    where a record has nothing for a topic: a field of NaN). The timer's
    step from the record before counts the records in between as lost, once
    :attr:`expected_ticks` (the ticks between two records) is known, and not
    across a new link or a pause (:attr:`counting` False).
    """

    def __init__(self, messages: MessageSettings, stamping: Stamping,
                 rows: Sequence[RecordTopic], clock: SampleClock | None = None,
                 stats: StreamStats | None = None) -> None:
        #: The message factory (its ``frame_id`` is the one published, _ned and all).
        self.factory = factory = MessageFactory(messages)
        self.packers = tuple(factory.packer(row.packer) for row in rows)
        #: Device timer -> system-clock stamps, through resets, rollovers and gaps.
        self.clock = clock or SampleClock()
        self.stats = stats or StreamStats()
        self._stamp = self.clock.stamp
        self._device_time = stamping.device_time
        self._offset = stamping.offset
        self._wire_time = stamping.wire_time
        #: Timer ticks between two records (None: the divider not known yet).
        self.expected_ticks: int | None = None
        #: Whether the next record's timer step counts packet loss.
        self.counting = False
        #: The last record's stamp (s, system clock).
        self.stamp = 0.0

    def messages(self, values: tuple, read_time: float, read_mono: float) -> list:
        """
        Return the messages of a record (its ``DataPacket.values``) read at these times.

        ``read_time`` on the system clock, ``read_mono`` the same instant on
        the monotonic one. The stamp is kept in :attr:`stamp`.
        """
        clock = self.clock
        stamp = self._stamp(values[-1], read_mono, self._wire_time)
        # The timer's step since the record before, when it ran on (across a resync of
        # the fit too): the records in between were lost.
        since, expected = clock.ticks_since_last, self.expected_ticks
        if since is not None and self.counting and expected and 2 * since >= 3 * expected:
            self.stats.lost += records_lost(since, expected)
        self.counting = True
        if not self._device_time:
            stamp = read_time
        self.stamp = stamp = stamp + self._offset
        # The stamp's sec and nanosec (conversions.stamp_parts), once for every message.
        sec = math.floor(stamp)
        nanosec = round((stamp - sec) * 1e9)
        if nanosec >= 1_000_000_000:
            sec += 1
            nanosec -= 1_000_000_000
        messages = []
        for pack in self.packers:  # a loop, not a comprehension: no call of its own
            messages.append(pack(values, sec, nanosec))
        return messages

    def expect(self, ticks: int | None) -> None:
        """Count loss from here on against ``ticks`` between two records (None: unknown)."""
        self.expected_ticks = ticks

    def pause(self) -> None:
        """Let the next record start afresh: a new link or a deliberate pause is no loss."""
        self.counting = False

    def time(self, timings: hot_path.HotPathObserver) -> None:
        """Tell ``timings`` each record's Imu pack, and its stamp if it marks stages."""
        if timings.stages:
            self._stamp = hot_path.marked(self._stamp, 'stamped')
        imu = self.packers[0]

        def packed(values: tuple, sec: int, nanosec: int) -> bytes:
            message = imu(values, sec, nanosec)
            timings.packed(values[-1])
            return message
        self.packers = (packed, *self.packers[1:])


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
    """

    def __init__(self, publishers: Publishers, messages: MessageSettings,
                 stamping: Stamping, log: RcutilsLogger, publishing: bool = True) -> None:
        self.publishers = publishers
        self.stats = StreamStats()
        self.path = path = RecordPath(messages, stamping, [row for row, _ in publishers.records],
                                      stats=self.stats)
        #: The message factory (its ``frame_id`` is the one published, _ned and all).
        self.messages = path.factory
        (_, imu), *others = publishers.records
        self._publish_imu: Callable[[bytes], None] = imu.publish
        #: The other topics of each record: publish, the suffix its count is under.
        self._also = tuple((publisher.publish, row.suffix) for row, publisher in others)
        self.stats.published_on.update((suffix, 0) for _, suffix in self._also)
        self.sample_clock = path.clock
        if hot_path.timings is not None:
            self._time(hot_path.timings)
        #: Whether records are published: always for the plain node; while
        #: active for the managed one (records still in flight after a
        #: deactivate are counted as unpublished, not as published).
        self.publishing = publishing
        #: Whether the device side writes a kept gyro bias back after a power cycle.
        self._bias_kept = False
        self._log = log
        self._publish_lock = threading.Lock()

    def _time(self, timings: hot_path.HotPathObserver) -> None:
        """Tell ``timings`` each record's stamp, pack and publish (hot_path.py): off by default."""
        path, publish = self.path, self._publish_imu
        path.time(timings)

        def published(message: bytes) -> None:
            publish(message)
            timings.published(path.stamp)
        self._publish_imu = published

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
            self.path.expect(expected_ticks)
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
            self.path.pause()

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
            self.path.pause()

    def on_record(self, packet: DataPacket, read_time: float, read_mono: float) -> None:
        """
        Stamp and publish one record of the stream (runs in the reader thread).

        Only records of the stream come here: the link keeps back replies and
        counts any other record (device/link.py, ``set_streamed``).
        """
        with self._publish_lock:
            stats = self.stats
            if not self.publishing:
                stats.unpublished += 1
                return
            messages = self.path.messages(packet.values, read_time, read_mono)
            clock = self.sample_clock
            if clock.restarted and clock.last_restart == Restart.RESET.value:
                stats.device_resets += 1
                self.announce_calibrated(self._bias_kept)
                self._log.warning(
                    "the sensor's timer restarted (a power cycle or brown-out): "
                    'timestamps start afresh from its new clock')
            try:
                self._publish_imu(messages[0])
            except RCLError:
                # ROS is shutting down under the reader: nothing left to publish to.
                stats.unpublished += 1
                return
            stats.published += 1
            if not stats.first_time:
                stats.first_time = read_time
            stats.last_time = read_time
            for (publish, suffix), message in zip(self._also, messages[1:], strict=True):
                if message is not None:
                    publish(message)
                    stats.published_on[suffix] += 1
