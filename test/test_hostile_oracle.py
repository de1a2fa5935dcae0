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
The hostile station's oracle: which packets the node must publish.

Kept from the node fuzz's one finding in 30 minutes ("1 intact packets of a
calm stretch not published after Attack(phase='identity',
mode='stop_mid_packet')"). The attack held the reply to the node's
resume (its serial-number read) back; the node gave the resume up and ran
its full dialogue; the held bytes, let go at once, overfilled the pty (a
0xCC packet cut by the station itself) and their 0xCC records, published,
started the fuzz's calm stretch while the dialogue still polled 0xC2. The
0xC2 reply, a reply the node never publishes, was counted as a sample it
must publish. The bytes are the last the node was given before it. The
parser finds every complete packet in them: no driver defect.
"""

from harness.hostile import HostileStation
from i3dmgx2_driver.codec import SensorStreamParser
from i3dmgx2_driver.codec.framing import DataPacket, HEADER_SIZE
from i3dmgx2_driver.codec.layouts import ACCEL_ANG_RATE
from i3dmgx2_driver.codec.records import AccelAngRate, AccelAngRateMagOrientation
from i3dmgx2_driver.codec.streams import DEFAULT
import pytest

ADDRESS = 95
#: The tail of the finding's bytes: a packet's tail, the 0xEA reply of the resume, a
#: whole 0xCC packet, a 0xCC packet the full pty cut after 43 bytes, the ACK of the
#: dialogue's 0xC2 poll and its reply (the packet not published).
FINDING = bytes.fromhex(
    '3e6531a5bd621cc03ee11ce03f7f9c1c3ca9fc17bd517a56bcd3a72c3f7e9b98bdcea1843d47c371'
    '3dd105a73f7e5b618b0d2458de9f239caa0700005f1300ea0133303935202020202020202020202020'
    'e39e03b5aa0700005f4e00cc3d529d233dce3d56bf7e4cd33da20f9c3c122de03da24cc33e69e1ac'
    'bd66fbd33ee2e7723f7f9bce3caacff2bd51af2ebcd479ee3f7e9c23bdce691f3d47f01b3dd0d079'
    '3f7e5bed8b0d8459e49f27d8aa0700005f4e00cc3d522bff3dceb137bf7e60b53da609593c26fb26'
    '3da43c6d3e671f47bd69c59c3ee2aaaa0700005f1e00c23d9d850abe0cba8fbf7cabf73c236005bd'
    '277ca13cbd608f8dffac12edae0e96')
WHOLE_CC = FINDING[85:173]
POLL_REPLY = FINDING[216:]


def test_the_finding_bytes_hold_every_complete_packet_for_the_parser():
    parser = SensorStreamParser(address=ADDRESS)
    records = [e.record for e in parser.feed(FINDING) if isinstance(e, DataPacket)]
    # The 0xC2 reply waits behind the cut packet until bytes enough to refute it come.
    assert [type(r) for r in records[-1:]] == [AccelAngRateMagOrientation]
    more = [e.record for e in parser.feed(WHOLE_CC) if isinstance(e, DataPacket)]
    assert [type(r) for r in more] == [AccelAngRate, AccelAngRateMagOrientation]
    assert len(POLL_REPLY) == 40 and POLL_REPLY[HEADER_SIZE] == ACCEL_ANG_RATE


@pytest.fixture
def station():
    """Return a station with its pty (hence the tests' slow mark) and no upstream."""
    # The station is fed by hand; nothing reads the node's end of its pty.
    made = HostileStation('/nonexistent/upstream', ADDRESS, seed=1)
    yield made
    made.port.pull_out()
    made.port.remove()


@pytest.mark.slow
def test_a_polled_reply_is_allowed_but_not_owed(station):
    station._piece(POLL_REPLY, 1.0)
    station._piece(WHOLE_CC, 2.0)
    assert DEFAULT.code == WHOLE_CC[HEADER_SIZE]
    assert [t for t, _ in station.oracle.intact] == [2.0]
    assert len(station.oracle.intact_keys) == 2  # both may be published


@pytest.mark.slow
def test_a_packet_the_full_pty_cut_is_not_owed(station, monkeypatch):
    # The pty takes 43 bytes of it, as in the finding. Filling the real pty does not
    # pin that down: the kernel frees room in its buffers on its own schedule, and on
    # a CI machine the whole packet went in after the fill (a test that failed there
    # on timing, not on the oracle).
    write = station.port.write
    monkeypatch.setattr(station.port, 'write', lambda data: write(data[:43]))
    station._piece(WHOLE_CC, 1.0)
    assert station.oracle.intact == []
    assert station.bytes_out == 43  # what it took is still given, and checked
