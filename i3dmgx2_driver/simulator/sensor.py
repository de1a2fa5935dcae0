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
The simulated 3DM-GX2 itself: a device model with no I/O and no clock.

``SimulatedSensor`` answers commands with records, both through the codec, so
the simulator can never disagree with the driver about a byte without the
codec being wrong for both. Time is passed in by the caller (wall-clock
seconds, as ``time.time()`` gives), which keeps the model deterministic for a
seed and lets tests run it faster than real time.

Its calculation cycles sit on an exact grid counted from power-up (or from the
last rate change), and its timer is derived from that grid, not from the
absolute time, so that the tick spacing of a stream is exact to the rounding
of one tick: ``384 * divider * (1 + ppm * 1e-6)`` ticks per cycle. The timer
starts close to its 32-bit rollover by default, so every run crosses it, and
runs ``clock_ppm`` fast, so a host has a drift to estimate.
"""

import math
import random
import struct
from typing import Any, ClassVar, NamedTuple

from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec import records as rec
from i3dmgx2_driver.codec.commands import (
    Command,
    decode_command,
    decode_record,
    encode_record,
)
from i3dmgx2_driver.codec.errors import CodecError
from i3dmgx2_driver.codec.orientation import euler_from_matrix
from i3dmgx2_driver.codec.timer import TIMER_MODULUS

from .motion import Motion, Vector3

#: Ticks per second of the device timer.
TICKS_PER_SECOND = rec.TICKS_PER_SECOND
#: Default timer at power-up: five seconds before the rollover.
DEFAULT_TIMER_START = TIMER_MODULUS - 5 * TICKS_PER_SECOND
#: The calculation rate is this divided by the EEPROM divider.
BASE_RATE_HZ = 51200
#: EEPROM word holding the rate divider, its factory value and valid range.
RATE_DIVIDER_ADDRESS = 0xFCA2
FACTORY_DIVIDER = 512
MIN_DIVIDER = 170
MAX_DIVIDER = 51200
#: EEPROM word of the power-up auto-start (LSB: command; MSB 0x80: wireless).
AUTOSTART_ADDRESS = 0xFCA6
#: What the EEPROM answers for a word nobody wrote (erased flash).
ERASED_WORD = 0xFFFF
#: 0xD0 answer for a quantity it does not know.
INVALID_QUANTITY = 0xFFFF

#: Data records: no request arguments, a timer in the reply. These can be
#: polled and streamed; derived from the codec's table, not listed by hand.
STREAMABLE = frozenset(
    code for code, layout in lay.LAYOUTS.items()
    if layout.reply and layout.reply[-1].name == 'timer'
    and not layout.request and not layout.confirm)

#: Commands a wired sensor recognises in its byte stream: every command of the
#: table but the wireless ping, which only a base station answers.
WIRED_COMMANDS = frozenset(code for code in lay.LAYOUTS if code != lay.PING)

_ACCEL_COUNTS_PER_G = 32768 / 5.0           # +-5 g over the 16-bit A/D range
_GYRO_COUNTS_PER_RAD_S = 32768 / 5.235988   # +-300 deg/s
_A2D_ZERO = 32768.0
_FLOAT3 = struct.Struct('>3f')


class Reply(NamedTuple):
    """One record the sensor sends, with when it was measured and sent."""

    #: Wall-clock time at which the sensor transmits it.
    due: float
    #: Wall-clock time of the data it carries (its calculation cycle).
    sample_time: float
    #: The record as the host decodes it (float32 values, exactly).
    record: Any
    #: The record bytes (echo byte and data, no checksum), from the codec.
    data: bytes

    @property
    def code(self) -> int:
        """Return the record's echo byte."""
        return self.data[0]


def _sub(a: Vector3, b: Vector3) -> Vector3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _scale(v: Vector3, k: float) -> Vector3:
    return (v[0] * k, v[1] * k, v[2] * k)


def _text16(text: str) -> str:
    if len(text) > 16:
        raise ValueError(f'identifier {text!r} is longer than 16 characters')
    text.encode('latin-1')
    return text.ljust(16)


