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
Replay every bad-input fixture of test/fixtures/fuzz/ and check its exact outcome.

Each ``NAME.bin`` is a byte stream named after what is wrong in it (hand-made,
or kept from a fuzzing run of benchmarks/fuzz_parser.py); ``NAME.json`` says
which parser reads it and how (wireless or wired, address filter, a ping
expected, ``idle()`` at the end), why the outcome is what it is, and the
outcome: every event in order (a data or command packet as the offset and
size of its bytes in the file, decoded by the one-shot decoders to compare),
every counter, the bytes left held. The outcome must not depend on how the
stream is chunked, and every fixture must keep the fuzzer's properties.
"""

import json
from pathlib import Path

from harness.decoders import decode_command_packet, decode_data_packet, decode_wired_record
from harness.fuzz_checks import check_input, same
from i3dmgx2_driver.codec import (
    CommandStreamParser, RawCommand, RejectedPacket, SensorStreamParser,
)
from i3dmgx2_driver.codec.parser import ACK_EVENT, NACK_EVENT
from i3dmgx2_driver.codec.records import PingReply
from packets import packet_of
import pytest

FUZZ_DIR = Path(__file__).resolve().parent / 'fixtures' / 'fuzz'
CASES = sorted(path.stem for path in FUZZ_DIR.glob('*.bin'))
#: Chunk sizes to feed each fixture in (None: all at once).
CHUNKINGS = (None, 1, 2, 3, 7, 64)
#: The bad inputs every parser must be shown to handle, whatever the fuzzer finds.
HAND_MADE = {
    'truncated_packet', 'bad_checksum', 'bad_length', 'ack_then_packet', 'garbage_with_aa',
    'all_aa', 'huge_length_byte',
}


def load(name: str) -> tuple[bytes, dict]:
    """Return the bytes of a fixture and its expectations."""
    blob = (FUZZ_DIR / f'{name}.bin').read_bytes()
    spec = json.loads((FUZZ_DIR / f'{name}.json').read_text())
    return blob, spec


def expected_events(spec: dict, blob: bytes) -> list:
    """Build the expected events, decoding packets from their place in the file."""
    out = []
    for item in spec['events']:
        kind = item['type']
        piece = blob[item['at']:item['at'] + item['size']] if 'at' in item else b''
        if kind == 'data' and spec['wireless']:
            out.append(decode_data_packet(piece))
        elif kind == 'data':
            out.append(packet_of(None, decode_wired_record(piece), None, None))
        elif kind == 'ack':
            out.append(ACK_EVENT)
        elif kind == 'nack':
            out.append(NACK_EVENT)
        elif kind == 'ping':
            out.append(PingReply(item['ok']))
        elif kind == 'command_packet':
            out.append(decode_command_packet(piece))
        elif kind == 'raw':
            out.append(RawCommand(piece))
        elif kind == 'rejected':
            out.append(RejectedPacket(item['reason']))
        else:  # pragma: no cover - a typo in a fixture
            raise AssertionError(f'unknown event type {kind!r}')
    return out


def replay(spec: dict, blob: bytes, chunk: int | None) -> tuple[list, dict, int]:
    """Feed the fixture as its spec says; return events, counters and bytes held."""
    pieces = [blob] if chunk is None else [blob[i:i + chunk]
                                           for i in range(0, len(blob), chunk)]
    events = []
    if spec['parser'] == 'command':
        parser = CommandStreamParser(wireless=spec['wireless'])
        for piece in pieces:
            events += parser.feed(piece)
        return events, parser.stats.as_dict(), len(parser._buf)
    parser = SensorStreamParser(address=spec['address'], wireless=spec['wireless'])
    if spec['expect_ping']:
        parser.expect_ping()
    for piece in pieces:
        events += parser.feed(piece)
    if spec['idle_at_end']:
        events += parser.idle()
    return events, parser.stats.as_dict(), parser.pending


def test_fixtures_are_complete():
    """Every .bin has its .json (and the reverse), explained; the hand-made ones exist."""
    specs = {path.stem for path in FUZZ_DIR.glob('*.json')}
    assert set(CASES) == specs
    assert set(CASES) >= HAND_MADE
    for name in CASES:
        _, spec = load(name)
        assert spec['description'].strip(), name
        assert spec['parser'] in ('sensor', 'command'), name


@pytest.mark.parametrize('chunk', CHUNKINGS, ids=lambda c: f'chunk{c or "all"}')
@pytest.mark.parametrize('name', CASES)
def test_fixture_outcome_is_exact(name, chunk):
    blob, spec = load(name)
    events, stats, pending = replay(spec, blob, chunk)
    assert same(tuple(events), tuple(expected_events(spec, blob))), \
        f'{name}: {spec["description"]}\ngot {events}'
    assert stats == spec['stats'], f'{name}: {spec["description"]}'
    assert pending == spec['pending']


@pytest.mark.parametrize('name', CASES)
def test_fixture_keeps_the_fuzz_properties(name):
    blob, _ = load(name)
    check_input(blob)
