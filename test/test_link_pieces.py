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
The pieces a link and a connection are made of, each on its own, without a port.

Which data packet is a reply, a record of the stream or both
(``StreamWatch``), the radio's quality sums (``RadioQuality``), how a port
is opened for a connection and a shared port alike (``PortOpener``), and
the hot-path observer that notes nothing (``QuietObserver``).
"""

import threading

from i3dmgx2_driver.codec import layouts
from i3dmgx2_driver.codec.framing import DataPacket
from i3dmgx2_driver.codec.records import AccelAngRate, Magnetometer
from i3dmgx2_driver.device.exchange import Pending
from i3dmgx2_driver.device.hot_path import QuietObserver
from i3dmgx2_driver.device.port_opener import PortOpener, PortParts
from i3dmgx2_driver.device.radio import RadioQuality, RadioStats
from i3dmgx2_driver.device.settings import DeviceConfig
from i3dmgx2_driver.device.stream_watch import StreamWatch

ZERO = (0.0, 0.0, 0.0)


def _packet(record: object, lqi: int | None = 200, rssi: int | None = 150) -> DataPacket:
    return DataPacket(95, record, lqi, rssi)


class _Exchange:
    """What the watch reads of the exchange: the request waiting, if any."""

    def __init__(self) -> None:
        self.pending: Pending | None = None
        self.woken = 0

    def wake(self) -> None:
        self.woken += 1


def _watch() -> tuple[StreamWatch, _Exchange, RadioQuality, list]:
    exchange, radio, seen = _Exchange(), RadioQuality(), []
    watch = StreamWatch(lambda event, now, mono: seen.append((event.record, now, mono)),
                        exchange, radio)  # type: ignore[arg-type]
    return watch, exchange, radio, seen


def test_radio_quality_keeps_latest_lowest_and_mean() -> None:
    radio = RadioQuality()
    assert radio.stats is None
    for lqi, rssi in ((200, 150), (180, 160), (220, 140)):
        radio.note(lqi, rssi)
    assert radio.stats == RadioStats(220, 140, 180, 140, 200.0, 150.0)


def test_any_record_counts_while_nothing_is_streamed() -> None:
    watch, _, radio, seen = _watch()
    watch.on_data(_packet(Magnetometer(ZERO, 7)), 10.0, 1.0)
    assert (watch.records, watch.replies, watch.last_code) == (1, 0, layouts.MAGNETOMETER)
    assert (watch.last_data_time, watch.last_data_mono) == (10.0, 1.0)
    assert seen == [(Magnetometer(ZERO, 7), 10.0, 1.0)]
    assert radio.stats is not None and radio.stats.lqi == 200


def test_a_polled_reply_of_another_code_is_a_reply_only() -> None:
    watch, exchange, _, seen = _watch()
    watch.streamed = layouts.ACCEL_ANG_RATE
    pending = exchange.pending = Pending(layouts.MAGNETOMETER)
    watch.on_data(_packet(Magnetometer(ZERO, 7)), 10.0, 1.0)
    assert pending.done.is_set() and pending.reply == Magnetometer(ZERO, 7)
    assert (watch.records, watch.replies, seen) == (0, 1, [])
    # Not the stream's record: the stall watch must not take it for one.
    assert watch.last_data_mono == 0.0


def test_a_polled_reply_of_the_streamed_code_is_both() -> None:
    watch, exchange, _, seen = _watch()
    watch.streamed = layouts.ACCEL_ANG_RATE
    pending = exchange.pending = Pending(layouts.ACCEL_ANG_RATE)
    record = AccelAngRate(ZERO, ZERO, 9)
    watch.on_data(_packet(record, None, None), 11.0, 2.0)
    assert pending.reply == record
    assert (watch.records, watch.replies, watch.last_data_mono) == (1, 1, 2.0)
    assert seen == [(record, 11.0, 2.0)]


def test_another_record_while_streaming_is_handed_on_but_keeps_no_stream_alive() -> None:
    watch, _, radio, seen = _watch()
    watch.streamed = layouts.ACCEL_ANG_RATE
    watch.on_data(_packet(Magnetometer(ZERO, 7), None, None), 12.0, 3.0)
    assert (watch.records, watch.last_code) == (0, layouts.MAGNETOMETER)
    assert watch.last_data_mono == 0.0
    assert len(seen) == 1 and radio.stats is None


def test_wake_tells_the_exchange() -> None:
    watch, exchange, _, _ = _watch()
    watch.wake()
    assert exchange.woken == 1


class _Port:
    def __init__(self, state: str) -> None:
        self.low_latency_state = state


class _Log:
    def __init__(self) -> None:
        self.lines: list[str] = []

    def info(self, text: str) -> None:
        self.lines.append(text)


class _Opens(QuietObserver):
    def __init__(self) -> None:
        self.opens = 0

    def opened(self) -> None:
        self.opens += 1


def test_port_opener_opens_as_configured_and_logs_only_a_change() -> None:
    states = iter(['on', 'on', 'refused'])
    calls = []

    def factory(path: str, baud: int, low_latency: bool) -> _Port:
        calls.append((path, baud, low_latency))
        return _Port(next(states))

    timings, log = _Opens(), _Log()
    config = DeviceConfig(port='/dev/gx2', address=95, baud=115200, low_latency=False)
    opener = PortOpener(config, log, PortParts(factory, None, timings))
    for _ in range(3):
        opener.open_port()
    assert calls == [('/dev/gx2', 115200, False)] * 3
    assert timings.opens == 3
    assert log.lines == ['/dev/gx2: low-latency mode on', '/dev/gx2: low-latency mode refused']
    assert opener.low_latency_state == 'refused'


def test_port_opener_gives_every_reader_the_same_parts() -> None:
    def capture(data: bytes, when: float) -> None:
        pass

    timings, cancel = _Opens(), threading.Event()
    config = DeviceConfig(port='/dev/gx2', address=95, wireless=False)
    options = PortOpener(config, _Log(), PortParts(on_bytes=capture, timings=timings)) \
        .reader_options(cancel=cancel)
    assert (options.wireless, options.on_bytes, options.timings, options.cancel) == (
        False, capture, timings, cancel)
    assert options.observer is None and options.thread_policy == config.thread_policy


def test_quiet_observer_notes_nothing() -> None:
    quiet = QuietObserver()
    assert quiet.opened() is None and quiet.read(3, 1.0) is None
    assert quiet.published(object(), 2.0) is None