class SimulatedSensor:
    """
    A 3DM-GX2 as the host sees it through its radio, without the radio.

    Call :meth:`handle` with each command the sensor receives; it returns the
    replies (a gyro-bias capture answers only after its sampling time, so a
    reply carries the time it is due). While :attr:`streaming` is set, the
    caller asks :attr:`next_sample_time` when the next cycle is and takes it
    with :meth:`stream_sample`. Not thread-safe: the caller serialises access.
    """

    def __init__(self, address: int = 95, serial_number: str = '3095',
                 motion: Motion | None = None, *, clock_ppm: float = 40.0,
                 timer_start: int | None = None, rate_hz: float | None = None,
                 firmware_version: int = 2103, model_number: str = '3DM-GX2',
                 model_name: str = '3DM-GX2 Wireless', options: str = '5g 300deg/s',
                 eeprom: dict[int, int] | None = None, temperature_c: float = 25.0,
                 seed: int | None = None, power_up_time: float = 0.0) -> None:
        if not 1 <= address <= 65534:
            raise ValueError(f'address must be in 1..65534, got {address}')
        if timer_start is not None and not 0 <= timer_start < TIMER_MODULUS:
            raise ValueError('timer_start must be a uint32')
        if rate_hz is not None and rate_hz <= 0:
            raise ValueError('rate_hz must be positive')
        self.address = address
        self.serial_number = serial_number
        self.motion = motion if motion is not None else Motion()
        self.clock_ppm = clock_ppm
        self.timer_start = DEFAULT_TIMER_START if timer_start is None else timer_start
        self.firmware_version = firmware_version
        self.identifiers = {0: _text16(model_number), 1: _text16(serial_number),
                            2: _text16(model_name), 3: _text16(options)}
        #: The EEPROM words; it persists across power cycles, like the real one.
        self.eeprom: dict[int, int] = {RATE_DIVIDER_ADDRESS: FACTORY_DIVIDER,
                                       AUTOSTART_ADDRESS: 0x0000}
        if eeprom:
            self.eeprom.update(eeprom)
        self.temperature_c = temperature_c
        self.rng = random.Random(seed)
        self._rate_override = rate_hz
        self._tick_rate = TICKS_PER_SECOND * (1.0 + clock_ppm * 1e-6)
        # Bias corrections stored "in non-volatile memory" (0xD0) survive power cycles.
        self._nv_accel: Vector3 = (0.0, 0.0, 0.0)
        self._nv_gyro: Vector3 = (0.0, 0.0, 0.0)
        self._lqi = 230.0
        self._rssi = 170.0
        #: Commands received but not understood or not allowed (counted, not answered).
        self.ignored = 0
        self.power_up(power_up_time)

    # -- power, time and the calculation cycle --------------------------------------------

    def power_up(self, t: float) -> None:
        """
        Start from power-up at wall-clock time ``t``.

        The timer restarts at ``timer_start``, the rate comes from the EEPROM
        divider (unless overridden), the bias corrections from non-volatile
        memory, and streaming from the auto-start word, as on the device.
        """
        self.power_up_time = t
        self.accel_correction: Vector3 = self._nv_accel
        self.gyro_correction: Vector3 = self._nv_gyro
        self._pending_gyro: tuple[float, Vector3] | None = None
        self._grid_origin = 0.0
        self._next_index = 0
        self.period = 1.0 / self.rate_hz
        autostart = self.eeprom.get(AUTOSTART_ADDRESS, 0) & 0xFF
        #: Command byte being streamed, 0 when polled.
        self.streaming = 0
        if autostart in STREAMABLE:
            self.start_streaming(autostart, t)

    def power_off(self) -> None:
        """
        Lose power (a wired sensor fed by its cable): the stream stops.

        The EEPROM and the non-volatile biases stay; :meth:`power_up` starts
        again from them.
        """
        self.streaming = 0
        self._pending_gyro = None

    @property
    def rate_hz(self) -> float:
        """Return the calculation rate (Hz): the override, or 51200 / EEPROM divider."""
        if self._rate_override is not None:
            return self._rate_override
        return BASE_RATE_HZ / self.eeprom.get(RATE_DIVIDER_ADDRESS, FACTORY_DIVIDER)

    def set_rate_override(self, rate_hz: float | None, t: float) -> None:
        """Force a rate beyond the device's range (benchmarks), or None to drop it."""
        if rate_hz is not None and rate_hz <= 0:
            raise ValueError('rate_hz must be positive')
        self._rate_override = rate_hz
        self._regrid(t)

    def _regrid(self, t: float) -> None:
        """Restart the cycle grid at ``t`` with the current rate (a rate change)."""
        self.period = 1.0 / self.rate_hz
        self._grid_origin = t - self.power_up_time
        self._next_index = 1

    def timer_at(self, t: float) -> int:
        """Return the timer the device shows at wall-clock time ``t``."""
        return self._timer_rel(t - self.power_up_time)

    def _timer_rel(self, rel: float) -> int:
        return (self.timer_start + round(rel * self._tick_rate)) % TIMER_MODULUS

    def _cycle_rel(self, index: int) -> float:
        return self._grid_origin + index * self.period

    def _latest_cycle_rel(self, rel: float) -> float:
        index = math.floor((rel - self._grid_origin) / self.period + 1e-9)
        return self._cycle_rel(max(index, 0))

    def _next_cycle_rel(self, rel: float) -> float:
        index = math.ceil((rel - self._grid_origin) / self.period - 1e-9)
        return self._cycle_rel(max(index, 0))

    def start_streaming(self, code: int, t: float) -> None:
        """Stream ``code`` from the first calculation cycle after ``t``."""
        if code not in STREAMABLE:
            raise ValueError(f'0x{code:02X} cannot be streamed')
        self.streaming = code
        rel = t - self.power_up_time
        self._next_index = max(math.floor((rel - self._grid_origin) / self.period) + 1, 0)
        while self._cycle_rel(self._next_index) <= rel:
            self._next_index += 1

    @property
    def next_sample_time(self) -> float | None:
        """Wall-clock time of the next streamed cycle, or None when not streaming."""
        if not self.streaming:
            return None
        return self.power_up_time + self._cycle_rel(self._next_index)

    def stream_sample(self) -> Reply:
        """Take the next streamed cycle (call when :attr:`next_sample_time` is due)."""
        rel = self._cycle_rel(self._next_index)
        self._next_index += 1
        t = self.power_up_time + rel
        return self._reply(self._record(self.streaming, rel), t, t)

    def skip_to(self, t: float) -> int:
        """Skip streamed cycles before ``t`` (a host too slow to keep up); return how many."""
        rel = t - self.power_up_time
        target = max(math.ceil((rel - self._grid_origin) / self.period), self._next_index)
        skipped = target - self._next_index
        self._next_index = target
        return skipped

    # -- commands ---------------------------------------------------------------------------

    def ping_reply(self, address: int) -> bytes:
        """Return the base station's answer to a ping: 0x02 if ours, else 0x21."""
        return bytes((lay.PING if address == self.address else 0x21,))

    def link_quality(self) -> tuple[int, int]:
        """Return (LQI, RSSI) of the next packet: plausible, slowly wandering."""
        gauss = self.rng.gauss
        self._lqi = min(255.0, max(120.0, self._lqi + 0.05 * (230.0 - self._lqi) + gauss(0, 3)))
        self._rssi = min(230.0, max(80.0, self._rssi + 0.05 * (170.0 - self._rssi)
                                    + gauss(0, 2)))
        return int(self._lqi), int(self._rssi)

    def record_at(self, code: int, t: float) -> Reply:
        """Return the data record ``code`` of the calculation cycle at or before ``t``."""
        if code not in STREAMABLE:
            raise ValueError(f'0x{code:02X} is not a data record')
        rel = self._latest_cycle_rel(t - self.power_up_time)
        return self._reply(self._record(code, rel), t, self.power_up_time + rel)

    def handle(self, command: bytes | Command, now: float) -> list[Reply]:
        """
        Act on one command received at ``now``; return the replies it causes.

        Commands that do not decode (wrong confirmation bytes) or that the
        device would refuse are ignored and counted in :attr:`ignored`: the
        real sensor answers nothing, and the host must time out and retry.
        """
        if not isinstance(command, Command):
            try:
                command = decode_command(bytes(command))
            except CodecError:
                self.ignored += 1
                return []
        code, args = command.code, command.args
        rel = now - self.power_up_time
        cycle = self._latest_cycle_rel(rel)
        cycle_time = self.power_up_time + cycle
        timer = self._timer_rel(cycle)
        if code in STREAMABLE:
            # A polled record is the one the next calculation cycle computes,
            # sent when that cycle completes.
            polled = self._next_cycle_rel(rel)
            polled_time = self.power_up_time + polled
            return [self._reply(self._record(code, polled), polled_time, polled_time)]
        if code == lay.SET_CONTINUOUS:
            target = args[0]
            if target == 0:
                self.streaming = 0
            elif target in STREAMABLE:
                self.start_streaming(target, now)
            else:
                self.ignored += 1
                return []
            return [self._reply(rec.ContinuousModeReply(target, timer), now, cycle_time)]
        if code == lay.STOP_CONTINUOUS:
            self.streaming = 0
            return []
        handler = self._HANDLERS.get(code)
        if handler is None:
            self.ignored += 1
            return []
        record, due, sample_time = handler(self, args, now, cycle, timer)
        return [self._reply(record, due, sample_time)]

    def _write_accel_bias(self, args, now, cycle, timer):
        self.accel_correction = self._float32(args[0])
        return rec.AccelBias(self.accel_correction, timer), now, now

    def _write_gyro_bias(self, args, now, cycle, timer):
        self.gyro_correction = self._float32(args[0])
        self._pending_gyro = None
        return rec.GyroBias(self.gyro_correction, timer), now, now

    def _capture_gyro_bias(self, args, now, cycle, timer):
        # The device averages its raw gyros over the sampling time: the true
        # bias if it is still, the bias plus the mean rotation if it is not.
        seconds = args[0] / 1000.0
        rel = now - self.power_up_time
        mean = self.motion.mean_rate(rel, rel + seconds)
        cycles = max(1.0, seconds * self.rate_hz)
        noise = self.motion.config.gyro_noise / math.sqrt(cycles)
        bias = self._float32(tuple(mean[i] + self.motion.config.gyro_bias[i]
                                   + self.rng.gauss(0.0, noise) for i in range(3)))
        self._pending_gyro = (rel + seconds, bias)
        return (rec.CapturedGyroBias(bias, self._timer_rel(rel + seconds)),
                now + seconds, now + seconds)

    def _transfer(self, args, now, cycle, timer):
        quantity = args[0]
        if quantity == 1:
            self._nv_accel = self.accel_correction
        elif quantity == 2:
            self._apply_pending_gyro(now - self.power_up_time)
            self._nv_gyro = self.gyro_correction
        else:
            quantity = INVALID_QUANTITY
        return rec.TransferToNonVolatile(quantity, timer), now, now

    def _write_eeprom(self, args, now, cycle, timer):
        address, value = args
        if address == RATE_DIVIDER_ADDRESS:
            # An invalid divider is not stored; the reply shows the word kept.
            if MIN_DIVIDER <= value <= MAX_DIVIDER:
                self.eeprom[address] = value
                self._regrid(now)
        else:
            self.eeprom[address] = value
        return rec.EepromWritten(self.eeprom.get(address, ERASED_WORD)), now, now

    def _read_eeprom(self, args, now, cycle, timer):
        return rec.EepromWord(self.eeprom.get(args[0], ERASED_WORD)), now, now

    def _firmware(self, args, now, cycle, timer):
        return rec.FirmwareVersion(self.firmware_version), now, now

    def _identifier(self, args, now, cycle, timer):
        selector = args[0]
        return rec.DeviceIdentifier(selector, self.identifiers.get(selector, ' ' * 16)), now, now

    def _built_in_test(self, args, now, cycle, timer):
        return rec.BuiltInTest(args[0]), now, now

    _HANDLERS: ClassVar[dict[int, Any]] = {
        lay.WRITE_ACCEL_BIAS: _write_accel_bias,
        lay.WRITE_GYRO_BIAS: _write_gyro_bias,
        lay.CAPTURE_GYRO_BIAS: _capture_gyro_bias,
        lay.TRANSFER_TO_NON_VOLATILE: _transfer,
        lay.WRITE_EEPROM: _write_eeprom,
        lay.READ_EEPROM: _read_eeprom,
        lay.FIRMWARE_VERSION: _firmware,
        lay.DEVICE_IDENTIFIER: _identifier,
        lay.BUILT_IN_TEST: _built_in_test,
    }

    # -- records ----------------------------------------------------------------------------

    @staticmethod
    def _float32(v: Vector3) -> Vector3:
        """Round to float32: the device keeps what fits in its registers."""
        return _FLOAT3.unpack(_FLOAT3.pack(*v))

    def _apply_pending_gyro(self, rel: float) -> None:
        if self._pending_gyro is not None and rel >= self._pending_gyro[0]:
            self.gyro_correction = self._pending_gyro[1]
            self._pending_gyro = None

    def temperature_codes(self, rel: float) -> tuple[int, tuple[int, int, int]]:
        """A/D codes of the four temperature sensors: ~25 C, warming up slowly."""
        warm = self.temperature_c + 2.0 * (1.0 - math.exp(-rel / 600.0))

        def code(celsius: float) -> int:
            value = (celsius / 100.0 + 0.5) * 4096.0 / 3.3 + self.rng.gauss(0.0, 0.4)
            return max(0, min(4095, round(value)))

        return code(warm), (code(warm + 1.0), code(warm + 1.5), code(warm + 0.5))

    def _record(self, code: int, rel: float) -> Any:
        """Build the record ``code`` for the calculation cycle at ``rel``."""
        self._apply_pending_gyro(rel)
        timer = self._timer_rel(rel)
        if code == lay.TEMPERATURES:
            accel_code, gyro_codes = self.temperature_codes(rel)
            return rec.Temperatures(accel_code, gyro_codes, timer)
        meas = self.motion.measure(rel, self.rng)
        m = meas.truth.matrix
        accel = _sub(meas.accel, self.accel_correction)
        rate = _sub(meas.angular_rate, self.gyro_correction)
        mag = meas.mag
        dt = self.period
        if code == lay.ACCEL_ANG_RATE_MAG_ORIENTATION:
            return rec.AccelAngRateMagOrientation(accel, rate, mag, m, timer)
        if code == lay.ACCEL_ANG_RATE_MAG:
            return rec.AccelAngRateMag(accel, rate, mag, timer)
        if code == lay.ACCEL_ANG_RATE:
            return rec.AccelAngRate(accel, rate, timer)
        if code == lay.ACCEL_ANG_RATE_ORIENTATION:
            return rec.AccelAngRateOrientation(accel, rate, m, timer)
        if code == lay.RAW_ACCEL_ANG_RATE:
            return rec.RawAccelAngRate(
                tuple(_A2D_ZERO + a * _ACCEL_COUNTS_PER_G for a in accel),
                tuple(_A2D_ZERO + w * _GYRO_COUNTS_PER_RAD_S for w in rate), timer)
        if code == lay.DELTA_ANGLE_VELOCITY:
            return rec.DeltaAngleVelocity(_scale(rate, dt), _scale(accel, dt), timer)
        if code == lay.DELTA_ANGLE_VELOCITY_MAG:
            return rec.DeltaAngleVelocityMag(_scale(rate, dt), _scale(accel, dt), mag, timer)
        if code == lay.ORIENTATION_MATRIX:
            return rec.OrientationMatrix(m, timer)
        if code == lay.ORIENTATION_UPDATE_MATRIX:
            return rec.OrientationUpdateMatrix(self.motion.update_matrix(rel, dt), timer)
        if code == lay.MAGNETOMETER:
            return rec.Magnetometer(mag, timer)
        if code == lay.EULER_ANGLES:
            return rec.EulerAngles(*euler_from_matrix(m), timer)
        if code == lay.EULER_ANGLES_ANG_RATE:
            return rec.EulerAnglesAngRate(*euler_from_matrix(m), rate, timer)
        if code == lay.STABILISED_ACCEL_ANG_RATE_MAG:
            # Gyro-stabilised vectors are the filter's estimates: smooth, biased alike.
            bias = self.motion.config.accel_bias
            stab_accel = _sub(tuple(meas.truth.accel[i] + bias[i] for i in range(3)),
                              self.accel_correction)
            stab_mag = mag if math.isnan(mag[0]) else meas.truth.mag
            return rec.StabilisedAccelAngRateMag(stab_accel, rate, stab_mag, timer)
        raise ValueError(f'0x{code:02X} is not a data record')  # pragma: no cover

    def _reply(self, record: Any, due: float, sample_time: float) -> Reply:
        """Encode through the codec, and keep the record as the host will decode it."""
        data = encode_record(record)
        return Reply(due, sample_time, decode_record(data), data)
