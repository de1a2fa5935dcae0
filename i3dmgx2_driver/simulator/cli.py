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
Command line of the simulator: a 3DM-GX2 on a pseudo-terminal for a driver to open.

The first line printed is ``port: <path>`` (flushed at once), so that a script
or a person can hand the path to the driver (``port:=<path>``); then a status
line every few seconds. SIGINT, SIGTERM and SIGHUP stop it cleanly with exit
status 0 (the port symlink is removed), so that it can run under a launch file
or a test harness; so does the end of the process that started it (SIGTERM,
``lifetime.die_with_parent``: the demo's simulator runs in a session of its
own, which a closed terminal does not reach).
"""

import argparse
from collections.abc import Callable
import contextlib
import dataclasses
import math
import time
from typing import Any

from i3dmgx2_driver.codec import command_firmware as firmware, framing
from i3dmgx2_driver.codec.data_rate import MAX_DIVIDER, MIN_DIVIDER

from .config import SimulatorConfig
from .faults import FaultConfig
from .ground_truth import FAULT_COUNTERS
from .motion import MotionConfig, MOTIONS
from .noise_model import NoiseConfig
from .pty_link import PtySimulator
from .sensor import DEFAULT_FIRMWARE, STREAMABLE, STREAMABLE_TEXT
from .. import lifetime
from ..arguments import in_range


_probability = in_range(float, 0.0, 1.0, 'probability')
_non_negative = in_range(float, 0.0, math.inf, 'number')
_positive = in_range(float, 1e-3, math.inf, 'positive number')
_address = in_range(lambda text: int(text, 0), framing.MIN_ADDRESS, framing.MAX_ADDRESS,
                    'node address')


def _code(text: str, valid: Callable[[int], bool], wrong: str) -> int:
    """Return ``text`` as an integer (0x... too) that is ``valid``, else the error ``wrong``."""
    with contextlib.suppress(ValueError):
        if valid(value := int(text, 0)):
            return value
    raise argparse.ArgumentTypeError(wrong)


def _divider(text: str) -> int:
    return _code(text, lambda value: MIN_DIVIDER <= value <= MAX_DIVIDER,
                 f'the data-rate divider is an integer in {MIN_DIVIDER}..{MAX_DIVIDER} '
                 f'(rate 51200/N Hz: {51200 / MIN_DIVIDER:.1f}..{51200 / MAX_DIVIDER:g} Hz), '
                 f'got {text}')


def _streamable(text: str) -> int:
    return _code(text, STREAMABLE.__contains__,
                 f'{text} is not a record the sensor can stream; streamable: {STREAMABLE_TEXT}')


def _firmware(text: str) -> tuple[int | None, int]:
    """Parse ``2.1.03`` (every sensor) or ``17=2.1.03`` (the sensor at address 17)."""
    address, _, version = text.rpartition('=')
    try:
        return (_address(address) if address else None), firmware.parse(version)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


#: The faults drawn by chance, in the order of ``--help``: flag, the ``FaultConfig``
#: field it sets (its dest, as every option's is the field it sets), and its help.
_CHANCES = (
    ('--garbage', 'garbage_probability', 'chance of random garbage bytes before a packet'),
    ('--corrupt-checksum', 'corrupt_checksum_probability',
     'chance of a packet with a bad checksum'),
    ('--corrupt-length', 'corrupt_length_probability',
     'chance of a packet with a bad length byte'),
    ('--foreign', 'foreign_probability', 'chance of a packet from another sensor address'),
    ('--drop', 'drop_probability', 'chance that a data packet is lost on the radio'),
    ('--command-loss', 'command_loss_probability',
     'chance that an ACKed command never reaches the sensor'),
    ('--nack', 'nack_probability', 'chance that the base station NACKs a good command packet'),
)


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser (separate so that docs and tests can use it)."""
    parser = argparse.ArgumentParser(
        prog='simulator',
        description='Simulated MicroStrain 3DM-GX2 with its wireless base station (or, '
                    'with --wired, a wired 3DM-GX2) on a pseudo-terminal. Prints '
                    '"port: PATH" first; open PATH like a serial port at 115200 baud.')
    # Each option's dest is the SimulatorConfig (or MotionConfig, FaultConfig) field it sets.
    add = parser.add_argument_group('device').add_argument
    add('--address', type=_address, action='append', metavar='N',
        help='node address of the sensor (default: 95); given again, several sensors behind '
             'the one base station, each with its own motion, clock and serial number (e.g. '
             '--address 17 --address 95)')
    add('--wired', action='store_false', dest='wireless',
        help='a wired sensor on the port, no base station: raw commands in, wired records '
             '(echo, data, checksum) out, no ACK/NACK, no ping')
    add('--divider', type=_divider, metavar='N',
        help=f'EEPROM data-rate divider at power-up, {MIN_DIVIDER}..{MAX_DIVIDER} (rate '
             '51200/N Hz; factory: 512, 100 Hz)')
    add('--stream', type=_streamable, metavar='CODE', dest='streaming_at_start', default=False,
        help=f'stream this record from power-up (EEPROM auto-start), e.g. 0xC2; one of '
             f'{STREAMABLE_TEXT}')
    add('--firmware', type=_firmware, action='append', metavar='VERSION',
        help='firmware the sensor reports (0xE9), e.g. 2.1.03: commands newer than it go '
             f'unanswered (default {firmware.text(DEFAULT_FIRMWARE)}, which has them all); '
             'N=VERSION for the sensor at address N alone')
    add('--serial', default='3095', dest='serial_number', metavar='SERIAL',
        help='serial number (default: 3095)')
    add('--rate', type=_positive, metavar='HZ', dest='rate_hz',
        help='calculation rate overriding the EEPROM divider (benchmarks)')
    add('--static', action='store_true', help='sensor at rest')
    add('--honest-noise', action='store_true',
        help='gyro and accelerometer noise term by term (white noise, bias instability, rate '
             'random walk per axis, from the real records: simulator/noise_model.py) instead '
             'of white noise alone')
    add('--nan-mag', action='store_true',
        help='no magnetometer: every field reading is NaN (Inertia-Link)')
    add('--mag-nan-probability', type=_probability, default=0.0, metavar='P',
        help='share of cycles without a new magnetometer reading')
    add('--motion', choices=tuple(MOTIONS), default='sway',
        help='sway (default); tumble: through every attitude; yaw: level, turning in yaw alone '
             '(a magnetometer calibration, docs/magcal.md)')
    add('--hard-iron', type=float, nargs=3, default=(0.0, 0.0, 0.0), metavar=('X', 'Y', 'Z'),
        help="offset added to the field (Gauss, the sensor's axes)")
    add('--soft-iron', type=float, nargs=9, metavar='M', default=MotionConfig.soft_iron,
        help='matrix the field is multiplied by (row-major), before the offset')
    add('--ppm', type=float, default=40.0, dest='clock_ppm', metavar='PPM',
        help='clock error of the sensor timer in ppm (default: 40)')
    add('--timer-start', type=lambda s: int(s, 0), metavar='TICKS',
        help='timer at power-up (default: 5 s before the rollover)')
    add('--latency-ms', type=_non_negative, default=2.0, help='radio latency (default: 2 ms)')
    add('--wire-baud', type=int, default=115200,
        help='serial line baud: each packet arrives its wire time late (default: 115200; 0: '
             'at once)')
    add('--line-rate-limit', action='store_true', dest='limit_to_line_rate',
        help='skip streamed cycles a 115200-baud line could not carry')
    add('--line-queue', action='store_true',
        help="the base station's line carries one packet at a time: packets queue behind each "
             'other, garbage and foreign packets take their time on it too (one sensor)')
    add('--radio-hold-ms', type=_non_negative, default=0.0, metavar='N',
        help='with --line-queue: the first packet after a gap of 0.1 s or more reaches the '
             'line N ms late, the rest queue behind it')
    add('--seed', type=int, help='seed for reproducible noise and faults')

    add = parser.add_argument_group('faults').add_argument
    for flag, field, text in _CHANCES:
        add(flag, type=_probability, default=0.0, metavar='P', dest=field, help=text)
        if flag == '--garbage':
            add('--garbage-any', action='store_false', dest='garbage_safe',
                help='garbage may contain 0xAA/0x21/0x02 (spurious ACK/NACK)')
    add('--already-streaming', action='store_true', help='the sensor streams 0xCC from power-up')
    add('--ignore-first-continuous', action='store_true',
        help='the first request to stream is ignored')
    add('--needs-polled-first', action='store_true',
        help='a request to stream is ignored unless a polled request came first since the '
             'port was opened')
    add('--jitter-ms', type=_non_negative, default=0.0, metavar='N',
        help='random 0..N ms extra delay before each packet is written')
    add('--stall-at', type=_non_negative, metavar='T',
        help='radio silence starting T seconds after start')
    add('--stall-for', type=_non_negative, default=2.0, metavar='S', dest='stall_seconds',
        help='length of that silence (default: 2 s)')
    add('--power-cycle-at', type=_non_negative, metavar='T',
        help='switch the sensor off T seconds after start')
    add('--power-off-for', type=_non_negative, default=1.0, metavar='S',
        dest='power_off_seconds', help='how long it stays off (default: 1 s)')
    add('--fault-address', type=_address, metavar='N',
        help='with several sensors: the one --stall-at and --power-cycle-at hit, the others '
             'streaming on (default: a stall silences the base station, a power cycle hits '
             'the first sensor)')
    add('--unplug-at', type=_non_negative, metavar='T',
        help='unplug the base station T seconds after start')
    add('--unplug-for', type=_non_negative, default=2.0, metavar='S', dest='unplug_seconds',
        help='how long it stays unplugged (default: 2 s)')

    add = parser.add_argument_group('run').add_argument
    add('--duration', type=_positive, metavar='S',
        help='exit after S seconds (default: run until SIGINT/SIGTERM)')
    add('--symlink', metavar='PATH',
        help='fixed path for the port symlink (default: a temporary directory)')
    add('--status-interval', type=_positive, default=5.0, metavar='S',
        help='seconds between status lines (default: 5)')
    add('--quiet', action='store_true', help='print the port line only')
    return parser


