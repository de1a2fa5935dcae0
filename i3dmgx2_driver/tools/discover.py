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
Find the sensors: which port, which address, so nobody has to guess.

Lists the serial ports, probes the ones that look like a MicroStrain base
station or a USB-serial cable (every one given with ``--port``, every listed
one with ``--all``), and prints what answered with the exact command that
starts the driver for it: a table, or JSON for scripts, and what to try next
when nothing answered. Exit status: 0 a sensor was found, 1 none, 2 bad
arguments.

What is tried on a port, and how each sensor is left as it was found, is
discover_probe.py's (:func:`~.discover_probe.probe_port`); this module is the
command line and what it prints.
"""

import argparse
from collections.abc import Sequence
import json
import shlex
import sys
import time
from typing import Any, TextIO

from .discover_probe import FACTORY_ADDRESSES, PortProbe, probe_port, ProbeConfig, SensorFound
from .port_listing import (
    BY_ID_DIR, DEFAULT_LATENCY_TIMER_MS, describe_path, latency_timer_ms, list_ports, port_group,
    PortInfo, SYS_CLASS_TTY,
)
from .. import lifetime
from ..arguments import seconds
from ..codec import command_firmware as fw
from ..codec.framing import MAX_ADDRESS, MIN_ADDRESS
from ..device.identity import DeviceInfo
from ..device.port import serial_group, UDEV_RULE_INSTALL

EXIT_FOUND = 0
EXIT_NONE = 1
EXIT_INTERRUPTED = 130

#: What to do about a port in use.
BUSY_HINT = ' (the driver? fuser -v {path} names the process); skipped'
#: Wired sensors need no address, but the node requires one: any valid one does.
WIRED_ADDRESS = 1


def parse_addresses(text: str) -> list[int]:
    """
    Parse ``1-99``, ``95``, ``3,7,10-20`` into sorted unique node addresses.

    Raises ValueError naming what is wrong and the valid range.
    """
    found: set[int] = set()
    for part in text.replace(' ', '').split(','):
        if not part:
            raise ValueError(f'empty item in address list {text!r}')
        low_text, dash, high_text = part.partition('-')
        try:
            low = int(low_text)
            high = int(high_text) if dash else low
        except ValueError:
            raise ValueError(f'{part!r} is not an address or a range like 1-99') from None
        if not MIN_ADDRESS <= low <= high <= MAX_ADDRESS:
            raise ValueError(f'{part!r}: addresses are {MIN_ADDRESS}..{MAX_ADDRESS}, '
                             f'a range low-high')
        found.update(range(low, high + 1))
    return sorted(found)


def node_command(path: str, sensor: SensorFound) -> str:
    """Return the ``ros2 run`` line that starts the driver for ``sensor``."""
    head = f'ros2 run i3dmgx2_driver node --ros-args -p port:={shlex.quote(path)}'
    return f'{head} -p address:={sensor.address}' if sensor.wireless else \
        f'{head} -p wireless:=false -p address:={WIRED_ADDRESS}'


def port_command(path: str, sensors: Sequence[SensorFound]) -> str:
    """
    Return the one ``ros2 run`` line that starts the driver for every sensor on a port.

    The node opens its port exclusively, so several sensors behind one base
    station are served by one node (``addresses``), never one node each.
    """
    wireless = sorted(sensor.address for sensor in sensors if sensor.wireless)
    if len(wireless) < 2:
        return node_command(path, sensors[0])
    listed = ','.join(map(str, wireless))
    return (f'ros2 run i3dmgx2_driver node --ros-args -p port:={shlex.quote(path)} '
            f'-p {shlex.quote(f"addresses:=[{listed}]")}')


def udev_note(path: str, message: str = '', sys_class_tty: str = SYS_CLASS_TTY) -> str:
    """
    Say when the package's udev rule would help this port, or return ''.

    It would when the adapter's latency timer is still the 16 ms it comes up
    with, or when the port belongs to a group this session is not in (and
    the error ``message`` of a refused open does not already say so).
    """
    reasons = []
    timer = latency_timer_ms(path, sys_class_tty)
    if timer is not None and timer >= DEFAULT_LATENCY_TIMER_MS:
        reasons.append(f'its latency timer is {timer} ms (records arrive in {timer} ms bursts)')
    group, member = port_group(path) or ('', True)
    if not member and 'udev rule' not in message:
        why = '' if serial_group(group, path) else \
            f', and joining {group} would give you far more than this port'
        reasons.append(f'it belongs to the {group} group, which you are not in{why}')
    if not reasons:
        return ''
    return (f'{" and ".join(reasons)}; the udev rule that comes with the driver sets a 1 ms '
            f'latency timer and gives the port to the dialout group (mode 0660): '
            f'{UDEV_RULE_INSTALL}')


def _addresses(text: str) -> list[int]:
    try:
        return parse_addresses(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


_seconds = seconds(0.0, 60.0)


def build_parser() -> argparse.ArgumentParser:
    """Return the command line of ``discover``."""
    parser = argparse.ArgumentParser(
        prog='discover',
        description='Find 3DM-GX2 sensors: the serial port of their base station (or cable) '
                    'and their node address, and the command that starts the driver.',
        epilog='Exit status: 0 a sensor was found, 1 none was, 2 bad arguments.')
    parser.add_argument('--port', action='append', metavar='PATH',
                        help='probe this port only (repeatable); default: the listed ports '
                             'that look like a base station or USB-serial cable')
    parser.add_argument('--all', action='store_true',
                        help='probe every listed port, not only the likely ones')
    parser.add_argument('--addresses', type=_addresses, metavar='LIST',
                        default=list(FACTORY_ADDRESSES),
                        help='node addresses to ping, e.g. 95, 1-65534 or 3,7,10-20 '
                             '(default: 1-99, the factory addresses)')
    parser.add_argument('--listen', type=_seconds, default=ProbeConfig.listen_s, metavar='SECONDS',
                        help='listen this long for sensors that already stream '
                             f'(default {ProbeConfig.listen_s})')
    parser.add_argument('--ping-timeout', type=_seconds, default=ProbeConfig.ping_timeout,
                        metavar='SECONDS',
                        help='wait this long for a base station to answer a ping before '
                             'taking the port for one without a base station '
                             f'(default {ProbeConfig.ping_timeout})')
    parser.add_argument('--stop-streams', action='store_true',
                        help='stop a streaming sensor to read it (it is restarted), '
                             'rather than asking it while it streams')
    parser.add_argument('--baud', type=int, default=ProbeConfig.baud,
                        help=f'serial baud rate (default {ProbeConfig.baud})')
    parser.add_argument('--json', action='store_true',
                        help='print the result as JSON (for scripts)')
    parser.add_argument('--by-id-dir', default=BY_ID_DIR, help=argparse.SUPPRESS)
    return parser


# -- output --------------------------------------------------------------------

def _firmware_note(sensor: SensorFound) -> str:
    """Say what the sensor's firmware lacks of what the driver offers ('' if nothing, unknown)."""
    version = fw.version_of(sensor.info.firmware) if sensor.info else None
    return fw.summary(version) if fw.lacks(version) else ''


