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
seed and lets tests run it faster than real time. What a sensor is
(address, identifiers, firmware, clock error, EEPROM presets) is a ``SensorSpec``;
its firmware leaves every command newer than it unanswered, as a real sensor does.

Its calculation cycles and timer are a ``CycleClock`` (``cycle_clock``):
an exact grid from power-up. The timer starts close to its 32-bit rollover
by default, so every run crosses it, and runs ``clock_ppm`` fast, so a host
has a drift to estimate. Its data records are made by a ``RecordMaker``
(``data_records``) from the motion, less the host's bias corrections.
Its EEPROM, with the rate divider and the auto-start it holds, is a
``SensorEeprom`` (``eeprom``).
"""

import dataclasses
import math
import random
from typing import Any, ClassVar, NamedTuple

from i3dmgx2_driver.codec import command_firmware as firmware, framing
from i3dmgx2_driver.codec import layouts as lay, records as rec
from i3dmgx2_driver.codec.commands import Command, decode_command, decode_record, encode_record
from i3dmgx2_driver.codec.errors import CodecError
from i3dmgx2_driver.codec.timer import TIMER_MODULUS

from .cycle_clock import CycleClock
from .data_records import BiasCorrections, float32, RecordMaker
# The EEPROM's words and limits are read here by the configuration, the command line
# and the harness, as they always were.
from .eeprom import SensorEeprom
from .motion import Motion

#: Default timer at power-up: five seconds before the rollover.
DEFAULT_TIMER_START = TIMER_MODULUS - 5 * rec.TICKS_PER_SECOND
#: Data records: these can be polled and streamed (the codec's table says which).
STREAMABLE = lay.STREAMABLE
#: Their codes as a message lists them.
STREAMABLE_TEXT = ', '.join(f'0x{code:02X}' for code in sorted(STREAMABLE))
#: Firmware of a simulated sensor unless told: one that answers every command.
DEFAULT_FIRMWARE = firmware.NEWEST

#: Commands a wired sensor recognises in its byte stream: every command of the
#: table but the wireless ping, which only a base station answers.
WIRED_COMMANDS = frozenset(code for code in lay.LAYOUTS if code != lay.PING)


def decoded(raw: bytes) -> Command | None:
    """Return the command ``raw`` holds, or None where it does not decode (not answered)."""
    try:
        return decode_command(raw)
    except CodecError:
        return None


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


def _text16(text: str) -> str:
    if len(text) > 16:
        raise ValueError(f'identifier {text!r} is longer than 16 characters')
    text.encode('latin-1')
    return text.ljust(16)


@dataclasses.dataclass(frozen=True)
class SensorSpec:
    """What one 3DM-GX2 is: its identity, its clock, and the EEPROM it powers up with."""

    #: Node address (factory: last two digits of the serial number), 1..65534.
    address: int = 95
    #: Serial number it reports (identifier 1).
    serial_number: str = '3095'
    #: Error of its clock (ppm; positive: its timer runs fast).
    clock_ppm: float = 40.0
    #: Timer at power-up (None: 5 s before the 32-bit rollover).
    timer_start: int | None = None
    #: Calculation rate (Hz) overriding the EEPROM divider (None: the divider's).
    rate_hz: float | None = None
    #: Firmware as 0xE9 reports it (2113: 2.1.13); a command newer than it goes
    #: unanswered, as on a real sensor (codec/command_firmware.py says which).
    firmware_version: int = DEFAULT_FIRMWARE
    model_number: str = '3DM-GX2'
    model_name: str = '3DM-GX2 Wireless'
    options: str = '5g 300deg/s'
    #: EEPROM words on top of the factory ones (address -> value).
    eeprom: dict[int, int] | None = None
    #: Temperature (C) its sensors read at power-up.
    temperature_c: float = 25.0

    def __post_init__(self) -> None:
        """Reject what no sensor can be, naming the field."""
        if not framing.MIN_ADDRESS <= self.address <= framing.MAX_ADDRESS:
            raise ValueError(f'address must be in {framing.MIN_ADDRESS}..{framing.MAX_ADDRESS}, '
                             f'got {self.address}')
        if self.timer_start is not None and not 0 <= self.timer_start < TIMER_MODULUS:
            raise ValueError('timer_start must be a uint32')
        if self.rate_hz is not None and self.rate_hz <= 0:
            raise ValueError('rate_hz must be positive')

    @property
    def identifiers(self) -> dict[int, str]:
        """Return the 0xEA identifiers by selector, 16 characters each."""
        return {0: _text16(self.model_number), 1: _text16(self.serial_number),
                2: _text16(self.model_name), 3: _text16(self.options)}


class SimulatedSensor:
    """
    A 3DM-GX2 as the host sees it through its radio, without the radio.

    Call :meth:`handle` with each command the sensor receives; it returns the
    replies (a gyro-bias capture answers only after its sampling time, so a
    reply carries the time it is due). While :attr:`streaming` is set, the
    caller asks :attr:`next_sample_time` when the next cycle is and takes it
    with :meth:`stream_sample`. Not thread-safe: the caller serialises access.
    """

    def __init__(self, spec: SensorSpec | None = None, motion: Motion | None = None, *,
                 seed: int | None = None, power_up_time: float = 0.0) -> None:
        spec = spec if spec is not None else SensorSpec()
        self.address, self.firmware_version = spec.address, spec.firmware_version
        self.identifiers = spec.identifiers
        #: The EEPROM and the settings it holds; it persists across power cycles.
        self.settings = SensorEeprom(spec.eeprom, spec.rate_hz)
        #: The EEPROM words (the settings' own dict).
        self.eeprom: dict[int, int] = self.settings.words
        self.rng = random.Random(seed)
        #: The calculation cycles and the timer.
        self.clock = CycleClock(spec.clock_ppm, DEFAULT_TIMER_START if spec.timer_start is None
                                else spec.timer_start)
        #: The bias corrections the host set.
        self.biases = BiasCorrections()
        #: The motion the sensor goes through.
        self.motion = motion if motion is not None else Motion()
        self._maker = RecordMaker(self.motion, self.rng, spec.temperature_c, self.biases)
        self._lqi, self._rssi = 230.0, 170.0
        #: Commands received but not understood or not allowed (counted, not answered).
        self.ignored = 0
        self.power_up(power_up_time)

    # -- power, time and the calculation cycle --------------------------------------------

    def power_up(self, t: float, timer_start: int | None = None) -> None:
        """
        Start from power-up at wall-clock time ``t``.

        The timer restarts at ``timer_start`` if given (kept from then on),
        else at ``clock.timer_start``; the rate comes from the EEPROM
        divider (unless overridden), the bias corrections from non-volatile
        memory, and streaming from the auto-start word, as on the device.
        """
        self.biases.restore()
        self.clock.restart(t, self.rate_hz, timer_start)
        #: Command byte being streamed, 0 when polled.
        self.streaming = 0
        if (autostart := self.settings.autostart) in STREAMABLE:
            self.start_streaming(autostart, t)

    def power_off(self) -> None:
        """
        Lose power (a wired sensor fed by its cable): the stream stops.

        The EEPROM and the non-volatile biases stay; :meth:`power_up` starts
        again from them.
        """
        self.streaming = 0
        self.biases.forget_capture()

    @property
    def rate_hz(self) -> float:
        """Return the calculation rate (Hz): the override, or 51200 / EEPROM divider."""
        return self.settings.rate_hz

    def set_rate_override(self, rate_hz: float | None, t: float) -> None:
        """Force a rate beyond the device's range (benchmarks), or None to drop it."""
        if rate_hz is not None and rate_hz <= 0:
            raise ValueError('rate_hz must be positive')
        self.settings.rate_override = rate_hz
        self.clock.regrid(t, self.rate_hz)

    def start_streaming(self, code: int, t: float) -> None:
        """Stream ``code`` from the first calculation cycle after ``t``."""
        if code not in STREAMABLE:
            raise ValueError(f'0x{code:02X} cannot be streamed')
        self.streaming = code
        self.clock.stream_from(t)

    @property
    def next_sample_time(self) -> float | None:
        """Wall-clock time of the next streamed cycle, or None when not streaming."""
        return self.clock.next_time if self.streaming else None

    def stream_sample(self) -> Reply:
        """Take the next streamed cycle (call when :attr:`next_sample_time` is due)."""
        return self._sample(self.streaming, self.clock.take())

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
        return self._sample(code, self.clock.latest_cycle_rel(self.clock.rel(t)), t)

    def handle(self, command: bytes | Command, now: float) -> list[Reply]:
        """
        Act on one command received at ``now``; return the replies it causes.

        Commands that do not decode (wrong confirmation bytes), that the
        device would refuse, or that are newer than its firmware (a stream of
        such a record included) are ignored and counted in :attr:`ignored`:
        the real sensor answers nothing, and the host must time out and retry.
        """
        if not isinstance(command, Command):
            command = decoded(bytes(command))
        version = self.firmware_version
        if command is None or not firmware.has(version, command.code) or (
                command.code == lay.SET_CONTINUOUS and command.args[0] in lay.LAYOUTS
                and not firmware.has(version, command.args[0])):
            self.ignored += 1
            return []
        code, args = command.code, command.args
        rel = self.clock.rel(now)
        cycle = self.clock.latest_cycle_rel(rel)
        cycle_time, timer = self.clock.power_up_time + cycle, self.clock.timer_rel(cycle)
        if code in STREAMABLE:
            # A polled record is the one the next calculation cycle computes,
            # sent when that cycle completes.
            return [self._sample(code, self.clock.next_cycle_rel(rel))]
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
        if code == lay.CAPTURE_GYRO_BIAS:
            return [self._capture_gyro_bias(args[0] / 1000.0, now)]
        answer = self._ANSWERS.get(code)
        if answer is None:
            self.ignored += 1
            return []
        return [self._reply(answer(self, args, now, timer), now, now)]

    def _capture_gyro_bias(self, seconds: float, now: float) -> Reply:
        # The device averages its raw gyros over the sampling time: the true
        # bias if it is still, the bias plus the mean rotation if it is not.
        rel, motion = self.clock.rel(now), self.motion
        mean = motion.mean_rate(rel, rel + seconds)
        noise = motion.config.gyro_noise / math.sqrt(max(1.0, seconds * self.rate_hz))
        bias = float32(tuple(mean[i] + motion.config.gyro_bias[i]
                             + self.rng.gauss(0.0, noise) for i in range(3)))
        self.biases.capture_gyro(rel + seconds, bias)
        return self._reply(rec.CapturedGyroBias(bias, self.clock.timer_rel(rel + seconds)),
                           now + seconds, now + seconds)

    def _write_accel_bias(self, args, now, timer):
        self.biases.accel = float32(args[0])
        return rec.AccelBias(self.biases.accel, timer)

    def _write_gyro_bias(self, args, now, timer):
        self.biases.set_gyro(float32(args[0]))
        return rec.GyroBias(self.biases.gyro, timer)

    def _transfer(self, args, now, timer):
        # The RAM corrections go to non-volatile memory, which a power-up loads;
        # unless the memory refuses (then nothing is stored, and 0xFFFF says so).
        return rec.TransferToNonVolatile(rec.INVALID_QUANTITY if self.settings.refuse_bias_store
                                         else self.biases.store(args[0], self.clock.rel(now)),
                                         timer)

    def _write_eeprom(self, args, now, timer):
        address, value = args
        if self.settings.write(address, value):
            self.clock.regrid(now, self.rate_hz)
        return rec.EepromWritten(self.settings.read(address))

    #: The answer to each command that is not a data record, a stream or a capture.
    _ANSWERS: ClassVar[dict[int, Any]] = {
        lay.WRITE_ACCEL_BIAS: _write_accel_bias,
        lay.WRITE_GYRO_BIAS: _write_gyro_bias,
        lay.TRANSFER_TO_NON_VOLATILE: _transfer,
        lay.WRITE_EEPROM: _write_eeprom,
        lay.READ_EEPROM: lambda self, args, *_: rec.EepromWord(self.settings.read(args[0])),
        lay.FIRMWARE_VERSION: lambda self, *_: rec.FirmwareVersion(self.firmware_version),
        lay.DEVICE_IDENTIFIER: lambda self, args, *_: rec.DeviceIdentifier(
            args[0], self.identifiers.get(args[0], ' ' * 16)),
        lay.BUILT_IN_TEST: lambda self, args, *_: rec.BuiltInTest(args[0]),
    }

    # -- records ----------------------------------------------------------------------------

    def _sample(self, code: int, rel: float, due: float | None = None) -> Reply:
        """Return the record ``code`` of the calculation cycle at ``rel``, sent then or ``due``."""
        self.biases.apply_capture(rel)
        record = self._maker.record(code, rel, self.clock.timer_rel(rel), self.clock.period)
        sample_time = self.clock.power_up_time + rel
        return self._reply(record, sample_time if due is None else due, sample_time)

    def _reply(self, record: Any, due: float, sample_time: float) -> Reply:
        """Encode through the codec, and keep the record as the host will decode it."""
        data = encode_record(record)
        return Reply(due, sample_time, decode_record(data), data)
