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
The soak and fault campaign: the real node against a simulator that misbehaves.

The node runs as its own process (``harness/instrumented_node.py``: the
real node, with its counters written to a file) on a simulated base station
whose faults change at random all through the run (``fault_driver.py``):
line noise (garbage, with and without 0xAA bytes), corrupted checksums and
lengths, packets from a foreign sensor, radio drops and lost commands,
jitter, stalls short and long, unplug and replug, sensor power cycles
(streaming again at once, or not), the sensor ignoring its first request to
stream or wanting a polled request first. A real rclpy subscriber (reliable,
deep history) records what the node publishes. Afterwards every published
message is matched, by its exact values, to the simulator's ground truth,
and the node's counters are reconciled with what the simulator wrote
(``campaign_verdict.py``: the rules, the checks and the report).

Here: the pieces a faulted run stands on, the truth kept compact with the
values the node would publish for it, the subscriber, the node's counters.
The node processes and the run itself are the long soak's (``long_soak.py``;
the campaign is one of its legs, ``run_campaign``).
"""

from collections.abc import Callable
import json
import struct
import threading
import time

from harness.campaign_verdict import Sent
from harness.processes import Listener, NodeProcess
from i3dmgx2_driver.codec.commands import decode_record, encode_record
from i3dmgx2_driver.codec.errors import CodecError
from i3dmgx2_driver.codec.framing import HEADER_SIZE
from i3dmgx2_driver.codec.layouts import LAYOUTS
from i3dmgx2_driver.codec.orientation import ENU
from i3dmgx2_driver.codec.streams import STREAMS
from i3dmgx2_driver.ros.cdr import StampedDoubles
from i3dmgx2_driver.ros.conversions import MessageFactory, MessageSettings
from i3dmgx2_driver.simulator import PtySimulator
from sensor_msgs.msg import Imu

#: A published message's acceleration and angular velocity, packed: how a message is
#: matched to its record, by its exact values (a run writes 10^5 records and more).
VALUES = struct.Struct('<6d')
#: Its orientation, packed.
QUATERNION = struct.Struct('<4d')
#: The Imu message of frame imu_link, as the node's packer writes it (ros/conversions.py).
_IMU = StampedDoubles('imu_link', '4d72s3d72s3d72s').struct
#: The bytes that can each become a spurious parser event (ACK/start of packet, NACK).
_MARKS = (0xAA, 0x21)


# -- the truth, and the values the node publishes for it ---------------------------------------

def message_key(msg: Imu) -> bytes:
    """Pack a received message's acceleration and angular velocity, as the truth's keys are."""
    la, av = msg.linear_acceleration, msg.angular_velocity
    return VALUES.pack(la.x, la.y, la.z, av.x, av.y, av.z)


#: For each stream's record type: the node's own message factory (ENU), the record's
#: size in a packet and its command byte, so that every stream's published values are
#: computed as the node does.
_FACTORIES = {
    stream.record_type: (MessageFactory(MessageSettings('imu_link', ENU, stream=stream)),
                         LAYOUTS[stream.code].record_size, stream.code)
    for stream in STREAMS}


def imu_values(record) -> tuple[bytes, bytes] | None:
    """Return the packed (acceleration, rate) and orientation the node publishes, or None."""
    made = _FACTORIES.get(type(record))
    if made is None:
        return None
    factory, _, code = made
    values = LAYOUTS[code].reply_struct.unpack_from(encode_record(record), 1)
    # The Imu's bytes as the node packs them: orientation 5-8, rate 10-12, acceleration 14-16.
    imu = _IMU.unpack(factory.imu_cdr(values, 0, 0))
    return VALUES.pack(*imu[14:17], *imu[10:13]), QUATERNION.pack(*imu[5:9])


def compact(entry) -> Sent:
    """Keep the parts of a SentRecord the checks need."""
    record = entry.record
    key = bad_key = quat = code = None
    values = imu_values(record)
    if values is not None:
        key, quat = values
        code = _FACTORIES[type(record)][2]
        if entry.fault == 'checksum':
            size = _FACTORIES[type(record)][1]
            try:
                bad = imu_values(decode_record(entry.packet[HEADER_SIZE:HEADER_SIZE + size]))
                bad_key = bad[0] if bad is not None else None
            except CodecError:
                bad_key = None
    marks = sum(1 for byte in entry.packet if byte in _MARKS)
    return Sent(entry.index, entry.write_time, entry.valid, entry.fault, entry.address,
                entry.source, key, bad_key, quat, entry.timer, entry.sample_time, marks,
                len(entry.packet), code)


class TruthCollector(threading.Thread):
    """
    Move the simulator's truth into compact form as it is produced.

    Twice a second, so that the simulator's bounded truth never overflows.
    """

    def __init__(self, sim: PtySimulator) -> None:
        super().__init__(name='soak-truth', daemon=True)
        self.sim = sim
        self.entries: list[Sent] = []
        self.missed = 0
        self._next = 0
        self._halt = threading.Event()
        self._lock = threading.Lock()

    def collect(self) -> None:
        """Take whatever is new in the simulator's truth."""
        with self._lock:
            fresh = [e for e in self.sim.truth if e.index >= self._next]
            for entry in fresh:
                if entry.index != self._next:
                    self.missed += entry.index - self._next
                self.entries.append(compact(entry))
                self._next = entry.index + 1

    def take(self) -> tuple[list[Sent], int]:
        """Return the entries and the missed count so far, and start both afresh (a leg's)."""
        self.collect()
        with self._lock:
            entries, self.entries = self.entries, []
            missed, self.missed = self.missed, 0
        return entries, missed

    def run(self) -> None:
        """Collect twice a second until stopped."""
        while not self._halt.wait(0.5):
            self.collect()

    def stop(self) -> None:
        """Stop and take the rest."""
        self._halt.set()
        self.join(5.0)
        self.collect()