def _sensor_dict(sensor: SensorFound, command: str | None) -> dict[str, Any]:
    info = sensor.info
    return {'address': sensor.address, 'link': 'wireless' if sensor.wireless else 'wired',
            'found_by': sensor.found_by,
            **(info._asdict() if info else dict.fromkeys(DeviceInfo._fields)),
            'firmware_lacks': fw.lacks(fw.version_of(info.firmware)) if info else None,
            'firmware_note': _firmware_note(sensor) or None, 'rate_divider': sensor.divider,
            'rate_hz': round(sensor.rate_hz, 3) if sensor.rate_hz else None,
            'streaming': f'0x{sensor.streaming:02X}' if sensor.streaming else None,
            'stream_restarted': sensor.restarted, 'lqi': sensor.lqi, 'rssi': sensor.rssi,
            'note': sensor.note or None, 'command': command}


def _port_dict(port: PortInfo, probe: PortProbe | None) -> dict[str, Any]:
    out: dict[str, Any] = {
        'device': port.device, 'by_id': port.by_id, 'usb_id': port.usb_id,
        'description': port.description or None, 'looks_like': port.kind,
        'status': probe.status if probe else 'not probed',
        'latency_timer_ms': latency_timer_ms(port.device),
        'udev_note': udev_note(port.device, probe.message if probe else '') or None,
    }
    if probe is not None:
        command = port_command(port.stable_path, probe.sensors) if probe.sensors else None
        out.update(message=probe.message or None, base_station=probe.base_station,
                   pinged=probe.pinged, ping_seconds=round(probe.ping_seconds, 3),
                   seconds=round(probe.seconds, 3),
                   sensors=[_sensor_dict(s, command) for s in probe.sensors], command=command)
    return out


