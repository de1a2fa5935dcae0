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
Bring-up: one command a first-time hardware user runs, and sends us.

``ros2 run i3dmgx2_driver bringup --port PATH --address N`` talks to a real
sensor for about a minute and writes, in one folder it names:

- ``report.txt``, the table it also prints: the sensor's identity (with
  what its firmware lacks of what the driver offers), its data rate
  divider, the port's low-latency mode and FTDI latency timer as found;
  the round trips of a ping, a short command (0xE9) and continuous mode's
  start and stop (min / median / max, and how many were lost or NACKed);
  every stream its firmware has (the others are skipped, with the firmware
  they need) at the highest rate the line allows, for a few seconds each
  (rate achieved, records lost by the sensor's timer, LQI and RSSI, the
  device clock's drift); the timeouts a measured round trip comes within a
  factor 2 of (``device/timeouts.py``); and the state the sensor was left in;
- ``report.json``, the same for a program;
- ``session.gx2cap``, every byte read, with its receive time, in the
  capture format (``capture/file_format.py``): ``replay`` plays it to the driver.

The sensor is left exactly as found: the stream it was streaming (or none),
its rate divider in EEPROM (written for the streams, written back at the
end and read back). Exit status: 0 done and left as found, 1 the sensor did
not answer or could not be restored, 2 bad arguments, 130 interrupted (the
sensor restored first).
"""

import argparse
from collections.abc import Callable, Sequence
import itertools
import json
import os
from pathlib import Path
import sys
import threading
import time
from typing import Any, TextIO

from .bringup_round_trips import (
    close_calls, COMMAND, CONTINUOUS_START, MEASURE_TIMEOUT, note_longest, PING, radio_timeouts,
    RECORD_GAP, SHORT_COMMAND, spread,
)
from .port_listing import latency_timer_ms, port_group
from .. import lifetime
from ..arguments import seconds, whole_number
from ..capture.file_format import CaptureWriter, default_header
from ..codec import command_firmware as fw
from ..codec import commands, layouts, line_budget, streams
from ..codec.data_rate import divider_for_rate, period_of_divider, rate_of_divider, ticks_per_cycle
from ..codec.framing import DataPacket, MAX_ADDRESS, MIN_ADDRESS
from ..codec.layouts import STREAMABLE
from ..codec.records import TICKS_PER_SECOND
from ..codec.timer import TIMER_MODULUS
from ..device import timeouts
from ..device.clock import DeviceClock
from ..device.identity import read_identity
from ..device.link import DeviceError, DeviceLink, DeviceNack, LinkOptions
from ..device.port import PortError, SerialPort
from ..device.sample_clock import records_lost
from ..device.sensor_steps import SensorSteps

#: One record of a stream measured: (monotonic read time, code, timer, LQI, RSSI).
Entry = tuple[float, int, int, int | None, int | None]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_INTERRUPTED = 130

_count = whole_number(1, 1000, 'count')
_address = whole_number(MIN_ADDRESS, MAX_ADDRESS, 'node address')
_seconds = seconds(0.2, 600.0)


def _streams(text: str) -> list[streams.Stream]:
    if text == 'all':
        return list(streams.STREAMS)
    try:
        return [streams.parse(item.strip()) for item in text.split(',') if item.strip()]
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def build_parser() -> argparse.ArgumentParser:
    """Return the command line of ``bringup``."""
    parser = argparse.ArgumentParser(
        prog='bringup',
        description='Talk to a real 3DM-GX2 for about a minute and write a report a person '
                    'can read and a capture a developer can replay, in one folder: attach '
                    'that folder to a bug report.',
        epilog='Exit status: 0 done and the sensor left as found, 1 it did not answer or '
               'could not be restored, 2 bad arguments.')
    parser.add_argument('--port', required=True, metavar='PATH',
                        help='serial port of the base station (discover finds it)')
    parser.add_argument('--address', required=True, type=_address, metavar='N',
                        help="the sensor's node address (discover finds it)")
    parser.add_argument('--baud', type=int, default=115200, help='baud rate (default 115200)')
    parser.add_argument('--output-dir', default='.', metavar='DIR',
                        help='where the report folder is made (default: here)')
    for flag, default, what in (('pings', 20, 'pings'), ('commands', 20, 'short commands (0xE9)'),
                                ('cycles', 5, 'continuous-mode starts and stops')):
        parser.add_argument(f'--{flag}', type=_count, default=default, metavar='N',
                            help=f'{what} to time (default {default})')
    parser.add_argument('--stream-seconds', type=_seconds, default=5.0, metavar='S',
                        help='how long each stream runs (default 5)')
    parser.add_argument('--listen', type=_seconds, default=1.0, metavar='S',
                        help='how long to listen first for a stream already running (default 1)')
    parser.add_argument('--streams', type=_streams, default='all', metavar='LIST',
                        help='streams to run, e.g. full,inertial or 0xCC,0xC2 (default: all)')
    return parser


class RecordLog:
    """The records a stream's figures are made of, as the link's reader thread hands them."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._entries: list[Entry] | None = None

    def __call__(self, packet: DataPacket, now: float, mono: float) -> None:
        with self._lock:
            if self._entries is not None:
                timer = packet.values[-1] if packet.code in STREAMABLE else 0
                self._entries.append((mono, packet.code, timer, packet.lqi, packet.rssi))

    def start(self) -> None:
        """Keep every record from now on."""
        with self._lock:
            self._entries = []

    def stop(self) -> list[Entry]:
        """Return the records kept since :meth:`start`; keep none from now on."""
        with self._lock:
            entries, self._entries = self._entries or [], None
        return entries


class Bringup:
    """
    One bring-up session over an open link; each step fills part of :attr:`report`.

    What is said to the sensor, and when a stream counts as started or
    stopped, are the steps every tool and the node take (:attr:`steps`,
    device/sensor_steps.py); here: the sensor as found, the round trips
    (each ``time_*`` returns its entries of the report's ``round_trips`` and
    notes its longest in :attr:`longest`, held against the timeouts by
    bringup_round_trips.py), every stream measured, and the sensor as found
    again.
    """

    def __init__(self, link: DeviceLink, log: RecordLog, args: argparse.Namespace,
                 say: Callable[[str], None]) -> None:
        self.link, self.log, self.args, self.say = link, log, args, say
        self.report: dict[str, Any] = {}
        self.found_stream = 0
        self.found_divider: int | None = None
        #: The sensor's firmware (0xE9; None: not answered, nothing skipped for it).
        self.firmware: int | None = None
        #: The rate divider as last written or found (None: unknown).
        self.divider: int | None = None
        #: Longest round trip of each kind (s), for the timeouts' check.
        self.longest: dict[str, float] = {}
        self.steps = SensorSteps()

    # -- the sensor as found --------------------------------------------------------

    def find_state(self) -> bool:
        """
        Listen for a stream, quiet it, read identity and divider.

        Returns False, with the reason in the report, when the sensor is not
        there: no stream heard and no answer to a ping through the base station.
        """
        link = self.link
        self.say(f'listening {self.args.listen:g} s for a stream already running')
        deadline = time.monotonic() + self.args.listen
        while time.monotonic() < deadline and not link.records:
            time.sleep(0.02)
        time.sleep(min(0.2, max(0.0, deadline - time.monotonic())))
        self.found_stream = (link.last_code or 0) if link.records else 0
        if self.found_stream:
            self.say(f'the sensor streams 0x{self.found_stream:02X}: stopping it (restarted '
                     f'at the end)')
        self.steps.stop_until_quiet(link, period_of_divider(None))
        if not self.found_stream:
            for _ in range(3):
                if answer := link.ping_once(link.address, MEASURE_TIMEOUT):
                    break
            if not answer:
                self.report['error'] = (
                    f'node {link.address} does not answer on {link.port.path}: ' + (
                        'the base station answered the pings, the sensor did not (is it on? '
                        'its address?)' if answer is False else
                        'nothing answered the pings (no base station on this port?)')
                    + '; ros2 run i3dmgx2_driver discover finds the port and address')
                return False
        self.say('reading identity and data rate')
        info = read_identity(link, self.steps.timeout, self.steps.retries)
        self.firmware = fw.version_of(info.firmware)
        self.report['identity'] = {**info._asdict(), 'answered': any(info),
                                   'firmware_lacks': fw.lacks(self.firmware)}
        self.say(fw.summary(self.firmware))
        divider = self.divider = self.found_divider = self._read_divider()
        self.report['as_found'] = {
            'streaming': f'0x{self.found_stream:02X}' if self.found_stream else None,
            'rate_divider': divider,
            'rate_hz': round(rate_of_divider(divider), 3) if divider else None}
        return True

    def _read_divider(self) -> int | None:
        """Read the rate divider from EEPROM; None if the sensor does not say."""
        try:
            return self.steps.read_divider(self.link)
        except DeviceError:
            return None

    def _write_divider(self, divider: int) -> bool:
        """Write the rate divider to EEPROM (once, read back); True if it holds."""
        try:
            self.divider = self.steps.write_divider(self.link, self.divider, divider)
        except DeviceError:
            self.divider = None  # written or not: unknown
            return False
        return True

    # -- the round trips ----------------------------------------------------------------

    def _request(self, command: bytes, code: int) -> str | None:
        """Send ``command`` once; return the failure's name ('nacked', 'lost') or None."""
        try:
            self.link.request(command, code, MEASURE_TIMEOUT, 1)
        except DeviceNack:
            return 'nacked'
        except DeviceError:
            return 'lost'
        return None

    def _timed(self, kind: str, count: int, failures: tuple[str, ...],
               attempt: Callable[[], str | None]) -> dict[str, Any]:
        """Time ``count`` tries of ``attempt`` (it returns the failure's name, or None)."""
        times, failed = [], dict.fromkeys(failures, 0)
        for _ in range(count):
            start = time.monotonic()
            failure = attempt()
            if failure is None:
                times.append(time.monotonic() - start)
            else:
                failed[failure] += 1
        note_longest(self.longest, kind, times)
        return {kind: {**spread(times, 1e3), **failed}}

    def time_pings(self) -> dict[str, Any]:
        """Time pings through the base station (no answer: lost; 0x21: not the sensor's)."""
        self.say(f'timing {self.args.pings} pings')

        def once() -> str | None:
            answer = self.link.ping_once(self.link.address, MEASURE_TIMEOUT)
            # Falsy: the base station answered, the sensor did not (0x21).
            return 'lost' if answer is None else None if answer else 'not_answered_by_sensor'
        return self._timed(PING, self.args.pings, ('lost', 'not_answered_by_sensor'), once)

    def time_commands(self) -> dict[str, Any]:
        """Time the short command's request and reply."""
        self.say(f'timing {self.args.commands} short commands (0x{SHORT_COMMAND:02X})')
        return self._timed(COMMAND, self.args.commands, ('lost', 'nacked'),
                           lambda: self._request(bytes((SHORT_COMMAND,)), SHORT_COMMAND))

    def time_continuous(self, code: int, period: float) -> dict[str, Any]:
        """
        Time continuous mode ``code``: reply and first record, then the stop's last record.

        ``period`` is the time between records at the sensor's rate.
        """
        self.say(f'timing {self.args.cycles} continuous-mode starts and stops (0x{code:02X})')
        link, steps = self.link, self.steps
        starts, stops, replies = [], [], []
        failed = dict.fromkeys(('lost', 'nacked', 'no_records'), 0)
        for _ in range(self.args.cycles):
            before = link.records
            start = time.monotonic()
            if (failure := self._request(commands.set_continuous(code),
                                         layouts.SET_CONTINUOUS)) is None:
                replies.append(time.monotonic() - start)
            else:
                failed[failure] += 1
            deadline = start + MEASURE_TIMEOUT + timeouts.RECORD_PERIODS * period
            while link.records <= before and time.monotonic() < deadline:
                time.sleep(0.002)
            if link.records <= before:
                failed['no_records'] += 1
                continue
            starts.append(link.last_data_mono - start)
            time.sleep(0.2)
            # Once, no retry: the stop's round trip is measured.
            stop_sent = time.monotonic()
            link.send(commands.stop_continuous())
            last = steps.wait_quiet(link, stop_sent, period, MEASURE_TIMEOUT)
            if last is None:
                failed['lost'] += 1  # the stop was lost: stop it the sure way
                steps.stop_until_quiet(link, period)
                continue
            stops.append(max(0.0, last - stop_sent))
        note_longest(self.longest, CONTINUOUS_START, starts)
        return {'continuous_start': {**spread(starts, 1e3), 'reply': spread(replies, 1e3),
                                     **failed},
                'continuous_stop': spread(stops, 1e3)}

    # -- every stream --------------------------------------------------------------------

    def run_stream(self, stream: streams.Stream) -> dict[str, Any]:
        out: dict[str, Any] = {'stream': stream.label, 'code': f'0x{stream.code:02X}'}
        if lacking := fw.stream_refusal(stream, self.firmware):
            self.say(f'skipping {stream.label}: {lacking}')
            return {**out, 'skipped': lacking}
        if (rate := line_budget.max_rate(stream.code, self.args.baud, True)) is None:
            return {**out, 'error': 'no rate fits the line'}
        divider = divider_for_rate(rate)
        out.update(divider=divider, rate_asked_hz=round(rate_of_divider(divider), 2))
        self.say(f'streaming {stream.label} at {rate_of_divider(divider):.1f} Hz for '
                 f'{self.args.stream_seconds:g} s')
        if divider != self.divider and not self._write_divider(divider):
            return {**out, 'error': f'could not set the rate divider to {divider}'}
        period = period_of_divider(divider)
        self.log.start()
        try:
            self.steps.start_stream(self.link, stream.code, period)
            time.sleep(self.args.stream_seconds)
        except DeviceError:
            out['error'] = (f'no records after {timeouts.CONTINUOUS_TRIES} continuous-mode '
                            f'requests')
        log = self.log.stop()
        self.steps.stop_until_quiet(self.link, period)
        out.update(stream_figures([e for e in log if e[1] == stream.code], divider,
                                  line_budget.wire_time(stream.code, self.args.baud, True)))
        note_longest(self.longest, RECORD_GAP, [out['longest_gap_ms'] / 1e3]
                     if out.get('longest_gap_ms') is not None else [])
        return out

    # -- as found again -------------------------------------------------------------------

    def restore(self) -> dict[str, Any]:
        """Put divider and stream back as found; say how it went."""
        link, steps, found = self.link, self.steps, self.found_divider
        steps.stop_until_quiet(link, period_of_divider(self.divider))
        readback, divider_restored = None, self.divider is None
        if found is not None:
            ok = self.divider == found or self._write_divider(found)
            readback = self._read_divider()
            divider_restored = bool(ok and readback == found)
        restarted = True
        if self.found_stream:
            try:
                restarted = steps.start_stream(link, self.found_stream,
                                               period_of_divider(self.divider))
            except DeviceError:
                restarted = False
        return {'rate_divider': readback, 'rate_divider_restored': divider_restored,
                'streaming': f'0x{self.found_stream:02X}'
                if self.found_stream and restarted else None,
                'stream_restored': restarted, 'as_found': divider_restored and restarted,
                'eeprom_writes': steps.eeprom_writes}


def stream_figures(log: Sequence[Entry], divider: int, wire_time: float) -> dict[str, Any]:
    """Rate, records lost by the timer, LQI/RSSI and clock drift of one stream's records."""
    if len(log) < 2:
        return {'records': len(log), 'rate_hz': None, 'lost': None, 'lqi': spread([]),
                'rssi': spread([]), 'drift_ppm': None, 'longest_gap_ms': None}
    expected, lost, ticks = ticks_per_cycle(divider), 0, [0]
    for previous, entry in itertools.pairwise(log):
        step = (entry[2] - previous[2]) % TIMER_MODULUS
        ticks.append(ticks[-1] + step)
        lost += records_lost(step, expected)
    span = ticks[-1] / TICKS_PER_SECOND
    host_span = log[-1][0] - log[0][0]
    # The driver's own fit of the device clock, with ten envelope windows in the run.
    clock = DeviceClock(window=max(span / 10, 0.05), history=20)
    for tick, entry in zip(ticks, log, strict=True):
        clock.stamp(tick, entry[0], wire_time)
    return {
        'records': len(log),
        'rate_hz': round((len(log) - 1) / host_span, 2) if host_span > 0 else None,
        'device_rate_hz': round((len(log) - 1 + lost) / span, 2) if span > 0 else None,
        'lost': lost, 'lost_share': round(lost / (len(log) + lost), 4),
        'lqi': spread([e[3] for e in log if e[3] is not None], digits=0),
        'rssi': spread([e[4] for e in log if e[4] is not None], digits=0),
        'drift_ppm': round(clock.drift_ppm, 1) if host_span >= 1.0 else None,
        'longest_gap_ms': round(max(b[0] - a[0] for a, b in itertools.pairwise(log)) * 1e3, 1),
    }


# -- the report ------------------------------------------------------------------------


def _cell(value: Any) -> str:
    return '-' if value is None else str(value)


def _timer(value: int | None) -> str:
    return ('none (not an FTDI USB-serial port)' if value is None
            else f'{value} ms' + (' (the udev rule sets 1 ms)' if value > 1 else ''))


def _table(rows: list[list[str]]) -> list[str]:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return ['  ' + '  '.join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip()
            for row in rows]


def format_report(report: dict[str, Any]) -> str:
    """Return the report as the table a person reads (printed and in report.txt)."""
    lines = [f'3DM-GX2 bring-up, {report["started"]}', '']
    port = report['port']
    ident = report.get('identity', {})
    found = report.get('as_found', {})
    lines += _table([
        ['port', port['path']],
        ['address', str(report['address'])],
        ['model', f'{_cell(ident.get("model_name"))} ({_cell(ident.get("model_number"))})'],
        ['serial', _cell(ident.get('serial_number'))],
        ['firmware', _cell(ident.get('firmware'))
         + (': no ' + ', '.join(ident['firmware_lacks']) if ident.get('firmware_lacks') else '')],
        ['options', _cell(ident.get('options'))],
        ['rate divider', f'{_cell(found.get("rate_divider"))} ({_cell(found.get("rate_hz"))} Hz)'],
        ['streaming as found', _cell(found.get('streaming')) if found else '-'],
        ['low-latency mode as found', _cell(port.get('low_latency_as_found'))],
        ['low-latency mode now', _cell(port.get('low_latency'))],
        ['FTDI latency timer as found', _timer(port.get('latency_timer_ms_as_found'))],
        ['FTDI latency timer now', _timer(port.get('latency_timer_ms'))],
        ['group', f'{_cell(port.get("group"))}'
                  f'{"" if port.get("in_group", True) else " (you are not in it)"}'],
    ])
    if trips := report.get('round_trips', {}):
        lines += ['', 'Round trips (ms):']
        rows = [['', 'count', 'min', 'median', 'max', 'lost', 'nacked']]
        for name, key in (('ping', 'ping'), ('short command (0xE9)', 'command'),
                          ('continuous start (to 1st record)', 'continuous_start'),
                          ('continuous stop (to last record)', 'continuous_stop')):
            if (t := trips.get(key)) is not None:
                rows.append([name, str(t['count']), _cell(t['min']), _cell(t['median']),
                             _cell(t['max']), _cell(t.get('lost')), _cell(t.get('nacked'))])
        lines += _table(rows)
        if silent := trips.get('ping', {}).get('not_answered_by_sensor'):
            lines.append(f'  pings the base station answered 0x21 (sensor silent): {silent}')
    if report.get('streams'):
        lines += ['', 'Streams, each at the highest rate the line allows:']
        rows = [['stream', 'asked Hz', 'got Hz', 'records', 'lost', 'LQI min/med',
                 'RSSI min/med', 'drift ppm', 'longest gap ms']]
        for s in report['streams']:
            if 'skipped' in s:  # the whole reason was said, and is in report.json
                least = fw.text(fw.needs(int(s['code'], 16)))
                rows.append([s['stream'], '-', f'skipped: needs firmware {least}'] + [''] * 6)
            elif 'error' in s and not s.get('records'):
                rows.append([s['stream'], _cell(s.get('rate_asked_hz')), s['error']] + [''] * 6)
            else:
                rows.append([s['stream'], _cell(s.get('rate_asked_hz')), _cell(s.get('rate_hz')),
                             str(s['records']), _cell(s.get('lost')),
                             f'{_cell(s["lqi"]["min"])}/{_cell(s["lqi"]["median"])}',
                             f'{_cell(s["rssi"]["min"])}/{_cell(s["rssi"]["median"])}',
                             _cell(s.get('drift_ppm')), _cell(s.get('longest_gap_ms'))])
        lines += _table(rows)
    if report.get('close_calls'):
        lines += ['', 'Timeouts a round trip comes close to:']
        lines += [f'  - {text}' for text in report['close_calls']]
    if (left := report.get('left')) is not None:
        lines += ['', 'Left as found: ' + ('yes' if left['as_found'] else 'NO') + ': '
                  f'rate divider {_cell(left["rate_divider"])} in EEPROM (read back after '
                  f'{left["eeprom_writes"]} writes of the rate divider, the only EEPROM '
                  'word written), '
                  + (f'streaming {left["streaming"]}' if left['streaming']
                     else 'not streaming') + '.']
    if report.get('error'):
        lines += ['', f'Error: {report["error"]}']
    lines += ['', f'Folder: {report["folder"]} (report.txt, report.json, session.gx2cap): '
                  'please attach it to your bug report.']
    return '\n'.join(lines) + '\n'


def _folder(base: str) -> str:
    stamp = os.path.join(base, 'bringup-' + time.strftime('%Y%m%d-%H%M%S'))
    path, suffix = stamp, 1
    while os.path.exists(path):
        suffix += 1
        path = f'{stamp}-{suffix}'
    os.makedirs(path)
    return path


def run(args: argparse.Namespace, out: TextIO) -> int:
    """Run a bring-up session as ``args`` say; write the folder; return the exit status."""
    folder = _folder(args.output_dir)

    def say(text: str) -> None:
        print(f'bringup: {text}', file=out, flush=True)

    say(f'writing to {folder}')
    group, in_group = port_group(args.port) or (None, None)
    report: dict[str, Any] = {
        'started': time.strftime('%Y-%m-%d %H:%M:%S %z'), 'folder': folder,
        'address': args.address, 'baud': args.baud,
        'port': {'path': args.port, 'real_path': os.path.realpath(args.port),
                 'latency_timer_ms_as_found': latency_timer_ms(args.port),
                 'group': group, 'in_group': in_group},
        'settings': {'pings': args.pings, 'commands': args.commands, 'cycles': args.cycles,
                     'stream_seconds': args.stream_seconds},
        'timeouts': [t._asdict() for t in radio_timeouts()],
        'round_trips': {}, 'streams': [],
    }
    status = EXIT_FAILED
    try:
        port = SerialPort(args.port, args.baud, low_latency=False)
    except PortError as exc:
        report['error'] = str(exc)
        _write(folder, report, out)
        return EXIT_FAILED
    report['port']['low_latency_as_found'] = {
        True: 'on', False: 'off', None: 'unknown (not a USB-serial port)'}[port.low_latency_flag()]
    report['port']['low_latency'] = port.enable_low_latency()
    report['port']['latency_timer_ms'] = latency_timer_ms(args.port)
    capture = CaptureWriter(os.path.join(folder, 'session.gx2cap'), default_header(
        port=args.port, address=args.address, baud=args.baud, wireless=True,
        notes='bringup session'))
    log = RecordLog()
    link = DeviceLink(port, args.address, log, LinkOptions.listening(True, capture.write))
    session = Bringup(link, log, args, say)
    session.report = report
    try:
        link.start()
        if not session.find_state():
            pass  # the report says why
        elif not report['identity']['answered'] and session.found_divider is None:
            report['error'] = (f'node {args.address} on {args.port} answered nothing: '
                               f'discover finds the port and address')
        else:
            report['round_trips'].update(session.time_pings())
            report['round_trips'].update(session.time_commands())
            report['round_trips'].update(session.time_continuous(
                session.found_stream or streams.DEFAULT.code, period_of_divider(session.divider)))
            for stream in args.streams:
                report['streams'].append(session.run_stream(stream))
        say('putting the sensor back as found')
        report['left'] = session.restore()
        report['close_calls'] = close_calls(session.longest)
        if report['left']['as_found'] and 'error' not in report:
            status = EXIT_OK
    except KeyboardInterrupt:
        report['error'] = 'interrupted'
        status = EXIT_INTERRUPTED
        if 'left' not in report:
            report['left'] = session.restore()
    except (PortError, DeviceError) as exc:
        report['error'] = str(exc)
    finally:
        link.stop()
        port.close()
        capture.close()
    report['capture'] = {'path': os.path.join(folder, 'session.gx2cap'),
                         'chunks': capture.chunks, 'bytes': capture.bytes}
    _write(folder, report, out)
    return status


def _write(folder: str, report: dict[str, Any], out: TextIO) -> None:
    text = format_report(report)
    Path(folder, 'report.txt').write_text(text)
    Path(folder, 'report.json').write_text(json.dumps(report, indent=2) + '\n')
    print('\n' + text, end='', file=out, flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``bringup``; return the exit status."""
    args = build_parser().parse_args(argv)
    # A closed terminal, SIGTERM or its parent's end take Ctrl-C's way out: the sensor is
    # left as found.
    lifetime.interrupt_on_stop_signals()
    try:
        return run(args, sys.stdout)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED


if __name__ == '__main__':
    sys.exit(main())
