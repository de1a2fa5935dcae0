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
The hostile station's pieces on their own: the attacks' bytes and the oracle's books.

Fast and without a pty: what ``harness/hostile.py``'s ``PacketMutator`` sends
must be what each mode says (a foreign packet valid but from elsewhere, a
stopped packet given back whole), and its ``PublishOracle`` must allow
exactly what a parser finds from the station's address and owe only whole
records of the node's stream.
"""

import random

from harness.campaign import imu_values
from harness.hostile import PacketMutator, PublishOracle, reseal
from i3dmgx2_driver.codec import SensorStreamParser
from i3dmgx2_driver.codec.framing import DataPacket, HEADER_SIZE
from i3dmgx2_driver.codec.layouts import ACCEL_ANG_RATE
import pytest

ADDRESS = 95
#: A 0xC2 record (acceleration, angular rate) from address 95, as the wireless station frames it.
PACKET = bytes.fromhex('aa0700005f1e00c23d9d850abe0cba8fbf7cabf73c236005bd277ca13cbd608f8d'
                       'ffac12edae0e96')


def packets(data: bytes, address: int | None = None) -> list[DataPacket]:
    parser = SensorStreamParser(address=address)
    return [e for e in parser.feed(data) if isinstance(e, DataPacket)]


def test_the_packet_is_a_valid_record_of_the_station():
    found = packets(PACKET, ADDRESS)
    assert len(found) == 1 and found[0].address == ADDRESS
    assert PACKET[HEADER_SIZE] == ACCEL_ANG_RATE
    assert reseal(bytearray(PACKET)) == PACKET


@pytest.mark.parametrize('seed', range(20))
def test_a_foreign_packet_is_valid_from_another_address(seed):
    out = PacketMutator(random.Random(seed)).mutate(PACKET, True, 'foreign')
    found = packets(out)
    assert len(found) == 1 and found[0].address != ADDRESS
    assert found[0].record == packets(PACKET)[0].record
    assert packets(out, ADDRESS) == []


@pytest.mark.parametrize('seed', range(20))
def test_a_stopped_packet_is_given_back_whole_in_order(seed):
    mutator = PacketMutator(random.Random(seed))
    head = mutator.mutate(PACKET, True, 'stop_mid_packet')
    assert 1 <= len(head) < len(PACKET)
    # Everything after the cut waits, the next pieces too, until the attack ends.
    assert mutator.mutate(b'\x21', False, 'stop_mid_packet') == b''
    assert mutator.mutate(PACKET, True, 'stop_mid_packet') == b''
    assert head + b''.join(mutator.release()) == PACKET + b'\x21' + PACKET
    assert mutator.release() == []


def test_unsolicited_appends_the_last_reply_and_unknown_modes_pass_through():
    mutator = PacketMutator(random.Random(1))
    assert mutator.mutate(PACKET, True, 'unsolicited') == PACKET
    mutator.remember_reply(PACKET)
    assert mutator.mutate(PACKET, True, 'unsolicited') == PACKET + PACKET
    assert mutator.mutate(PACKET, True, 'no such mode') == PACKET


def test_the_oracle_allows_what_a_parser_finds_from_the_station_only():
    key = imu_values(packets(PACKET)[0].record)[0]
    oracle = PublishOracle(ADDRESS, ACCEL_ANG_RATE)
    foreign = PacketMutator(random.Random(3)).mutate(PACKET, True, 'foreign')
    oracle.given(foreign)
    assert oracle.allowed == set()
    oracle.given(PACKET[:20])
    assert oracle.allowed == set()
    oracle.given(PACKET[20:])
    assert oracle.allowed == {key}


def test_the_oracle_owes_only_whole_records_of_the_stream():
    key = imu_values(packets(PACKET)[0].record)[0]
    other_stream = PublishOracle(ADDRESS, ACCEL_ANG_RATE + 1)
    other_stream.owed(PACKET, key, len(PACKET), 1.0)
    assert other_stream.intact == []
    oracle = PublishOracle(ADDRESS, ACCEL_ANG_RATE)
    oracle.owed(PACKET, key, len(PACKET) - 1, 1.0)
    assert oracle.intact == []
    oracle.owed(PACKET, key, len(PACKET), 2.0)
    assert oracle.intact == [(2.0, key)]
    oracle.attacked(key, 'bitflip')
    assert oracle.attacked_keys == {key: 'bitflip'}
