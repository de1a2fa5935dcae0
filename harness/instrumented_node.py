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
The real driver node, with its counters written to a JSON file for the soak campaign.

Runs the driver node as ``ros2 run`` does (``i3dmgx2_driver.ros.main.run``),
observed from outside, nothing of it replaced: a ROS timer that writes the
node's ``stats``, the parser counters summed over every connection
(``supervisor.status().parser``) to the file
named by ``$I3DMGX2_SOAK_STATS`` twice a second and once more after
shutdown; the serial port's class, wrapped in this process only
(:func:`observe_ports`), notes the time of every open, input flush and
close; and the record publisher's class, wrapped the same way
(:func:`observe_anchors`), notes every link up, when the node re-anchors
(its reader publishes every record from then on). They tell the campaign
when the node could read the port (records written outside those windows
may be lost legitimately). With ``$I3DMGX2_TIMINGS`` set it also records
the hot path's timings, as the node's own main does
(benchmarks/reconnect.py reads both files).
Nothing on the path of a sample is changed.

With ``--lifecycle`` (before ``--ros-args``) it runs the managed node the
same way: each configure makes a new core, and the file holds the counters
of the last one; an activate is noted as an
anchor once it returns (records are published from then on), a deactivate
as ``deactivate`` when it begins (they are not published from then on).

