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
A sensor's samples as arrays in the units and axes the node publishes, from a capture or a bag.

Whatever the source, what the noise tool measures is what a subscriber of
``imu/raw_data`` would get: angular rate in rad/s, acceleration in m/s^2,
field in tesla, REP-103 body axes. A capture holds the device's units (g,
rad/s, Gauss, its FRD axes); they are converted with the node's own factors
and axes (ros/conversions.py, codec/orientation.py), on whole arrays.
Sample times come from the device timer (a capture: unwrapped through
rollovers, the host's receive times telling long pauses and restarts) or
from the messages' stamps (a bag). The readers underneath (a capture's
records, a bag's Imu and field messages, the timer unwrapped) serve magcal
and plot as well.
"""

from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
import os
from pathlib import Path
from typing import Any, NamedTuple
import warnings

import numpy as np

from .bag_io import bag_reader, deserializer
from ..capture.file_format import read_capture, TruncatedCaptureWarning
from ..codec.orientation import body_vector, ENU
from ..codec.parser import SensorStreamParser
from ..codec.records import TICKS_PER_SECOND
from ..codec.timer import TIMER_MODULUS
from ..ros.conversions import STANDARD_GRAVITY, TESLA_PER_GAUSS

#: Period of the device timer (s): it wraps after 2^32 ticks.
TIMER_PERIOD = TIMER_MODULUS / TICKS_PER_SECOND
#: The driver's Imu topic (the one sensor's, ros/publishers.py).
DEFAULT_TOPIC = '/imu/raw_data'
#: Body axes of REP-103 from the device's: the signs ``body_vector`` applies.
_ENU_SIGNS = np.array(body_vector((1.0, 1.0, 1.0), ENU))


class Samples(NamedTuple):
    """What the noise tool analyses: n samples of a sensor, node units, REP-103 axes."""

    time: np.ndarray           # (n,) s from the first
    gyro: np.ndarray           # (n, 3) rad/s
    accel: np.ndarray          # (n, 3) m/s^2
    mag: np.ndarray | None     # (m, 3) T, its valid readings only; None without a field
    source: str
    #: What the reader found wrong with the source (a capture cut short), for the report.
    notes: tuple[str, ...] = ()

    @property
    def rate_hz(self) -> float:
        """Return the sample rate: one over the median step."""
        steps = np.diff(self.time)
        return 1.0 / float(np.median(steps)) if steps.size else 0.0


def vectors(values: Iterable[Sequence[float]]) -> np.ndarray:
    """Return ``values`` as an (n, 3) array, (0, 3) when there are none."""
    return np.array(list(values), dtype=float).reshape(-1, 3)


def xyz(vector: Any) -> tuple[float, float, float]:
    """Return a message's Vector3 (or a quaternion's vector part) as a tuple."""
    return vector.x, vector.y, vector.z


def device_times(timers: Sequence[int], host_times: Sequence[float],
                 tolerance: float = 1.0) -> tuple[np.ndarray, list[int]]:
    """
    Unwrap the device timer into seconds from the first record; also the restarts.

    Each step is the timer's forward difference plus whichever number of
    whole periods (218.45 s) brings it closest to the host's elapsed receive
    time: that unwraps rollovers, including pauses longer than half a period
    that a timer-only unwrapper must take for resets. When no period count
    agrees with the host (within ``tolerance`` s plus 2 %), the timer has
    restarted (a power cycle, or separate captures joined): the host's
    elapsed time is used instead and the index is returned as a break.
    """
    step = (np.diff(np.asarray(timers, dtype=np.int64)) % TIMER_MODULUS) / TICKS_PER_SECOND
    host = np.maximum(np.diff(np.asarray(host_times, dtype=float)), 0.0)
    candidate = step + np.maximum(np.round((host - step) / TIMER_PERIOD), 0.0) * TIMER_PERIOD
    agrees = np.abs(candidate - host) <= tolerance + 0.02 * host
    times = np.cumsum(np.concatenate([[0.0], np.where(agrees, candidate, host)]))
    return times[:len(timers)], (np.nonzero(~agrees)[0] + 1).tolist()


def decode(chunks: Iterable[tuple[float, bytes]], address: int | None, wireless: bool,
           fields: Sequence[str]) -> tuple[list[tuple[float, Any]], int]:
    """Return each (receive time, record) of ``chunks`` with all ``fields``; the frames read."""
    parser, found = SensorStreamParser(address, wireless), []
    for receive_time, data in chunks:
        for event in parser.feed(data):
            record = getattr(event, 'record', None)
            if all(hasattr(record, name) for name in fields):
                found.append((receive_time, record))
    return found, parser.stats.good_frames


def capture_records(path: str, fields: Sequence[str]) -> tuple[list[tuple[float, Any]], int]:
    """:func:`decode` a capture, of the sensor and link its header names."""
    header, chunks = read_capture(path)
    address = header.get('address')
    return decode(chunks, address if isinstance(address, int) else None,
                  bool(header.get('wireless', True)), fields)


def from_capture(path: str) -> Samples:
    """
    Decode a capture (the node's, a fault capture, bringup's) into samples.

    The records that carry both acceleration and angular rate are kept, of
    the stream most of them are (replies to polls of another record are
    not part of the stream).
    """
    if os.path.isfile(path) and os.path.getsize(path) == 0:
        raise ValueError(f'{path}: an empty file (0 bytes), not a capture')
    with warnings.catch_warnings(record=True) as cut:
        warnings.simplefilter('always', TruncatedCaptureWarning)
        rows, frames = capture_records(path, ('angular_rate', 'accel', 'timer'))
    if not rows:
        raise ValueError(f'{path}: no record with acceleration and angular rate '
                         f'({frames} frames decoded)')
    kind = Counter(type(record) for _, record in rows).most_common(1)[0][0]
    rows = [(t, record) for t, record in rows if type(record) is kind]
    times = device_times([record.timer for _, record in rows], [t for t, _ in rows])[0]
    gyro = np.array([record.angular_rate for _, record in rows]) * _ENU_SIGNS
    accel = np.array([record.accel for _, record in rows]) * (_ENU_SIGNS * STANDARD_GRAVITY)
    mag = None
    if hasattr(kind, '_fields') and 'mag' in kind._fields:
        field = np.array([record.mag for _, record in rows])
        mag = field[~np.isnan(field).any(axis=1)] * (_ENU_SIGNS * TESLA_PER_GAUSS)
    notes = tuple(f'the capture was cut: {w.message}' for w in cut)
    return Samples(times, gyro, accel, mag, path, notes)


def imu_row(msg: Any) -> tuple[float, ...]:
    """Return an Imu message's stamp (s), angular velocity and acceleration, as one row."""
    s = msg.header.stamp
    return (s.sec + s.nanosec * 1e-9, *xyz(msg.angular_velocity), *xyz(msg.linear_acceleration))