def _fields(kind: type, args: argparse.Namespace) -> dict[str, Any]:
    """Return the fields of the dataclass ``kind`` that options set: those of the same dest."""
    given = vars(args)
    return {f.name: given[f.name] for f in dataclasses.fields(kind) if f.name in given}


def config_from_args(args: argparse.Namespace) -> SimulatorConfig:
    """Turn parsed arguments into a simulator configuration."""
    addresses = tuple(args.address or (95,))
    versions = dict(args.firmware or ())
    return SimulatorConfig(**{
        **_fields(SimulatorConfig, args),
        'firmware_version': versions.pop(None, DEFAULT_FIRMWARE), 'firmware_versions': versions,
        'address': addresses[0], 'addresses': addresses if len(addresses) > 1 else (),
        'motion': MotionConfig(static=args.static,
                               noise=NoiseConfig() if args.honest_noise else None,
                               hard_iron=tuple(args.hard_iron), soft_iron=tuple(args.soft_iron),
                               **MOTIONS[args.motion]),
        'faults': FaultConfig(**_fields(FaultConfig, args)),
        'latency_s': args.latency_ms / 1000.0, 'wire_baud': args.wire_baud or None,
        'radio_hold_s': args.radio_hold_ms / 1000.0,
        # A demo may run for hours: keep no ground truth, only the counters.
        'truth_limit': 0})


