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
A sensor at rest for an hour, as the reads a host makes of it, in seconds of wall time.

The running simulator makes one record a cycle through the codec, as the
device does: right for a driver, far too slow for an hour of samples to
measure noise on (900,000 records at 250 Hz). Here the records of a still
sensor are made all at once with numpy: the truth (gravity's reaction and
the Earth's field at the resting pose of ``MotionConfig``, the gyro and
accelerometer biases), plus the noise of a ``NoiseModel``, packed into the
layout the codec's table gives for the stream (big-endian float32 fields,
the timer) and framed as wireless data packets or wired records, with the
checksums summed in numpy. The codec itself stays free of numpy; the tests
check these bytes against its encoder, record for record.

A still sensor is also disturbed as recordings are: tilted (gravity turns
about the device's x axis while the gyro reads the turn), knocked (a
ringing that averages out of a second's mean), or with a dead axis (no
noise at all). What comes out are ``(receive_time, bytes)`` chunks, as a
capture holds them: a tool or a test writes them with ``capture.file_format``
(and cuts the file to make a cut capture).
"""

from collections.abc import Iterator, Sequence
import dataclasses
import math

from i3dmgx2_driver.codec import framing, layouts as lay
from i3dmgx2_driver.codec.records import TICKS_PER_SECOND
from i3dmgx2_driver.codec.timer import TIMER_MODULUS
import numpy as np

from .motion import Motion, MotionConfig
from .noise_model import NoiseConfig, NoiseModel
from .sensor import DEFAULT_TIMER_START

#: Quantities of a still sensor that the fields of a record may ask for.
_STILL_FIELDS = ('accel', 'angular_rate', 'mag', 'matrix', 'timer')
#: Records made at once; a block's chunks are yielded before the next is made.
BLOCK = 1 << 15
#: A tilt turns at a steady rate over this long (s).
TILT_S = 1.0
#: A knock: a ringing at this frequency (Hz) under a Gaussian of this width (s), of this
#: amplitude on the accelerometer (g) and the gyro (rad/s): no mean left in a second's.
KNOCK_HZ, KNOCK_S, KNOCK_G, KNOCK_RAD_S = 40.0, 0.05, 0.3, 0.2


def _still(layout: lay.Layout) -> bool:
    """Whether a still capture makes every field of ``layout``: still quantities, timer last."""
    names = [field.name for field in layout.reply or ()]
    return bool(names) and names[-1] == 'timer' and set(names) <= set(_STILL_FIELDS)


def record_dtype(code: int) -> np.dtype:
    """Return the numpy layout of record ``code`` (echo byte first), from the codec's table."""
    layout = lay.LAYOUTS[code]
    if not _still(layout):
        usable = sorted(f'0x{c:02X}' for c, other in lay.LAYOUTS.items() if _still(other))
        raise ValueError(f'stream 0x{code:02X} has fields a still capture does not make; '
                         f'one of {", ".join(usable)}')
    kinds = {'f': '>f4', 'I': '>u4'}
    return np.dtype([('echo', 'u1')] + [(field.name, kinds[field.code],
                                         (field.count,) if field.count > 1 else ())
                                        for field in layout.reply])


def _checksums(data: np.ndarray) -> np.ndarray:
    """Return the 16-bit sum of each row of bytes (codec.checksum.checksum16), big-endian."""
    total = data.astype(np.uint32).sum(axis=1) & 0xFFFF
    return np.stack([total >> 8, total & 0xFF], axis=1).astype(np.uint8)


def frame(records: np.ndarray, wireless: bool, address: int, lqi: int = 230,
          rssi: int = 170) -> np.ndarray:
    """Frame rows of record bytes as wireless data packets or wired records: rows of bytes."""
    n, size = records.shape
    if not wireless:
        return np.concatenate([records, _checksums(records)], axis=1)
    header = np.frombuffer(bytes((framing.SOP, framing.DATA_FLAGS, 0, address >> 8,
                                  address & 0xFF, size + 1, 0)), np.uint8)
    body = np.concatenate([np.broadcast_to(header, (n, header.size)), records], axis=1)
    link = np.broadcast_to(np.array([lqi, rssi], np.uint8), (n, 2))
    return np.concatenate([body, link, _checksums(body[:, 1:])], axis=1)