def from_rows(rows: Sequence[tuple[float, ...]], mag: np.ndarray | None, source: str) -> Samples:
    """Return the samples of ``imu_row`` rows (of any order, one at least) in stamp order."""
    rows = np.array(rows)
    rows = rows[np.argsort(rows[:, 0], kind='stable')]
    return Samples(rows[:, 0] - rows[0, 0], rows[:, 1:4], rows[:, 4:7], mag, source)


def mag_topic(topic: str) -> str:
    """Return the field's topic of an Imu topic: its sibling ``mag``, as the driver names them."""
    return topic.rsplit('/', 1)[0] + '/mag'


def bag_messages(path: str, topic: str) -> Iterator[tuple[bool, Any]]:
    """
    Yield (whether it is an Imu message, the message) of ``topic`` and its mag topic in a bag.

    sqlite3 or MCAP, through rosbags (an optional extra); a bag without
    ``topic``, or one rosbags cannot read, is a ValueError that says so.
    """
    try:
        with bag_reader(Path(path)) as reader:
            known = {c.topic: c.msgtype for c in reader.connections}
            if topic not in known:
                imu_topics = sorted(t for t, kind in known.items() if kind.endswith('/Imu'))
                raise ValueError(f'{path}: no topic {topic!r}; its Imu topics: '
                                 f'{", ".join(imu_topics) or "none"}')
            wanted = [c for c in reader.connections if c.topic in (topic, mag_topic(topic))]
            read = deserializer(reader)
            for connection, _, raw in reader.messages(connections=wanted):
                yield connection.topic == topic, read(raw, connection.msgtype)
    except Exception as exc:     # rosbags' own errors (AnyReaderError...): a message, no trace
        if not type(exc).__module__.startswith('rosbags'):
            raise
        raise ValueError(f'{path}: not a readable bag ({type(exc).__name__}: {exc})') from None


def from_bag(path: str, topic: str = DEFAULT_TOPIC) -> Samples:
    """Read ``topic``'s sensor_msgs/Imu and the field of its mag topic from a rosbag2 bag."""
    rows, mag = [], []
    for imu, msg in bag_messages(path, topic):
        if imu:
            rows.append(imu_row(msg))
        else:
            mag.append(xyz(msg.magnetic_field))
    if not rows:
        raise ValueError(f'{path}: no message on {topic}')
    return from_rows(rows, np.array(mag) if mag else None, f'{path} ({topic})')