def status_line(sim: PtySimulator, elapsed: float) -> str:
    """One line on what the simulator has done so far."""
    stats = sim.stats

    def named(code: int) -> str:
        return f'0x{code:02X}' if code else 'no'
    streaming = (','.join(f'{a}:{named(sim.streaming_of(a))}' for a in sim.addresses)
                 if len(sim.addresses) > 1 else named(sim.streaming))
    link = f'acks={stats.acks} nacks={stats.nacks}' if sim.config.wireless else 'wired'
    plugged = 'plugged' if sim.pty.plugged.is_set() else 'unplugged'
    extra = ''.join(f' {k}={v}' for k, v in stats.as_dict().items() if v and k in {
        *FAULT_COUNTERS.values(), 'garbage_bytes', 'commands_lost', 'commands_ignored',
        'late_skipped', 'host_bytes_ignored'})
    return (f'[{elapsed:8.1f} s] records={stats.records_sent} replies={stats.replies_sent} '
            f'commands={stats.commands_received} {link} streaming={streaming} '
            f'rate={sim.sensor.rate_hz:g}Hz port={plugged} opens={stats.port_opens}{extra}')


def _say(text: str) -> None:
    # Nobody listens any more: keep simulating until told to stop.
    with contextlib.suppress(BrokenPipeError, ValueError):
        print(text, flush=True)


def main(argv: list[str] | None = None) -> int:
    """Run the simulator until SIGINT, SIGTERM, SIGHUP, ``--duration`` or its parent's end."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        config = config_from_args(args)
    except ValueError as error:  # a combination argparse cannot see, e.g. --wired --nack
        parser.error(str(error))
    lifetime.die_with_parent()
    # Not a threading.Event: a signal handler may not take a lock (lifetime.py says why).
    stop = lifetime.StopSignal().install()
    try:
        with PtySimulator(config) as sim:
            _say(f'port: {sim.port}')
            start = time.monotonic()
            deadline = start + (args.duration or math.inf)
            next_status = start + args.status_interval
            while (now := time.monotonic()) < deadline and not stop.wait(
                    max(min(next_status, deadline) - now, 0.0)):
                if time.monotonic() >= next_status:
                    next_status += args.status_interval
                    if not args.quiet:
                        _say(status_line(sim, time.monotonic() - start))
            if not args.quiet:
                _say(status_line(sim, time.monotonic() - start))
    finally:
        stop.restore()
    return 0