def _table(rows: list[list[str]], out: TextIO, indent: str = '  ') -> None:
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    for row in rows:
        out.write(indent + '  '.join(cell.ljust(w) for cell, w in zip(row, widths, strict=True))
                  .rstrip() + '\n')


def print_ports(ports: Sequence[PortInfo], probing: set[str], out: TextIO) -> None:
    """Print the port list, saying which ports will be probed."""
    if not ports:
        out.write("No serial ports found. Is the base station (or the sensor's USB cable) "
                  'plugged in? dmesg tells what the kernel saw.\n')
        return
    rows = [['device', 'stable path', 'usb id', 'description', 'looks like', '']]
    rows += [[port.device, port.by_id or '-', port.usb_id or '-', port.description or '-',
              port.kind or '-', 'probe' if port.device in probing else 'skip'] for port in ports]
    out.write('Serial ports:\n')
    _table(rows, out)


def _state(sensor: SensorFound) -> str:
    if not sensor.streaming:
        return 'polled'
    return f'streaming 0x{sensor.streaming:02X}' + (' (restarted)' if sensor.restarted else '')


def print_results(results: Sequence[tuple[PortInfo, PortProbe]], out: TextIO) -> None:
    """Print what each port held, a table of sensors, and the commands."""
    rows = [['port', 'link', 'address', 'serial', 'model', 'firmware', 'rate', 'state',
             'found by']]
    commands = []
    for port, probe in results:
        note = udev_note(port.device, probe.message)
        if probe.status != 'probed':
            hint = BUSY_HINT.format(path=shlex.quote(port.device)) \
                if probe.status == 'busy' else ''
            out.write(f'{port.device}: {probe.message}{hint}\n')
            if note:
                out.write(f'  note: {note}\n')
            continue
        if note:
            out.write(f'{port.device}: note: {note}\n')
        if not probe.sensors:
            what = {True: 'a base station, but no sensor answered',
                    False: 'no base station and no wired sensor answered',
                    None: 'nothing answered'}[probe.base_station]
            pinged = f' (pinged {probe.pinged} addresses)' if probe.base_station else ''
            out.write(f'{port.device}: {what}{pinged}, {probe.seconds:.1f} s\n')
            continue
        count = len(probe.sensors)
        out.write(f'{port.device}: {count} sensor{"s" if count > 1 else ""}, '
                  f'{probe.seconds:.1f} s\n')
        commands.append((probe.sensors, port_command(port.stable_path, probe.sensors)))
        for sensor in probe.sensors:
            info = sensor.info or DeviceInfo('', '', '', '', '')
            rows.append([
                port.device, 'wireless' if sensor.wireless else 'wired',
                str(sensor.address) if sensor.wireless else '-', info.serial_number or '?',
                info.model_name or info.model_number or '?', info.firmware or '?',
                f'{sensor.rate_hz:.1f} Hz' if sensor.rate_hz else '?',
                _state(sensor), sensor.found_by])
    if not commands:
        return
    out.write('\n')
    _table(rows, out)
    out.write('\nStart the driver with:\n')
    for sensors, command in commands:
        out.write(f'  {command}\n')
        for sensor in sensors:
            if sensor.note:
                out.write(f'    note: {sensor.note}\n')
            if firmware := _firmware_note(sensor):
                who = f'node {sensor.address}' if sensor.wireless else 'the wired sensor'
                out.write(f'    {who}: {firmware}\n')