# -- what the node published, as a subscriber of another process received it ------------------

class Subscriber(Listener):
    """
    The harness's rclpy listener, keeping what the checks need of each Imu message.

    Its exact values (packed as the truth's keys are), its stamp, its
    orientation and its arrival time.
    """

    def __init__(self, depth: int = 10000, topics: tuple[str, ...] = ('imu/raw_data',)) -> None:
        self.rows: list[tuple[bytes, int, bytes, float]] = []
        super().__init__(dict.fromkeys(topics, Imu), depth=depth)

    def _store(self, topic: str, msg: Imu) -> None:
        o = msg.orientation
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self.rows.append((message_key(msg), stamp, QUATERNION.pack(o.x, o.y, o.z, o.w),
                          time.time()))

    def take(self) -> list[tuple[bytes, int, bytes, float]]:
        """Return the messages received so far, and start afresh (a leg's)."""
        rows, self.rows = self.rows, []
        return rows

    def wait_count(self, count: int, timeout: float) -> bool:
        """Wait until ``count`` messages have come; return whether they did."""
        deadline = time.monotonic() + timeout
        while len(self.rows) < count and time.monotonic() < deadline:
            time.sleep(0.05)
        return len(self.rows) >= count

    def wait_publisher(self, node: NodeProcess, topic: str, timeout: float = 60.0) -> None:
        """Wait until this subscriber's node knows the node's publisher of ``topic``."""
        deadline = time.monotonic() + timeout
        while self.node.count_publishers(topic) < 1:
            if node.proc.poll() is not None:
                raise RuntimeError(f'the node exited:\n{node.output()[-3000:]}')
            if time.monotonic() > deadline:
                raise RuntimeError(f'no publisher of {topic} within {timeout:g} s')
            time.sleep(0.1)


# -- the node's counters ---------------------------------------------------------------------

def read_counters(path: str, done: Callable[[dict], bool], timeout: float) -> dict:
    """
    Return the node's counters once ``done`` takes them; the last read after ``timeout`` s.

    The file is missing until the node first writes it, and is replaced
    whole at each write; a read that fails counts as empty.
    """
    deadline = time.monotonic() + timeout
    got: dict = {}
    while time.monotonic() < deadline:
        try:
            with open(path) as handle:
                got = json.load(handle)
        except (OSError, ValueError):
            got = {}
        if done(got):
            break
        time.sleep(0.1)
    return got
