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
What ``discover`` tries on one port, and what it found there.

:func:`probe_port` opens the port exclusively and then, in this order:

1. listens: a sensor that already streams gives itself away, a wireless
   one by the node address every data packet carries, a wired one by records
   whose checksums hold;
2. sweeps with base-station pings. A base station answers every ping with one
   byte (0x02: the node answers over the radio; 0x21: it does not), so
   silence to the first few pings means there is no base station;
3. without a base station, asks as a wired sensor is asked;
4. for each sensor found, reads its data-rate divider (EEPROM 0xFCA2, read,
   never written: the first answer, or none, says whether it answers at
   all), its identity (0xEA) and firmware (0xE9).

Every sensor is left as it was found. A streaming sensor is asked in
combined mode (polled requests interleave with its stream), so its stream
goes on untouched; only if it does not answer that way (the radio loses
more while streaming), or when asked to, is its stream stopped, the sensor
read, and the same record restarted and seen to flow again. Stopping,
reading and restarting are the steps every conversation with a sensor takes
(device/sensor_steps.py), with the waits of device/timeouts.py; which
ports, addresses and questions to try, and leaving each sensor as found,
are this module's. What is found is printed by discover.py.
"""

from collections.abc import Callable, Iterable
from dataclasses import dataclass
import threading
import time
from typing import NamedTuple

from ..codec.data_rate import period_of_divider, rate_of_divider
from ..codec.framing import DataPacket
from ..codec.parser import SensorStreamParser
from ..device import timeouts
from ..device.identity import DeviceInfo, read_identity
from ..device.link import DeviceError, DeviceLink, LinkOptions
from ..device.port import (
    PortBusy, PortDisconnected, PortError, PortMissing, PortPermissionDenied, SerialPort,
)
from ..device.sensor_steps import SensorSteps

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
    listen_s: float = timeouts.PROBE_LISTEN_S
    #: Seconds to wait for the answer to a ping, until a base station has answered one.
    ping_timeout: float = timeouts.PROBE_PING_TIMEOUT
    #: Seconds to wait for it once a base station is known to be there.
    answer_timeout: float = timeouts.PROBE_ANSWER_TIMEOUT
    #: This many unanswered pings first: no base station on the port.
    silent_pings: int = timeouts.PROBE_SILENT_PINGS
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
        return rate_of_divider(self.divider) if self.divider else None


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


class _Heard(NamedTuple):
    """What streamed from one address (None: a wired sensor): its latest record's."""

    code: int = 0
    count: int = 0
    lqi: int | None = None
    rssi: int | None = None


class _Prober:
    """The dialogue with one open port; see the module docstring for the order."""

    def __init__(self, port: SerialPort, config: ProbeConfig, progress: Progress | None) -> None:
        self.port, self.config = port, config
        self.steps = SensorSteps(config.request_timeout, config.request_retries)
        self._progress = progress or (lambda stage, done, total: None)
        self._heard: dict[int | None, _Heard] = {}
        self._heard_lock = threading.Lock()
        self._wired_parser: SensorStreamParser | None = None
        self.link: DeviceLink | None = None
        self.base_station: bool | None = None
        self.pinged, self.ping_seconds = 0, 0.0

    # -- what the reader thread sees ------------------------------------

    def _on_record(self, packet: DataPacket, now: float, mono: float = 0.0) -> None:
        with self._heard_lock:
            count = self._heard.get(packet.address, _Heard()).count + 1
            self._heard[packet.address] = _Heard(packet.code, count, packet.lqi, packet.rssi)

    def _on_bytes(self, data: bytes, now: float) -> None:
        # While listening, the same bytes also go through a wired parser: a
        # wired sensor's stream has no packets for the wireless one to find.
        parser = self._wired_parser
        if parser is not None:
            for event in parser.feed(data):
                if isinstance(event, DataPacket):
                    self._on_record(event, now)

    def heard(self, address: int | None) -> _Heard:
        """Return what streamed from ``address`` so far."""
        with self._heard_lock:
            return self._heard.get(address) or _Heard()

    # -- links -----------------------------------------------------------

    def _open_link(self, wireless: bool) -> DeviceLink:
        self.close()
        # No address yet: a listening link takes packets from every node.
        self.link = DeviceLink(self.port, None, self._on_record,
                               LinkOptions.listening(wireless, self._on_bytes))
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
        cfg, start = self.config, time.monotonic()
        answered, silent = [], 0
        try:
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
        finally:
            self.ping_seconds += time.monotonic() - start

    def _wired(self, link: DeviceLink, found_by: str) -> list[SensorFound]:
        """Return the sensor on the line itself, if one answers, as a list of 0 or 1."""
        self._progress('identify', 0, 1)
        sensor = self._identify(link, None, found_by)
        self._progress('identify', 1, 1)
        return [sensor] if sensor.info is not None or sensor.streaming else []

    # -- one sensor ------------------------------------------------------

    def _identify(self, link: DeviceLink, address: int | None, found_by: str) -> SensorFound:
        link.retarget(address)
        code = self.heard(address).code
        info = divider = None
        if not (code and self.config.stop_streams):
            info, divider = self._read(link)
        code = self.heard(address).code  # a slow stream may show itself only now
        restarted, note = False, ''
        if info is None and code:
            # Combined mode failed (or was not wanted): quiet it, read, restart.
            if self.steps.stop_until_quiet(link, period_of_divider(divider)):
                info, divider = self._read(link)
                try:  # stream ``code`` again, as it was; True once its records flow
                    restarted = self.steps.start_stream(link, code, period_of_divider(divider))
                except DeviceError:
                    restarted = False
                if not restarted:
                    note = (f'its 0x{code:02X} stream was stopped to read it and did not '
                            f'restart: power-cycle the sensor or run the node')
            else:
                note = 'streams but answers no request'
        heard = self.heard(address)
        return SensorFound(address, found_by, info, divider, code, restarted,
                           heard.lqi, heard.rssi, note)

    def _read(self, link: DeviceLink) -> tuple[DeviceInfo | None, int | None]:
        """Return the identity and rate divider; (None, None) if it answers nothing."""
        steps = self.steps
        try:
            # The one word every sensor has, read first: unanswered, there is nobody to
            # ask the rest (a port without a sensor is given up in one request's time).
            divider = steps.read_divider(link)
        except DeviceError:
            return None, None
        return read_identity(link, steps.timeout, steps.retries), divider


def probe_port(path: str, config: ProbeConfig | None = None,
               progress: Progress | None = None) -> PortProbe:
    """Open ``path`` exclusively and find the sensors behind it; never raises PortError."""
    cfg, start = config or ProbeConfig(), time.monotonic()
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