def print_hints(results: Sequence[tuple[PortInfo, PortProbe]], config: ProbeConfig,
                out: TextIO) -> None:
    """Say what to try next when nothing was found."""
    addresses = list(config.addresses)
    out.write('\nNo sensor found. Check that the sensor is on (battery), then:\n')
    swept = [p for _, p in results if p.base_station and p.pinged]
    if swept and len(addresses) < 65534:
        per_ping = sum(p.ping_seconds for p in swept) / sum(p.pinged for p in swept)
        out.write(f'  - its address may not be the factory one: --addresses 1-65534 '
                  f'(about {per_ping * 65534 / 60:.1f} min at the pace seen here)\n')
    if any(p.base_station is False for _, p in results):
        out.write(f'  - a base station slower than {config.ping_timeout:g} s to answer a ping: '
                  f'--ping-timeout 2\n')
    out.write('  - sensor and base station may be on different radio channels '
              "(MicroStrain's software sets them)\n"
              '  - a wired sensor or another port: --all probes every listed port\n')


class _ProgressLine:
    """One self-overwriting status line on a terminal; silent elsewhere."""

    def __init__(self, out: TextIO, enabled: bool) -> None:
        self.out, self.enabled, self.port, self._last = out, enabled, '', 0.0

    def __call__(self, stage: str, done: int, total: int) -> None:
        now = time.monotonic()
        if not self.enabled or (done not in (0, total) and now - self._last < 0.05):
            return
        self._last = now
        text = {'listen': 'listening for streams', 'ping': f'pinging {done}/{total}',
                'identify': f'reading sensor {min(done + 1, total)}/{total}'}[stage]
        print(f'\r\x1b[K{self.port}: {text}', end='', file=self.out, flush=True)

    def clear(self) -> None:
        if self.enabled:
            print('\r\x1b[K', end='', file=self.out, flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``discover``; return the exit status."""
    args = build_parser().parse_args(argv)
    # A closed terminal, SIGTERM or its parent's end take Ctrl-C's way out: the port is
    # closed, the sensors left as found.
    lifetime.interrupt_on_stop_signals()
    out = sys.stdout
    ports = [describe_path(path, args.by_id_dir) for path in args.port] if args.port \
        else list_ports(args.by_id_dir)
    probing = {p.device for p in ports if args.port or args.all or p.likely}
    if not args.json and not args.port:
        print_ports(ports, probing, out)
    config = ProbeConfig(addresses=args.addresses, baud=args.baud, listen_s=args.listen,
                         ping_timeout=args.ping_timeout, stop_streams=args.stop_streams)
    progress = _ProgressLine(sys.stderr, sys.stderr.isatty() and not args.json)
    results = []
    try:
        for port in (p for p in ports if p.device in probing):
            progress.port = port.device
            results.append((port, probe_port(port.device, config, progress)))
            progress.clear()
    except KeyboardInterrupt:
        progress.clear()  # the port is closed on the way out; nothing was changed
        return EXIT_INTERRUPTED
    found = sum(len(probe.sensors) for _, probe in results)
    if args.json:
        probes = {port.device: probe for port, probe in results}
        json.dump({'found': found,
                   'ports': [_port_dict(p, probes.get(p.device)) for p in ports]}, out, indent=2)
        out.write('\n')
    elif results:
        if not args.port:
            out.write('\n')
        print_results(results, out)
        if not found:
            print_hints(results, config, out)
    elif ports:
        out.write('\nNo port looks like a base station or USB-serial cable: --all probes '
                  'them all, --port PATH one.\n')
    return EXIT_FOUND if found else EXIT_NONE


if __name__ == '__main__':
    sys.exit(main())
