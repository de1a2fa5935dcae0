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
What arrives on the line while nothing of ours does, and what it suggests.

When the link hears nothing it can use, "device not answering" is true but
useless: the user needs to know whether the port was silent, carried packets
from another sensor, spoke the other framing, or sent bytes that are no
packets at all (a wrong baud rate, another device). The observer is fed every
read of the link's reader thread while no packet of ours has arrived for a
while, and reads the bytes with parsers of its own: one for wireless packets
of any address (addresses heard) and one for wired records, so it sees both
framings whatever the link is configured for. Every half second it judges the
window, which starts afresh whenever a packet of ours arrives, and reports a
:class:`Finding` that names what it observed and the parameter to change.

It costs nothing once records flow: the link does not call it then (the
reader thread is the latency path). It is paused while the driver itself
keeps the device quiet (a service operation, a managed node inactive), when
silence is no symptom.
"""

from collections import Counter
from collections.abc import Callable
from typing import NamedTuple

from ..codec.framing import DataPacket
from ..codec.parser import SensorStreamParser

#: Observe only after this long without a packet of ours (s).
QUIET_AFTER = 0.5
#: How often the window is judged (s).
JUDGE_EVERY = 0.5
#: Shortest window that packets of another address or framing are judged on (s).
MIN_WINDOW = 1.0
#: A window with no byte at all this long is reported as silence (s).
SILENCE_AFTER = 3.0
#: Bytes that neither framing can read, over at least ``NOISE_WINDOW`` s, are noise.
NOISE_BYTES = 64
NOISE_WINDOW = 2.0
#: Wired records needed before a wireless link blames the framing (one could be chance).
MIN_WIRED_RECORDS = 2

#: Kinds of finding, the keys a caller throttles its messages by.
ADDRESS, FRAMING, NOISE, SILENCE = 'address', 'framing', 'noise', 'silence'


class Finding(NamedTuple):
    """One thing observed on the line and what to change: ``kind`` is a key above."""

    kind: str
    message: str


class Window(NamedTuple):
    """What one observation window saw, in plain numbers (for tests and judging)."""

    seconds: float
    bytes_in: int
    #: Wireless data packets by the node address they came from.
    heard: dict[int, int]
    wired_records: int
    #: Bytes that neither framing could read (the fewer of the two parsers' counts).
    unreadable: int


def _addresses(heard: dict[int, int], span: float) -> str:
    """'node 95 (100 in 1.0 s), node 96 (3)': the busiest first."""
    ranked = sorted(heard.items(), key=lambda item: -item[1])
    parts = [f'node {a} ({n} in {span:.1f} s)' if i == 0 else f'node {a} ({n})'
             for i, (a, n) in enumerate(ranked[:4])]
    return ', '.join(parts) + (', ...' if len(ranked) > 4 else '')


def judge(window: Window, port: str, address: int, wireless: bool, baud: int) -> Finding | None:
    """
    Say what a window without any packet of ours suggests; None if nothing yet.

    Pure: the thresholds above, no clock. Packets of another address or of
    the other framing are named first (they say exactly what to change),
    then unreadable bytes, then silence.
    """
    span, heard = window.seconds, window.heard
    if span >= MIN_WINDOW:
        best = max(heard, key=heard.__getitem__) if heard else None
        if wireless and heard and not heard.get(address):
            return Finding(ADDRESS, (
                f'packets arrive from {_addresses(heard, span)}, none from node '
                f'{address}: is that your sensor? If so, set -p address:={best}'))
        if wireless and window.wired_records >= MIN_WIRED_RECORDS and not heard:
            return Finding(FRAMING, (
                f'{port} sends wired (unframed) records ({window.wired_records} in '
                f'{span:.1f} s), not wireless packets: is a wired sensor on this port? '
                f'Then set -p wireless:=false'))
        if not wireless and heard:
            also = '' if best == address else f' and -p address:={best}'
            return Finding(FRAMING, (
                f'{port} sends wireless packets from {_addresses(heard, span)}, not '
                f'wired records: is a wireless base station on this port? Then set '
                f'-p wireless:=true{also}'))
    if span >= NOISE_WINDOW and window.unreadable >= NOISE_BYTES and not heard \
            and not window.wired_records:
        return Finding(NOISE, (
            f'{window.bytes_in} bytes in {span:.1f} s from {port}, and not one valid 3DM-GX2 '
            f'packet among them: check the baud rate (read at {baud} baud here, -p baud; the '
            f'3DM-GX2 ships set to 115200) and that the device on this port is a 3DM-GX2'))
    if span >= SILENCE_AFTER and not window.bytes_in:
        if wireless:
            return Finding(SILENCE, (
                f"not one byte from {port} in {span:.1f} s, not even the base station's "
                f'ACK of a command: is a powered 3DM-GX2 base station on this port? A wired '
                f'sensor needs -p wireless:=false'))
        return Finding(SILENCE, (
            f'not one byte from {port} in {span:.1f} s: is the sensor powered and connected? '
            f'A wireless base station needs -p wireless:=true (it ignores unframed commands)'))
    return None


class LineObserver:
    """
    Read the bytes of one link while none of its own packets arrive.

    ``feed`` runs in the link's reader thread with every read (b'' on a
    timeout) and the time of the link's last packet (``epoch``): a new epoch
    starts a new window. ``on_finding`` is called from there with each
    judgement that finds something, at most every ``JUDGE_EVERY`` s; it must
    not block (the supervisor throttles and logs it).
    """

    def __init__(self, port: str, address: int, wireless: bool, baud: int,
                 on_finding: Callable[[Finding], None]) -> None:
        #: The line as configured, which the findings name: judge()'s arguments.
        self._line = (port, address, wireless, baud)
        self._on_finding = on_finding
        #: The latest finding on this link, if any (kept across windows).
        self.last_finding: Finding | None = None
        #: False while the driver keeps the device quiet on purpose: the link
        #: then feeds nothing, and the next window starts when it resumes.
        self.active = True
        self._packets = SensorStreamParser(address=None, wireless=True)
        self._wired = SensorStreamParser(wireless=False)
        self._heard: Counter[int] = Counter()
        self._restart(0.0, None)  # the first feed starts the first window

    def _restart(self, now: float, epoch: float | None) -> None:
        self._epoch, self._start, self._next_judge = epoch, now, now + JUDGE_EVERY
        self._heard.clear()
        self._wired_records = self._bytes = 0
        self._base = (self._packets.stats.bytes_skipped, self._wired.stats.bytes_skipped)

    def pause(self) -> None:
        """Stop observing: the device is quiet on purpose."""
        self.active = False

    def resume(self) -> None:
        """Observe again, from a fresh window."""
        self._epoch = None
        self.active = True

    def window(self, now: float) -> Window:
        """Return what the current window saw up to ``now``."""
        unreadable = min(self._packets.stats.bytes_skipped - self._base[0],
                         self._wired.stats.bytes_skipped - self._base[1])
        return Window(now - self._start, self._bytes, dict(self._heard), self._wired_records,
                      unreadable)

    def feed(self, data: bytes, now: float, epoch: float) -> Finding | None:
        """Count one read; judge the window when due; return (and report) a finding."""
        if epoch != self._epoch:
            self._restart(now, epoch)
        if data:
            self._bytes += len(data)
            self._heard.update(event.address for event in self._packets.feed(data)
                               if isinstance(event, DataPacket))
            self._wired_records += sum(isinstance(e, DataPacket) for e in self._wired.feed(data))
        if now < self._next_judge:
            return None
        self._next_judge = now + JUDGE_EVERY
        finding = judge(self.window(now), *self._line)
        if finding is not None:
            self.last_finding = finding
            self._on_finding(finding)
        return finding
