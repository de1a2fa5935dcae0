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
The line observer: what it finds in real bytes of either framing, and when.

Packets are built by the codec's encoders, so the observer reads exactly what
a base station or a wired sensor sends; time is passed in, never read.
"""

import random

from i3dmgx2_driver.codec import encode_data_packet, encode_record, encode_wired_record
from i3dmgx2_driver.codec.records import AccelAngRate
from i3dmgx2_driver.device import observer as obs
from i3dmgx2_driver.device.observer import Finding, judge, LineObserver, Window
import pytest

PORT = '/dev/ttyUSB0'
RECORD = encode_record(AccelAngRate((0.0, 0.0, -1.0), (0.01, 0.02, 0.03), 1234))


def packet(address):
    """One wireless data packet from ``address``."""
    return encode_data_packet(address, RECORD, 230, 170)


def run(observer, chunks, start=100.0, step=0.1, epoch=0.0):
    """Feed ``chunks`` one per ``step`` s; return every finding."""
    found = []
    for i, chunk in enumerate(chunks):
        finding = observer.feed(chunk, start + i * step, epoch)
        if finding is not None:
            found.append(finding)
    return found


def observer(address=12, wireless=True, baud=115200):
    reported = []
    return LineObserver(PORT, address, wireless, baud, reported.append), reported


def test_packets_of_another_address_are_named_with_the_fix():
    watcher, reported = observer(address=12)
    found = run(watcher, [packet(95) * 10] * 12)
    assert found and found == reported
    assert found[0] == Finding(obs.ADDRESS, (
        'packets arrive from node 95 (110 in 1.0 s), none from node 12: is that your '
        'sensor? If so, set -p address:=95'))


def test_nothing_is_said_before_the_window_is_long_enough():
    watcher, reported = observer(address=12)
    assert run(watcher, [packet(95) * 10] * 10) == []  # 0.9 s
    assert reported == []


def test_several_addresses_are_named_busiest_first():
    watcher, _ = observer(address=12)
    found = run(watcher, [packet(95) * 3 + packet(96)] * 12)
    assert found[0].message.startswith(
        'packets arrive from node 95 (33 in 1.0 s), node 96 (11), none from node 12')


def test_wired_records_on_a_wireless_link_name_the_framing():
    watcher, _ = observer(address=95, wireless=True)
    found = run(watcher, [encode_wired_record(RECORD) * 5] * 12)
    assert found[0] == Finding(obs.FRAMING, (
        f'{PORT} sends wired (unframed) records (55 in 1.0 s), not wireless packets: is a '
        f'wired sensor on this port? Then set -p wireless:=false'))


def test_wireless_packets_on_a_wired_link_name_the_framing_and_the_address():
    watcher, _ = observer(address=12, wireless=False)
    found = run(watcher, [packet(95) * 10] * 12)
    assert found[0] == Finding(obs.FRAMING, (
        f'{PORT} sends wireless packets from node 95 (110 in 1.0 s), not wired records: is a '
        f'wireless base station on this port? Then set -p wireless:=true and -p address:=95'))
    watcher, _ = observer(address=95, wireless=False)
    found = run(watcher, [packet(95) * 10] * 12)
    assert found[0].message.endswith('Then set -p wireless:=true')


@pytest.mark.parametrize('wireless', [True, False])
def test_bytes_that_are_no_packet_point_at_the_baud_rate(wireless):
    rng = random.Random(7)
    noise = [bytes(rng.getrandbits(8) for _ in range(100)) for _ in range(22)]
    watcher, _ = observer(address=95, wireless=wireless, baud=57600)
    found = run(watcher, noise)
    assert [f.kind for f in found] == [obs.NOISE] * len(found) and found
    assert found[0].message == (
        f'2100 bytes in 2.0 s from {PORT}, and not one valid 3DM-GX2 packet among them: '
        f'check the baud rate (read at 57600 baud here, -p baud; the 3DM-GX2 ships set to '
        f'115200) and that the device on this port is a 3DM-GX2')


@pytest.mark.parametrize('wireless, fix', [(True, '-p wireless:=false'),
                                           (False, '-p wireless:=true')])
def test_silence_is_said_after_three_seconds_with_the_other_framing(wireless, fix):
    watcher, _ = observer(address=95, wireless=wireless)
    assert run(watcher, [b''] * 30) == []  # 2.9 s
    found = run(watcher, [b''] * 2, start=103.0)
    assert found[0].kind == obs.SILENCE
    assert found[0].message.startswith(f'not one byte from {PORT} in 3.0 s')
    assert fix in found[0].message


def test_acks_alone_are_neither_noise_nor_silence():
    # A base station whose sensor is off still ACKs every command.
    watcher, _ = observer(address=95)
    assert run(watcher, [b'\xaa'] * 50) == []


def test_a_packet_of_ours_starts_a_new_window():
    watcher, _ = observer(address=12)
    assert run(watcher, [packet(95) * 10] * 8) == []
    # Our packet arrived (the link's epoch moved): the 0.8 s seen so far are forgotten.
    assert run(watcher, [packet(95) * 10] * 8, start=100.8, epoch=100.75) == []
    assert run(watcher, [packet(95) * 10] * 4, start=101.6, epoch=100.75)


def test_judge_is_quiet_on_a_short_or_empty_window():
    assert judge(Window(0.5, 0, {}, 0, 0), PORT, 95, True, 115200) is None
    assert judge(Window(2.0, 0, {}, 0, 0), PORT, 95, True, 115200) is None
    assert judge(Window(5.0, 900, {95: 3}, 0, 0), PORT, 95, True, 115200) is None
    assert judge(Window(5.0, 900, {}, 1, 0), PORT, 95, True, 115200) is None  # one is chance


def test_a_resumed_observer_starts_a_fresh_window():
    watcher, _ = observer(address=95)
    assert run(watcher, [b''] * 25) == []  # 2.4 s of silence
    watcher.pause()
    assert not watcher.active
    watcher.resume()
    # The window restarts: 2.4 s more of silence is still no finding.
    assert run(watcher, [b''] * 25, start=110.0) == []
    assert watcher.last_finding is None
    assert run(watcher, [b''] * 7, start=112.5)[0].kind == obs.SILENCE
    assert watcher.last_finding.kind == obs.SILENCE
