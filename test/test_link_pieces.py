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
A link on its own, without a port or a thread; the pieces of a connection.

Which data packet is a reply, a record of the stream or both, and the
radio's quality sums (``DeviceLink``, fed as its reader would feed it), what
the reader tells a link that joins it late, how a port is opened for a
connection and a shared port alike (``PortOpener``), and a hot-path
observer that inherits the protocol's methods, which note nothing.
"""

from collections.abc import Callable
import gc
import threading
import time
import weakref

from fake_ports import FakePort
from i3dmgx2_driver.codec import layouts
from i3dmgx2_driver.codec.framing import DataPacket
from i3dmgx2_driver.codec.records import AccelAngRate, Magnetometer
from i3dmgx2_driver.device import hot_path
from i3dmgx2_driver.device.link import DeviceLink, LinkOptions, PortReader, RadioStats
from i3dmgx2_driver.device.port import PortDisconnected, SerialPort
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.device.shared_port import PortOpener
from packets import packet_of
import pytest

ZERO = (0.0, 0.0, 0.0)


def _packet(record: object, lqi: int | None = 200, rssi: int | None = 150) -> DataPacket:
    return packet_of(95, record, lqi, rssi)


class _Line(FakePort):
    """A port whose every write runs ``answer`` at once, as if the reply came back."""

    def __init__(self) -> None:
        self.written: list[bytes] = []
        self.answer = lambda: None

    def write(self, data: bytes) -> None:
        self.written.append(data)
        self.answer()

    def read_some(self, timeout: float) -> bytes:
        raise PortDisconnected('unplugged')


def _link(records_of: int | None = None) -> tuple[DeviceLink, _Line, list]:
    line, seen = _Line(), []
    link = DeviceLink(line, 95, lambda event, now, mono: seen.append((event.record, now, mono)),
                      LinkOptions(records_of=records_of))
    return link, line, seen


def test_radio_quality_keeps_latest_lowest_and_mean() -> None:
    link, _, _ = _link()
    assert link.radio.stats is None
    for lqi, rssi in ((200, 150), (180, 160), (220, 140)):
        link.on_data(_packet(Magnetometer(ZERO, 7), lqi, rssi), 10.0, 1.0)
    assert link.radio.stats == RadioStats(220, 140, 180, 140, 200.0, 150.0)


def test_any_record_counts_while_nothing_is_streamed() -> None:
    link, _, seen = _link()
    assert not link.heard
    link.on_data(_packet(Magnetometer(ZERO, 7)), 10.0, 1.0)
    assert (link.records, link.last_code, link.last_data_mono) == (1, layouts.MAGNETOMETER, 1.0)
    assert seen == [(Magnetometer(ZERO, 7), 10.0, 1.0)]
    assert link.other_records == 0
    assert link.heard and link.radio.stats is not None and link.radio.stats.lqi == 200


def test_a_record_the_consumer_does_not_take_is_counted_not_handed_on() -> None:
    link, _, seen = _link(records_of=layouts.ACCEL_ANG_RATE)
    link.on_data(_packet(Magnetometer(ZERO, 7)), 10.0, 1.0)
    # Still the sensor streaming (for the wait for silence), but no sample of the stream.
    assert (link.records, link.last_data_mono) == (1, 1.0)
    assert (seen, link.other_records) == ([], 1)
    link.on_data(_packet(AccelAngRate(ZERO, ZERO, 9)), 11.0, 2.0)
    assert (seen, link.other_records) == ([(AccelAngRate(ZERO, ZERO, 9), 11.0, 2.0)], 1)


def test_a_polled_reply_of_another_code_is_a_reply_only() -> None:
    link, line, seen = _link()
    link.set_streamed(layouts.ACCEL_ANG_RATE)
    line.answer = lambda: link.on_data(_packet(Magnetometer(ZERO, 7)), 10.0, 1.0)
    reply = link.request(bytes((layouts.MAGNETOMETER,)), layouts.MAGNETOMETER, 0.2, 1)
    assert reply == Magnetometer(ZERO, 7)
    assert (link.records, seen, link.heard, link.other_records) == (0, [], True, 0)
    # Not the stream's record: the stall watch must not take it for one.
    assert link.last_data_mono == 0.0


def test_a_polled_reply_of_the_streamed_code_is_both() -> None:
    link, line, seen = _link()
    link.set_streamed(layouts.ACCEL_ANG_RATE)
    record = AccelAngRate(ZERO, ZERO, 9)
    line.answer = lambda: link.on_data(_packet(record, None, None), 11.0, 2.0)
    assert link.request(bytes((layouts.ACCEL_ANG_RATE,)), layouts.ACCEL_ANG_RATE, 0.2, 1) \
        == record
    assert (link.records, link.last_data_mono) == (1, 2.0)
    assert seen == [(record, 11.0, 2.0)]


def test_another_record_while_streaming_is_counted_apart_and_keeps_no_stream_alive() -> None:
    link, _, seen = _link(records_of=layouts.ACCEL_ANG_RATE)
    link.set_streamed(layouts.ACCEL_ANG_RATE)
    link.on_data(_packet(Magnetometer(ZERO, 7), None, None), 12.0, 3.0)
    assert (link.records, link.last_code) == (0, layouts.MAGNETOMETER)
    assert link.last_data_mono == 0.0
    # Not handed on as a sample of the stream: counted (diagnostics' "other records").
    assert (seen, link.other_records) == ([], 1) and link.radio.stats is None


def test_a_port_lost_wakes_the_waiting_request_with_why() -> None:
    link, line, _ = _link()
    line.answer = lambda: link.port_lost('unplugged')
    with pytest.raises(PortDisconnected, match='unplugged'):
        link.request(bytes((layouts.MAGNETOMETER,)), layouts.MAGNETOMETER, 5.0, 3)
    assert len(line.written) == 1  # no retry on a dead port


def test_a_link_that_joins_a_reader_late_is_told_what_it_missed() -> None:
    line = _Line()
    reader = PortReader(line, None)
    reader._run()  # in this thread: it starts, then finds the port gone
    assert reader.disconnected.is_set() and reader.error == 'unplugged'
    link = DeviceLink(line, 17, lambda event, now, mono: None, reader=reader)
    assert not link.running.is_set() and link.error is None
    reader.route(17, link)
    assert link.running.is_set() and link.error == 'unplugged'
    assert link.policy_outcome == reader.policy_outcome


class _QuietLine(_Line):
    """A port that stays open and sends nothing: each read waits out its timeout."""

    def read_some(self, timeout: float) -> bytes:
        time.sleep(min(timeout, 0.01))
        return b''


def _freed_by_refcount(make_link: Callable[[], DeviceLink],
                       end: Callable[[DeviceLink], None]) -> tuple[bool, bool]:
    """
    Start a link of its own reader, ``end`` it, drop it: are it and its reader gone at once.

    The collector is off meanwhile: what a reference cycle holds stays until a
    full collection, which in the node comes seldom (its start-up heap frozen).
    """
    gc.collect()
    gc.disable()
    try:
        link = make_link()
        link.start()
        end(link)
        refs = weakref.ref(link), weakref.ref(link.reader)
        del link
        return refs[0]() is None, refs[1]() is None
    finally:
        gc.enable()


@pytest.mark.parametrize('how', ['port lost', 'stopped', 'stopped before its thread ran'])
def test_a_link_and_its_reader_are_freed_when_dropped_not_at_a_full_collection(how: str) -> None:
    """
    Each reconnect drops a link and its reader: they must not wait for the collector.

    The memory curve's blocks and C heap rose for thousands of faults and fell
    at a full collection: every connection's link, reader, port, parsers and
    thread (60 objects), kept by the link and reader holding each other.
    """
    def lost(link: DeviceLink) -> None:
        assert link.disconnected.wait(5.0)
        link.stop()

    def stopped(link: DeviceLink) -> None:
        assert link.reader.running.wait(5.0)
        link.stop()

    def never_ran(link: DeviceLink) -> None:
        link.stop()

    if how == 'port lost':
        made = (lambda: _link()[0]), lost
    elif how == 'stopped':
        made = (lambda: DeviceLink(_QuietLine(), 95, lambda *_: None)), stopped
    else:
        made = (lambda: _unstarted(DeviceLink(_QuietLine(), 95, lambda *_: None))), never_ran
    assert _freed_by_refcount(*made) == (True, True)


def _unstarted(link: DeviceLink) -> DeviceLink:
    link.start = lambda: None  # the connection failed before its reader was started
    return link


class _Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, text: str) -> None:
        self.lines.append(text)


class _Reads(hot_path.HotPathObserver):
    def __init__(self) -> None:
        self.reads = 0

    def read(self, nbytes: int, read_time: float) -> None:
        self.reads += 1


def test_port_opener_opens_as_configured_and_logs_only_a_change(monkeypatch) -> None:
    states = iter(['on', 'on', 'refused'])
    calls = []

    def opened(port: SerialPort, path: str, baud: int, low_latency: bool) -> None:
        calls.append((path, baud, low_latency))
        port.low_latency_state = next(states)

    # The opener opens SerialPort itself: its opening is replaced, the class kept.
    monkeypatch.setattr(SerialPort, '__init__', opened)
    log = _Log()
    config = DeviceConfig(port='/dev/gx2', address=95, baud=115200, low_latency=False)
    opener = PortOpener(config, log)
    for _ in range(3):
        assert type(opener.open_port()) is SerialPort
    assert calls == [('/dev/gx2', 115200, False)] * 3
    assert log.lines == ['/dev/gx2: low-latency mode on', '/dev/gx2: low-latency mode refused']
    assert opener.low_latency_state == 'refused'


def test_port_opener_gives_every_reader_the_same_parts() -> None:
    def capture(data: bytes, when: float) -> None:
        pass

    cancel = threading.Event()
    config = DeviceConfig(port='/dev/gx2', address=95, wireless=False)
    options = PortOpener(config, _Log(), on_bytes=capture).reader_options(cancel=cancel)
    assert (options.wireless, options.on_bytes, options.cancel) == (False, capture, cancel)
    assert options.observer is None and options.thread_policy == config.thread_policy


def test_an_observer_inherits_methods_that_note_nothing() -> None:
    quiet = _Reads()
    assert quiet.parsed() is None and quiet.stamped() is None
    assert quiet.packed(7) is None and quiet.published(2.0) is None
