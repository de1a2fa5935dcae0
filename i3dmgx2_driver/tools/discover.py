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
starts the driver for it. Exit status: 0 a sensor was found, 1 none, 2 bad
arguments.

Probing one port (:func:`probe_port`) opens it exclusively and then, in this
order:

1. listens: a sensor that already streams gives itself away, a wireless
   one by the node address every data packet carries, a wired one by records
   whose checksums hold;
2. sweeps with base-station pings. A base station answers every ping with one
   byte (0x02: the node answers over the radio; 0x21: it does not), so
   silence to the first few pings means there is no base station;
3. without a base station, asks as a wired sensor is asked (raw 0xE9);
4. for each sensor found, asks for its firmware (0xE9), identity (0xEA) and
   data-rate divider (EEPROM 0xFCA2, read, never written).

Every sensor is left as it was found. A streaming sensor is asked in
combined mode (polled requests interleave with its stream), so its stream
goes on untouched; only if it does not answer that way (the radio loses
more while streaming), or when asked to, is its stream stopped, the sensor
read, and the same record restarted and seen to flow again.
"""

import argparse
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
import json
import shlex
import sys
import threading
import time
from typing import Any, NamedTuple, TextIO

from .port_listing import (
    BY_ID_DIR, DEFAULT_LATENCY_TIMER_MS, describe_path, latency_timer_ms, list_ports, PortInfo,
    SYS_CLASS_TTY,
)
from .. import lifetime
from ..arguments import seconds
from ..codec import commands, layouts
from ..codec.data_rate import RATE_BASE_HZ, RATE_DIVIDER_ADDRESS
from ..codec.framing import DataPacket, MAX_ADDRESS, MIN_ADDRESS
from ..codec.parser import SensorStreamParser
from ..device import timeouts
from ..device.identity import DeviceInfo, IDENTIFIER_NAMES, read_firmware, read_identifier
from ..device.link import DeviceLink, DeviceTimeout, LinkOptions
from ..device.port import (
    port_group, PortBusy, PortDisconnected, PortError, PortMissing, PortPermissionDenied,
    serial_group, SerialPort, UDEV_RULE_INSTALL,
)

#: The factory addresses: the last two digits of the serial number.
FACTORY_ADDRESSES = range(1, 100)
#: Good records in a row that make a wired stream (one could be chance).
_WIRED_FRAMES_NEEDED = 2

#: Called with (stage, done, total) as the probe goes: stage is 'listen',
#: 'ping' or 'identify'.
Progress = Callable[[str, int, int], None]


@dataclass(frozen=True)
class ProbeConfig:
    """What to look for and how patient to be."""

    #: Node addresses to ping through a base station.
    addresses: Iterable[int] = FACTORY_ADDRESSES
    baud: int = 115200
    low_latency: bool = True
    #: Seconds to listen for sensors that already stream (one packet is enough).
    listen_s: float = 0.5
    #: Seconds to wait for the answer to a ping, until a base station has answered one.
    ping_timeout: float = timeouts.PROBE_PING_TIMEOUT
    #: Seconds to wait for it once a base station is known to be there.
    answer_timeout: float = timeouts.PROBE_ANSWER_TIMEOUT
    #: This many unanswered pings first: no base station on the port.
    silent_pings: int = 2
    request_timeout: float = timeouts.PROBE_REQUEST_TIMEOUT
    request_retries: int = timeouts.PROBE_REQUEST_RETRIES
    #: Stop a streaming sensor to read it (and restart it), instead of trying
    #: combined mode first.
    stop_streams: bool = False


class SensorFound(NamedTuple):
    """One sensor, what it says it is, and how it was found and left."""

    #: Node address behind a base station; None for a wired sensor.
    address: int | None
    #: 'stream' (heard streaming), 'ping' (answered a ping) or 'wired' (answered
    #: a request on a port without a base station).
    found_by: str
    #: Identity and firmware, None if the sensor did not tell them.
    info: DeviceInfo | None
    #: EEPROM data-rate divider (rate = 51200 / divider Hz), None if unknown.
    divider: int | None
    #: Record code it was streaming when found (0: none seen).
    streaming: int
    #: Its stream was stopped to read it, and restarted.
    restarted: bool
    #: LQI and RSSI of its latest streamed packet (wireless, streaming only).
    lqi: int | None
    rssi: int | None
    #: Anything the user should know (e.g. a stream that did not restart).
    note: str = ''

    @property
    def wireless(self) -> bool:
        """Whether the sensor is reached through a base station."""
        return self.address is not None

    @property
    def rate_hz(self) -> float | None:
        """Return the data rate the divider gives, or None."""
        return RATE_BASE_HZ / self.divider if self.divider else None


class PortProbe(NamedTuple):
    """What one port turned out to hold."""

    path: str
    #: 'probed', or why not: 'busy', 'missing', 'denied', 'error', 'disconnected'.
    status: str
    #: The error as a user can act on it, empty when probed.
    message: str
    #: True: a base station answered; False: none did; None: not probed that far.
    base_station: bool | None
    sensors: tuple[SensorFound, ...]
    #: Addresses pinged, and how long that took (s).
    pinged: int
    ping_seconds: float
    #: How long the whole probe took (s).
    seconds: float


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


class _Heard:
    """What streamed from one address (None: a wired sensor)."""

    __slots__ = ('code', 'count', 'lqi', 'rssi')

    def __init__(self) -> None:
        self.code = 0
        self.count = 0
        self.lqi: int | None = None
        self.rssi: int | None = None


class _Prober:
    """The dialogue with one open port; see the module docstring for the order."""

    def __init__(self, port: SerialPort, config: ProbeConfig,
                 progress: Progress | None) -> None:
        self.port = port
        self.config = config
        self._progress = progress or (lambda stage, done, total: None)
        self._heard: dict[int | None, _Heard] = {}
        self._heard_lock = threading.Lock()
        self._wired_parser: SensorStreamParser | None = None
        self.link: DeviceLink | None = None
        self.base_station: bool | None = None
        self.pinged = 0
        self.ping_seconds = 0.0

    # -- what the reader thread sees ------------------------------------

    def _on_record(self, packet: DataPacket, now: float, mono: float = 0.0) -> None:
        layout = commands.LAYOUT_BY_TYPE.get(type(packet.record))
        code = layout.code if layout is not None else 0
        with self._heard_lock:
            heard = self._heard.setdefault(packet.address, _Heard())
            heard.code = code
            heard.count += 1
            heard.lqi, heard.rssi = packet.lqi, packet.rssi

    def _on_bytes(self, data: bytes, now: float) -> None:
        # While listening, the same bytes also go through a wired parser: a
        # wired sensor's stream has no packets for the wireless one to find.
        parser = self._wired_parser
        if parser is not None:
            for event in parser.feed(data):
                if isinstance(event, DataPacket):
                    self._on_record(event, now)

    def heard(self, address: int | None) -> tuple[int, int]:
        """Return (record code, packets) streamed from ``address`` so far."""
        with self._heard_lock:
            heard = self._heard.get(address)
            return (heard.code, heard.count) if heard is not None else (0, 0)

    # -- links -----------------------------------------------------------

    def _open_link(self, wireless: bool) -> DeviceLink:
        if self.link is not None:
            self.link.stop()
        # No address yet: a listening link takes packets from every node.
        self.link = DeviceLink(self.port, None, self._on_record, LinkOptions(
            wireless=wireless, read_timeout=0.05, on_bytes=self._on_bytes))
        self.link.start()
        return self.link

    def close(self) -> None:
        """Stop the reader thread (the caller closes the port)."""
        if self.link is not None:
            self.link.stop()

    # -- the probe -------------------------------------------------------

    def run(self) -> list[SensorFound]:
        """Listen, sweep, identify; return the sensors found."""
        cfg = self.config
        self._wired_parser = SensorStreamParser(wireless=False)
        link = self._open_link(wireless=True)
        self._listen(cfg.listen_s)
        self._wired_parser = None
        with self._heard_lock:
            streaming = {a for a in self._heard if a is not None}
            wired = self._heard.get(None)
            if wired is not None and (streaming or wired.count < _WIRED_FRAMES_NEEDED):
                del self._heard[None]  # checksums that held by chance in other bytes
                wired = None
        if wired is not None:
            self.base_station = False
            return self._wired(self._open_link(wireless=False), found_by='stream')
        if streaming:
            self.base_station = True
        answered = self._sweep(link, [a for a in cfg.addresses if a not in streaming])
        if self.base_station is False:
            return self._wired(self._open_link(wireless=False), found_by='wired')
        with self._heard_lock:  # heard during the sweep too (a slow stream)
            streaming = {a for a in self._heard if a is not None}
        found = sorted(streaming | set(answered))
        sensors = []
        for index, address in enumerate(found):
            self._progress('identify', index, len(found))
            sensors.append(self._identify(link, address,
                                          'stream' if address in streaming else 'ping'))
        self._progress('identify', len(found), len(found))
        return sensors

    def _listen(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        step = max(seconds / 10, 0.01)
        while (left := deadline - time.monotonic()) > 0:
            self._progress('listen', round((seconds - left) / step), 10)
            time.sleep(min(step, left))
        self._progress('listen', 10, 10)

    def _sweep(self, link: DeviceLink, addresses: list[int]) -> list[int]:
        """Ping each address; return those whose sensor answered."""
        start = time.monotonic()
        try:
            return self._ping_each(link, addresses)
        finally:
            self.ping_seconds += time.monotonic() - start

    def _ping_each(self, link: DeviceLink, addresses: list[int]) -> list[int]:
        cfg = self.config
        answered = []
        silent = 0
        for index, address in enumerate(addresses):
            self._progress('ping', index, len(addresses))
            # A base station answers every ping, if slowly for a node that is
            # not there: once one has answered, a missing answer is waited for.
            timeout = cfg.answer_timeout if self.base_station else cfg.ping_timeout
            answer = link.ping_once(address, timeout)
            self.pinged += 1
            if answer is None:
                silent += 1
                if not self.base_station and silent >= cfg.silent_pings:
                    self.base_station = False
                    return []
                # An answer that comes late must not pass for the next one's.
                time.sleep(cfg.ping_timeout)
                continue
            self.base_station = True
            if answer:
                answered.append(address)
        self._progress('ping', len(addresses), len(addresses))
        return answered

    def _wired(self, link: DeviceLink, found_by: str) -> list[SensorFound]:
        """Return the sensor on the line itself, if one answers, as a list of 0 or 1."""
        self._progress('identify', 0, 1)
        sensor = self._identify(link, None, found_by)
        self._progress('identify', 1, 1)
        if sensor.info is None and not sensor.streaming:
            return []
        return [sensor]

    # -- one sensor ------------------------------------------------------

    def _identify(self, link: DeviceLink, address: int | None, found_by: str) -> SensorFound:
        cfg = self.config
        link.retarget(address)
        code, _ = self.heard(address)
        info = divider = None
        if not (code and cfg.stop_streams):
            info, divider = self._read(link)
        code, _ = self.heard(address)  # a slow stream may show itself only now
        restarted = False
        note = ''
        if info is None and code:
            # Combined mode failed (or was not wanted): quiet it, read, restart.
            if self._stop_stream(link, address):
                info, divider = self._read(link)
                restarted = self._restart(link, address, code, divider)
                if not restarted:
                    note = (f'its 0x{code:02X} stream was stopped to read it and did not '
                            f'restart: power-cycle the sensor or run the node')
            else:
                note = 'streams but answers no request'
        with self._heard_lock:
            heard = self._heard.get(address)
        return SensorFound(address, found_by, info, divider, code, restarted,
                           heard.lqi if heard else None, heard.rssi if heard else None, note)

    def _request(self, link: DeviceLink, command: bytes, code: int) -> Any:
        cfg = self.config
        return link.request(command, code, cfg.request_timeout, cfg.request_retries)

    def _read(self, link: DeviceLink) -> tuple[DeviceInfo | None, int | None]:
        """Return the identity and rate divider; (None, None) if it answers nothing."""
        cfg = self.config
        try:
            firmware = read_firmware(link, cfg.request_timeout, cfg.request_retries)
        except DeviceTimeout:
            return None, None
        texts = [self._identifier(link, selector) for selector in range(len(IDENTIFIER_NAMES))]
        try:
            divider = self._request(link, commands.read_eeprom(RATE_DIVIDER_ADDRESS),
                                    layouts.READ_EEPROM).value
        except DeviceTimeout:
            divider = None
        return DeviceInfo(*texts, firmware), divider

    def _identifier(self, link: DeviceLink, selector: int) -> str:
        try:
            return read_identifier(link, selector, self.config.request_timeout,
                                   self.config.request_retries)
        except DeviceTimeout:
            return ''

    def _quiet_for(self, address: int | None, seconds: float, within: float) -> bool:
        """Wait until nothing streamed from ``address`` for ``seconds``; say if so."""
        deadline = time.monotonic() + within
        _, count = self.heard(address)
        quiet_since = time.monotonic()
        while time.monotonic() < deadline:
            time.sleep(0.01)
            _, now_count = self.heard(address)
            if now_count != count:
                count, quiet_since = now_count, time.monotonic()
            elif time.monotonic() - quiet_since >= seconds:
                return True
        return False

    def _stop_stream(self, link: DeviceLink, address: int | None) -> bool:
        """Send 0xFA until the stream stops (it has no reply; the radio may drop it)."""
        for _ in range(3):
            link.stop_streaming()
            if self._quiet_for(address, 0.3, 1.0):
                return True
        return False

    def _restart(self, link: DeviceLink, address: int | None, code: int,
                 divider: int | None) -> bool:
        """Stream ``code`` again, as it was; True once its records flow."""
        period = divider / RATE_BASE_HZ if divider else 0.01
        for _ in range(self.config.request_retries + 2):
            _, before = self.heard(address)
            try:
                self._request(link, commands.set_continuous(code), layouts.SET_CONTINUOUS)
            except DeviceTimeout:
                pass  # the reply may be lost while the stream started: look for records
            deadline = time.monotonic() + max(0.3, 5 * period)
            while time.monotonic() < deadline:
                if self.heard(address)[1] > before:
                    return True
                time.sleep(0.01)
        return False


def probe_port(path: str, config: ProbeConfig | None = None,
               progress: Progress | None = None) -> PortProbe:
    """Open ``path`` exclusively and find the sensors behind it; never raises PortError."""
    cfg = config or ProbeConfig()
    start = time.monotonic()
    try:
        port = SerialPort(path, cfg.baud, low_latency=cfg.low_latency)
    except PortError as exc:
        status = {PortBusy: 'busy', PortMissing: 'missing',
                  PortPermissionDenied: 'denied'}.get(type(exc), 'error')
        return PortProbe(path, status, str(exc), None, (), 0, 0.0, time.monotonic() - start)
    prober = _Prober(port, cfg, progress)
    status, message, sensors = 'probed', '', []
    try:
        sensors = prober.run()
    except PortDisconnected as exc:
        status, message = 'disconnected', f'{path}: the device went away while probed ({exc})'
    finally:
        prober.close()
        port.close()
    return PortProbe(path, status, message, prober.base_station, tuple(sensors),
                     prober.pinged, prober.ping_seconds, time.monotonic() - start)


# -- the command line ----------------------------------------------------------

EXIT_FOUND = 0
EXIT_NONE = 1
EXIT_INTERRUPTED = 130

#: What to do about a port in use.
BUSY_HINT = ' (the driver? fuser -v {path} names the process); skipped'
#: Wired sensors need no address, but the node requires one: any valid one does.
WIRED_ADDRESS = 1


def node_command(path: str, sensor: SensorFound) -> str:
    """Return the ``ros2 run`` line that starts the driver for ``sensor``."""
    head = f'ros2 run i3dmgx2_driver node --ros-args -p port:={shlex.quote(path)}'
    if sensor.wireless:
        return f'{head} -p address:={sensor.address}'
    return f'{head} -p wireless:=false -p address:={WIRED_ADDRESS}'


def port_command(path: str, sensors: Sequence[SensorFound]) -> str:
    """
    Return the one ``ros2 run`` line that starts the driver for every sensor on a port.

    The node opens its port exclusively, so several sensors behind one base
    station are served by one node (``addresses``), never one node each.
    """
    wireless = [sensor for sensor in sensors if sensor.wireless]
    if len(wireless) < 2:
        return node_command(path, sensors[0])
    listed = ','.join(str(address) for address in sorted(s.address for s in wireless))
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
    owner = port_group(path)
    if owner is not None and not owner[1] and 'udev rule' not in message:
        group = owner[0]
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
    parser.add_argument('--listen', type=_seconds, default=ProbeConfig.listen_s,
                        metavar='SECONDS',
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

def _sensor_dict(sensor: SensorFound, command: str | None) -> dict[str, Any]:
    info = sensor.info
    return {
        'address': sensor.address,
        'link': 'wireless' if sensor.wireless else 'wired',
        'found_by': sensor.found_by,
        'model_number': info.model_number if info else None,
        'serial_number': info.serial_number if info else None,
        'model_name': info.model_name if info else None,
        'options': info.options if info else None,
        'firmware': info.firmware if info else None,
        'rate_divider': sensor.divider,
        'rate_hz': round(sensor.rate_hz, 3) if sensor.rate_hz else None,
        'streaming': f'0x{sensor.streaming:02X}' if sensor.streaming else None,
        'stream_restarted': sensor.restarted,
        'lqi': sensor.lqi,
        'rssi': sensor.rssi,
        'note': sensor.note or None,
        'command': command,
    }


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
        out.update({
            'message': probe.message or None,
            'base_station': probe.base_station,
            'pinged': probe.pinged,
            'ping_seconds': round(probe.ping_seconds, 3),
            'seconds': round(probe.seconds, 3),
            'sensors': [_sensor_dict(s, command) for s in probe.sensors],
            'command': command,
        })
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
    for port in ports:
        rows.append([port.device, port.by_id or '-', port.usb_id or '-',
                     port.description or '-', port.kind or '-',
                     'probe' if port.device in probing else 'skip'])
    out.write('Serial ports:\n')
    _table(rows, out)


def _state(sensor: SensorFound) -> str:
    if not sensor.streaming:
        return 'polled'
    state = f'streaming 0x{sensor.streaming:02X}'
    return state + ' (restarted)' if sensor.restarted else state


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
            info = sensor.info
            rows.append([
                port.device, 'wireless' if sensor.wireless else 'wired',
                str(sensor.address) if sensor.wireless else '-',
                (info.serial_number or '?') if info else '?',
                (info.model_name or info.model_number or '?') if info else '?',
                (info.firmware or '?') if info else '?',
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
        self.out = out
        self.enabled = enabled
        self.port = ''
        self._last = 0.0

    def __call__(self, stage: str, done: int, total: int) -> None:
        now = time.monotonic()
        if not self.enabled or (done not in (0, total) and now - self._last < 0.05):
            return
        self._last = now
        text = {'listen': 'listening for streams', 'ping': f'pinging {done}/{total}',
                'identify': f'reading sensor {min(done + 1, total)}/{total}'}[stage]
        self.out.write(f'\r\x1b[K{self.port}: {text}')
        self.out.flush()

    def clear(self) -> None:
        if self.enabled:
            self.out.write('\r\x1b[K')
            self.out.flush()


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``discover``; return the exit status."""
    args = build_parser().parse_args(argv)
    # A closed terminal, SIGTERM or its parent's end take Ctrl-C's way out: the port is
    # closed, the sensors left as found.
    lifetime.interrupt_on_stop_signals()
    out = sys.stdout
    if args.port:
        ports = [describe_path(path, args.by_id_dir) for path in args.port]
        probing = {p.device for p in ports}
    else:
        ports = list_ports(args.by_id_dir)
        probing = {p.device for p in ports if p.likely or args.all}
    if not args.json and not args.port:
        print_ports(ports, probing, out)
    config = ProbeConfig(addresses=args.addresses, baud=args.baud, listen_s=args.listen,
                         ping_timeout=args.ping_timeout, stop_streams=args.stop_streams)
    progress = _ProgressLine(sys.stderr, sys.stderr.isatty() and not args.json)
    results = []
    try:
        for port in ports:
            if port.device in probing:
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