Usage: ``I3DMGX2_SOAK_STATS=out.json python -m harness.instrumented_node
[--lifecycle] --ros-args -p port:=... -p address:=...``.
"""

import collections
import json
import os
import sys
import threading
import time
from typing import Any

from i3dmgx2_driver import lifetime
from i3dmgx2_driver.device import hot_path
from i3dmgx2_driver.device.port import SerialPort
from i3dmgx2_driver.ros import main as node_main
from i3dmgx2_driver.ros.imu_node import ImuDriverNode
from i3dmgx2_driver.ros.lifecycle_node import LifecycleDriverNode
from i3dmgx2_driver.ros.record_publisher import RecordPublisher

#: Environment variable naming the JSON file the counters go to.
STATS_ENV = 'I3DMGX2_SOAK_STATS'
#: How often the counters are written while the node runs (s).
DUMP_PERIOD = 0.5

#: Environment variable that sets how many port events are kept (default EVENTS_KEPT).
EVENTS_ENV = 'I3DMGX2_SOAK_EVENTS'
#: Port events kept (the newest): far more than a leg makes, so that an hour's run in
#: one process holds a bounded list rather than one that grows with every fault. A run
#: that reads no events (benchmarks/memory_curve.py) sets 0 in EVENTS_ENV: the list and
#: its copy in every write are the rig's memory, not the node's.
EVENTS_KEPT = int(os.environ.get(EVENTS_ENV, '4096'))

_events: collections.deque[tuple[str, float, int]] = collections.deque(maxlen=EVENTS_KEPT)
_events_lock = threading.Lock()
_connection = [0]


def _note(kind: str, at: float | None = None) -> None:
    with _events_lock:
        _events.append((kind, time.time() if at is None else at, _connection[0]))


def observe_ports() -> None:
    """
    Note every serial port's open, input flush and close, in this process.

    Wraps the methods of the package's SerialPort class itself: the node
    opens its ports as it always does, and this process, the rig's, runs
    nothing else that opens one.
    """
    init, flush_input, close = SerialPort.__init__, SerialPort.flush_input, SerialPort.close

    def opened(port: SerialPort, *args: Any, **kwargs: Any) -> None:
        init(port, *args, **kwargs)  # noted once it succeeded: a connection begins
        with _events_lock:
            _connection[0] += 1
        _note('open')

    def flushed(port: SerialPort) -> None:
        # Noted when it began: what was written before is gone; what was written
        # from then on may wait in the queue and be read after the next anchor
        # (campaign_verdict.Windows).
        began = time.time()
        flush_input(port)
        _note('flush', began)

    def closed(port: SerialPort) -> None:
        _note('close')  # before: the reader has stopped by now
        close(port)

    SerialPort.__init__, SerialPort.flush_input, SerialPort.close = opened, flushed, closed


class ObservedLifecycleNode(LifecycleDriverNode):
    """The managed node, its activations and deactivations noted, its last core kept."""

    def __init__(self, **kwargs) -> None:
        #: The core of the last configure (kept after cleanup, for the counters).
        self.last_core = None
        super().__init__(**kwargs)

    def on_configure(self, state):  # noqa: ANN001, ANN201 - rclpy's signature
        """Configure; keep the core made."""
        result = super().on_configure(state)
        if self.core is not None:
            self.last_core = self.core
        return result

    def on_activate(self, state):  # noqa: ANN001, ANN201
        """Activate; note the anchor once records are published."""
        result = super().on_activate(state)
        _note('anchor')
        return result

    def on_deactivate(self, state):  # noqa: ANN001, ANN201
        """Note that publishing ends, then deactivate."""
        _note('deactivate')
        return super().on_deactivate(state)


def _snapshot(node, final: bool) -> dict:
    core = node.core if node.core is not None else getattr(node, 'last_core', None)
    if core is None:
        return {'time': time.time(), 'final': final}
    stats = core.records.stats
    with _events_lock:
        events = list(_events)
    return {
        'time': time.time(),
        'final': final,
        'stats': {name: getattr(stats, name) for name in (
            'published', 'unpublished', 'lost', 'device_resets')},
        'parser': core.supervisor.status().parser,
        'port_events': events,
    }


def _write(path: str, document: dict) -> None:
    """
    Write ``document`` as JSON to ``path`` whole (a reader never sees half of it).

    ``json.dumps``, not ``json.dump``: to a file, json encodes with closures of
    its own that refer to each other, a reference cycle at every write, which
    twice a second kept the node's collector busy and its old generation full of
    the rig's garbage (3,800 objects a minute, most of the CPython blocks the
    memory curve saw come and go); the C encoder behind ``dumps`` makes none.
    """
    temporary = f'{path}.tmp'
    text = json.dumps(document)
    with open(temporary, 'w') as handle:
        handle.write(text)
    os.replace(temporary, path)


def observe_anchors() -> None:
    """
    Note every link up ('anchor'), in this process: the node re-anchors its clock there.

    Wraps the record publisher's class's ``link_changed``, which every
    supervisor calls before a new link's first record reaches it: every
    record is published from then on.
    """
    link_changed = RecordPublisher.link_changed

    def anchored(publisher: RecordPublisher) -> None:
        link_changed(publisher)
        _note('anchor')

    RecordPublisher.link_changed = anchored


def main() -> int:
    """Run the driver node, observed; write its counters as it runs and once at the end."""
    # As the node's own main: a benchmark stopped or killed takes its node with it
    # (one outlived a memory curve stopped with SIGTERM, streaming on until found).
    lifetime.die_with_parent()
    path = os.environ.get(STATS_ENV)
    if not path:
        print(f'{STATS_ENV} must name the file for the counters', file=sys.stderr)
        return 2
    made: list[ImuDriverNode] = []
    arguments = sys.argv[1:sys.argv.index('--ros-args')] if '--ros-args' in sys.argv \
        else sys.argv[1:]
    kind = ObservedLifecycleNode if '--lifecycle' in arguments else ImuDriverNode

    observe_ports()
    observe_anchors()
    recorder, timings_path = hot_path.recorder_from_environment()

    def make_node() -> ImuDriverNode:
        node = kind()
        node.create_timer(DUMP_PERIOD, lambda: _write(path, _snapshot(node, False)))
        made.append(node)
        return node

    code = node_main.run(make_node)
    if made:
        _write(path, _snapshot(made[0], True))
    if recorder is not None:
        lifetime.cancel_deadline()  # writing the timings is no part of the stop
        recorder.save(timings_path)
    return code


if __name__ == '__main__':
    sys.exit(main())
