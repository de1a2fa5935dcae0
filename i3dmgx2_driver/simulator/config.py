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
How a simulated 3DM-GX2 is set up: sensor, link, presets, timing and faults.

One dataclass, checked when it is made, so that a test or the command line
learns of a setting that cannot work before anything starts, with the field
named. The EEPROM presets (``divider``, ``eeprom``, ``streaming_at_start``)
are the state a sensor set up earlier would power up in.
"""

import dataclasses

from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec.data_rate import MAX_DIVIDER, MIN_DIVIDER, RATE_DIVIDER_ADDRESS

from . import sensor as sns
from .eeprom import AUTOSTART_ADDRESS
from .faults import FaultConfig
from .motion import MotionConfig

#: Record streamed when "already streaming" is asked for without a command.
DEFAULT_STREAM = lay.ACCEL_ANG_RATE_MAG_ORIENTATION


@dataclasses.dataclass
class SimulatorConfig:
    """Everything a simulated base station and sensor can be set up with."""

    #: Node address of the sensor (factory: last two digits of its serial number).
    address: int = 95
    #: Several sensors behind the one base station: their addresses, the first
    #: being ``address`` (set from it); () or one address: one sensor. The first
    #: is set up as the fields below say, the others differ from it (sensor_unit.py).
    addresses: tuple[int, ...] = ()
    #: The sensor the timed faults (``stall_at``, ``power_cycle_at``) hit; None:
    #: a stall silences the base station (every sensor), a power cycle hits the first.
    fault_address: int | None = None
    #: True: a wireless sensor behind its base station (packets, ACK/NACK, ping).
    #: False: a wired sensor on the port itself: raw command bytes in, wired
    #: records (echo, data, checksum) out, no ACK/NACK, no ping (see PtySimulator).
    wireless: bool = True
    #: Serial number the sensor reports (identifier 1).
    serial_number: str = '3095'
    #: Calculation rate (Hz) overriding the EEPROM divider: for benchmarks beyond 300 Hz.
    rate_hz: float | None = None
    #: Command byte the sensor streams from power-up (True: 0xCC; False/0: polled):
    #: the EEPROM auto-start word 0xFCA6 (MSB 0x80 wireless, 0x00 wired).
    streaming_at_start: bool | int = False
    #: EEPROM data-rate divider (0xFCA2) at power-up, 170..51200 (rate 51200 / divider
    #: Hz); None: the factory 512 (100 Hz), or what ``eeprom`` says.
    divider: int | None = None
    #: EEPROM words at power-up (address -> value), as a sensor set up earlier
    #: would keep them; ``divider`` and ``streaming_at_start`` win over these.
    eeprom: dict[int, int] = dataclasses.field(default_factory=dict)
    #: Seed of every random choice (noise, faults, chunking), for reproducible runs.
    seed: int | None = None
    motion: MotionConfig = dataclasses.field(default_factory=MotionConfig)
    faults: FaultConfig = dataclasses.field(default_factory=FaultConfig)
    #: Shortcut for ``motion.nan_mag``: no magnetometer, NaN fields (Inertia-Link).
    nan_mag: bool = False
    #: Shortcut for ``motion.mag_nan_probability``: NaN on that share of cycles.
    mag_nan_probability: float = 0.0
    #: Error of the sensor's clock (ppm; positive: its timer runs fast).
    clock_ppm: float = 40.0
    #: Timer at power-up (None: 5 s before the 32-bit rollover).
    timer_start: int | None = None
    #: Firmware as 0xE9 reports it (2103: 2.1.03): commands newer than it go unanswered.
    #: The default answers every command.
    firmware_version: int = sns.DEFAULT_FIRMWARE
    #: Firmware of single sensors among several (address -> version), over ``firmware_version``.
    firmware_versions: dict[int, int] = dataclasses.field(default_factory=dict)
    #: Radio latency (s) between the sensor sending a packet and the host getting it.
    latency_s: float = 0.002
    #: Baud rate of the serial line between the base station and the host: a
    #: packet's last byte arrives its wire time (10 bits a byte) after its first,
    #: so each packet is written that much later (throughput is not limited;
    #: see ``limit_to_line_rate``). None: bytes arrive at once, as over USB.
    wire_baud: int | None = 115200
    #: Each packet is written in a random number of chunks in this range.
    chunks: tuple[int, int] = (1, 3)
    #: Pause between the chunks of one packet (s), so that reads see them apart.
    chunk_gap_s: float = 0.0
    #: Fixed path for the port symlink (None: a private temporary directory).
    symlink: str | None = None
    #: Most truth entries kept (None: all; 0: none, for long demos).
    truth_limit: int | None = None
    #: Skip streamed cycles the 115200-baud line could not carry, as the device does.
    limit_to_line_rate: bool = False
    #: When the writer falls this far behind (s), it skips cycles instead of bursting.
    max_lag_s: float = 1.0
    #: The base station's serial line carries one packet at a time (one sensor): a
    #: packet that arrives over the radio while the one before is still on the line
    #: waits behind it, and the garbage and foreign packets written before it take
    #: their time on the line too. A line run near its limit then holds a queue,
    #: which leaves one packet (and what came with it) a wire time; needs ``wire_baud``.
    line_queue: bool = False
    #: After a gap in the stream (0.1 s or more, a stall), the first packet reaches the
    #: base station's line this much later (s; the radio link coming back), and the
    #: packets sampled meanwhile queue behind it (with ``line_queue``).
    radio_hold_s: float = 0.0
    #: Point the port symlink at /proc/<pid>/fd/<slave> rather than /dev/pts/N, so
    #: that it dangles when the simulator dies, however it dies (see pty_port).
    link_via_proc: bool = True

    def __post_init__(self) -> None:
        """Reject settings that cannot work, naming the field."""
        # The sensor's own checks: address, timer_start, rate_hz.
        self.addresses = tuple(self.addresses)
        if self.addresses:
            self.address = self.addresses[0]
        for address in self.all_addresses:
            sns.SensorSpec(address, timer_start=self.timer_start, rate_hz=self.rate_hz)
        if len(set(self.all_addresses)) != len(self.all_addresses):
            raise ValueError(f'addresses must differ, got {self.addresses}')
        if len(self.all_addresses) > 1 and not self.wireless:
            raise ValueError('several sensors need a base station (wireless), not a wired line')
        for address, version in {0: self.firmware_version, **self.firmware_versions}.items():
            if address and address not in self.all_addresses:
                raise ValueError(f'firmware_versions: {address} is none of the sensors '
                                 f'{self.all_addresses}')
            if not 0 < version <= 0xFFFFFFFF:
                raise ValueError(f'firmware_version must be a positive uint32 (2103 for '
                                 f'2.1.03), got {version}')
        if self.fault_address is not None and self.fault_address not in self.all_addresses:
            raise ValueError(f'fault_address {self.fault_address} is none of the sensors '
                             f'{self.all_addresses}')
        if not 1 <= self.chunks[0] <= self.chunks[1]:
            raise ValueError(f'chunks must be (min, max) with 1 <= min <= max, got {self.chunks}')
        if self.latency_s < 0 or self.chunk_gap_s < 0 or self.radio_hold_s < 0:
            raise ValueError('latency_s, chunk_gap_s and radio_hold_s must not be negative')
        if self.line_queue and (not self.wire_baud or len(self.all_addresses) > 1):
            raise ValueError('line_queue needs wire_baud and one sensor (several sensors '
                             'share the line in turn already)')
        if self.radio_hold_s and not self.line_queue:
            raise ValueError('radio_hold_s needs line_queue (the packets queue behind it)')
        if self.divider is not None and not MIN_DIVIDER <= self.divider <= MAX_DIVIDER:
            raise ValueError(f'divider must be in {MIN_DIVIDER}..{MAX_DIVIDER} '
                             f'(rate 51200 / divider Hz), got {self.divider}')
        for address, value in self.eeprom.items():
            if not (0 <= address <= 0xFFFF and 0 <= value <= 0xFFFF):
                raise ValueError(f'eeprom words are uint16 at uint16 addresses, got '
                                 f'{address!r}: {value!r}')
        if (code := self.start_stream) and code not in sns.STREAMABLE:
            raise ValueError(f'streaming_at_start: 0x{code:02X} cannot be streamed; '
                             f'streamable records: {sns.STREAMABLE_TEXT}')
        if not self.wireless:
            self.faults.check_wired()

    @property
    def all_addresses(self) -> tuple[int, ...]:
        """Return the address of every sensor, the first one's first."""
        return self.addresses or (self.address,)

    def firmware_of(self, address: int) -> int:
        """Return the firmware of the sensor at ``address``."""
        return self.firmware_versions.get(address, self.firmware_version)

    @property
    def start_stream(self) -> int:
        """Command byte streamed from power-up, 0 for none."""
        if self.streaming_at_start is True or (self.faults.already_streaming
                                               and not self.streaming_at_start):
            return DEFAULT_STREAM
        return int(self.streaming_at_start)

    @property
    def sensor_motion(self) -> MotionConfig:
        """Return the sensor's motion, with the magnetometer shortcuts applied."""
        motion = self.motion
        if not (self.nan_mag or self.mag_nan_probability):
            return motion
        return dataclasses.replace(
            motion, nan_mag=self.nan_mag or motion.nan_mag,
            mag_nan_probability=self.mag_nan_probability or motion.mag_nan_probability)

    @property
    def sensor_spec(self) -> sns.SensorSpec:
        """Return the sensor this configuration describes."""
        return sns.SensorSpec(self.address, self.serial_number, self.clock_ppm,
                              self.timer_start, self.rate_hz, self.firmware_of(self.address),
                              eeprom=self.power_up_eeprom)

    @property
    def power_up_eeprom(self) -> dict[int, int]:
        """EEPROM words the sensor starts with, presets applied (on top of the factory ones)."""
        words = dict(self.eeprom)
        if self.divider is not None:
            words[RATE_DIVIDER_ADDRESS] = self.divider
        if self.start_stream:
            words[AUTOSTART_ADDRESS] = (0x8000 if self.wireless else 0) | self.start_stream
        return words
