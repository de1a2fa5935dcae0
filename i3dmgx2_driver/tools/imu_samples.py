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
rollovers, the host's receive times telling long pauses) or from the
messages' stamps (a bag).
"""

from collections import Counter
from collections.abc import Sequence
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

#: Period of the device timer (s).
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


def unwrap_timer(timers: np.ndarray, host: np.ndarray) -> np.ndarray:
    """
    Return seconds from the first record, from raw timers and host receive times.

    Each step is the timer's forward difference plus the whole periods
    (218.45 s) that bring it nearest the host's elapsed time, as the plot
    tool reads a capture (``plot.device_times``), on arrays.
    """
    if timers.size == 0:
        return np.zeros(0)
    step = (np.diff(timers.astype(np.int64)) % TIMER_MODULUS) / TICKS_PER_SECOND
    elapsed = np.maximum(np.diff(host), 0.0)
    periods = np.maximum(np.round((elapsed - step) / TIMER_PERIOD), 0.0)
    return np.concatenate([[0.0], np.cumsum(step + periods * TIMER_PERIOD)])


def from_capture(path: str) -> Samples:
    """
    Decode a capture (the node's, a fault capture, bringup's) into samples.

    The records that carry both acceleration and angular rate are kept, of
    the stream most of them are (replies to polls of another record are
    not part of the stream).
    """
    if os.path.isfile(path) and os.path.getsize(path) == 0:
        raise ValueError(f'{path}: an empty file (0 bytes), not a capture')
    header, chunks = read_capture(path)
    address = header.get('address')
    parser = SensorStreamParser(address if isinstance(address, int) else None,
                                bool(header.get('wireless', True)))
    rows = []
    with warnings.catch_warnings(record=True) as cut:
        warnings.simplefilter('always', TruncatedCaptureWarning)
        for receive_time, data in chunks:
            for event in parser.feed(data):
                record = getattr(event, 'record', None)
                if all(hasattr(record, name) for name in ('angular_rate', 'accel', 'timer')):
                    rows.append((receive_time, record))
    if not rows:
        raise ValueError(f'{path}: no record with acceleration and angular rate '
                         f'({parser.stats.good_frames} frames decoded)')
    kind = Counter(type(record) for _, record in rows).most_common(1)[0][0]
    rows = [(t, record) for t, record in rows if type(record) is kind]
    host = np.array([t for t, _ in rows])
    timers = np.array([record.timer for _, record in rows], dtype=np.int64)
    gyro = np.array([record.angular_rate for _, record in rows]) * _ENU_SIGNS
    accel = np.array([record.accel for _, record in rows]) * (_ENU_SIGNS * STANDARD_GRAVITY)
    mag = None
    if hasattr(kind, '_fields') and 'mag' in kind._fields:
        field = np.array([record.mag for _, record in rows])
        mag = field[~np.isnan(field).any(axis=1)] * (_ENU_SIGNS * TESLA_PER_GAUSS)
    notes = tuple(f'the capture was cut: {w.message}' for w in cut)
    return Samples(unwrap_timer(timers, host), gyro, accel, mag, path, notes)


def imu_row(msg: Any) -> tuple[float, ...]:
    """Return an Imu message's stamp (s), angular velocity and acceleration, as one row."""
    s, w, a = msg.header.stamp, msg.angular_velocity, msg.linear_acceleration
    return (s.sec + s.nanosec * 1e-9, w.x, w.y, w.z, a.x, a.y, a.z)


def from_rows(rows: Sequence[tuple[float, ...]], mag: np.ndarray | None, source: str) -> Samples:
    """Return the samples of ``imu_row`` rows (of any order, one at least) in stamp order."""
    rows = np.array(rows)
    rows = rows[np.argsort(rows[:, 0], kind='stable')]
    return Samples(rows[:, 0] - rows[0, 0], rows[:, 1:4], rows[:, 4:7], mag, source)


def from_bag(path: str, topic: str = DEFAULT_TOPIC, mag_topic: str | None = None) -> Samples:
    """
    Read ``topic``'s sensor_msgs/Imu (and ``mag_topic``'s field) from a rosbag2 bag.

    sqlite3 or MCAP, through rosbags (an optional extra). The mag topic
    defaults to the Imu topic's sibling ``mag``, as the driver names them.
    """
    mag_topic = topic.rsplit('/', 1)[0] + '/mag' if mag_topic is None else mag_topic
    rows, mag = [], []
    try:
        with bag_reader(Path(path)) as reader:
            known = {c.topic: c.msgtype for c in reader.connections}
            if topic not in known:
                imu_topics = sorted(t for t, kind in known.items() if kind.endswith('/Imu'))
                raise ValueError(f'{path}: no topic {topic!r}; its Imu topics: '
                                 f'{", ".join(imu_topics) or "none"}')
            wanted = [c for c in reader.connections if c.topic in (topic, mag_topic)]
            decode = deserializer(reader)
            for connection, _, raw in reader.messages(connections=wanted):
                msg = decode(raw, connection.msgtype)
                if connection.topic == topic:
                    rows.append(imu_row(msg))
                else:
                    field = msg.magnetic_field
                    mag.append((field.x, field.y, field.z))
    except Exception as exc:     # rosbags' own errors (AnyReaderError...): a message, no trace
        if not type(exc).__module__.startswith('rosbags'):
            raise
        raise ValueError(f'{path}: not a readable bag ({type(exc).__name__}: {exc})') from None
    if not rows:
        raise ValueError(f'{path}: no message on {topic}')
    return from_rows(rows, np.array(mag) if mag else None, f'{path} ({topic})')