def disturb(t: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
            tilts: Sequence[tuple[float, float]], knocks: Sequence[float]) -> None:
    """
    Add tilts ``(start s, degrees)`` and knocks (times, s) to samples at ``t``, in place.

    A tilt turns the device about its x axis at a steady rate for ``TILT_S``:
    the gyro reads the rate, the accelerometer's gravity turns with it. A
    knock rings about its time, and averages out of any mean around it.
    """
    angle = np.zeros(t.size)
    for start, degrees in tilts:
        ramp = np.clip((t - start) / TILT_S, 0.0, 1.0)
        angle += math.radians(degrees) * ramp
        gyro[:, 0] += math.radians(degrees) / TILT_S * ((ramp > 0) & (ramp < 1))
    cos, sin = np.cos(angle), np.sin(angle)
    accel[:, 1], accel[:, 2] = cos * accel[:, 1] - sin * accel[:, 2], \
        sin * accel[:, 1] + cos * accel[:, 2]
    for when in knocks:
        age = t - when
        ring = np.cos(2 * math.pi * KNOCK_HZ * age) * np.exp(-0.5 * (age / KNOCK_S) ** 2)
        accel += KNOCK_G * ring[:, None]
        gyro += KNOCK_RAD_S * ring[:, None]


def still_chunks(seconds: float, rate_hz: float, code: int = lay.ACCEL_ANG_RATE,
                 wireless: bool = True, address: int = 95,
                 noise: NoiseConfig | None = None, motion: MotionConfig | None = None,
                 seed: int | None = None, start_time: float = 1_700_000_000.0,
                 per_read: int = 8, timer_start: int = DEFAULT_TIMER_START,
                 tilts: Sequence[tuple[float, float]] = (), knocks: Sequence[float] = (),
                 dead: Sequence[int] = ()) -> Iterator[tuple[float, bytes]]:
    """
    Yield the reads of a sensor at rest streaming ``code`` at ``rate_hz`` for ``seconds``.

    Each read holds ``per_read`` records and arrives when its last one is
    sampled (plus nothing: the line's delays do not matter to noise). The
    timer advances by the whole number of ticks nearest a period, from
    ``timer_start`` (by default near its rollover, which the reader must unwrap).
    ``tilts`` and ``knocks`` disturb it (``disturb``); the ``dead`` axes
    (0-5: gyro x, y, z, accelerometer x, y, z, the device's) have no noise.
    """
    if not rate_hz > 0 or not seconds > 0 or per_read < 1:
        raise ValueError(f'rate_hz and seconds must be positive and per_read >= 1, got '
                         f'{rate_hz!r}, {seconds!r}, {per_read!r}')
    dtype = record_dtype(code)
    motion = motion if motion is not None else MotionConfig()
    # What the sensor reads at its resting pose without noise, biases included.
    truth = Motion(dataclasses.replace(motion, static=True)).state(0.0)
    gyro_truth = np.asarray(motion.gyro_bias)
    accel_truth = np.asarray(truth.accel) + motion.accel_bias
    model = NoiseModel(noise, seed)
    ticks = round(TICKS_PER_SECOND / rate_hz)
    dt = ticks / TICKS_PER_SECOND
    total = math.floor(seconds / dt)
    rng = np.random.default_rng(None if seed is None else seed + 1)
    for begin in range(0, total, BLOCK):
        n = min(BLOCK, total - begin)
        index = np.arange(begin, begin + n)
        records = np.zeros(n, dtype)
        records['echo'] = code
        errors = model.draw(n, dt)
        errors[:, list(dead)] = 0.0
        gyro = gyro_truth + errors[:, :3]
        accel = accel_truth + errors[:, 3:]
        disturb(index * dt, gyro, accel, tilts, knocks)
        for name, value in (('angular_rate', gyro), ('accel', accel), ('matrix', truth.matrix)):
            if name in dtype.names:
                records[name] = value
        if 'mag' in dtype.names:
            records['mag'] = np.asarray(truth.mag) + rng.normal(0.0, motion.mag_noise, (n, 3))
        records['timer'] = (timer_start + index * ticks) % TIMER_MODULUS
        rows = frame(records.view(np.uint8).reshape(n, dtype.itemsize), wireless, address)
        for first in range(0, n, per_read):
            last = min(first + per_read, n)
            yield start_time + (begin + last) * dt, rows[first:last].tobytes()
