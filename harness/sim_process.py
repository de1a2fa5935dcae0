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
The simulated device in a process of its own, with its ground truth saved at the end.

Benchmarks run the simulator apart from the node, as a real device is: the
two then never compete for one interpreter lock, and what is measured is the
node's own delay. Prints ``port: PATH`` once the pty exists. SIGUSR1 silences
the radio for good (no more packets: the node can drain what was written, so
that every written packet can be accounted for). On SIGTERM, SIGINT or end of
standard input it stops and writes, as JSON, every data packet it produced
(timer, sample time, write time, valid, source) and its counters.

Usage: ``python -m harness.sim_process --config '{"rate_hz": 1000}' --truth
OUT.json``; started by ``harness.processes.SimProcess``. The config keys are
SimulatorConfig fields, plus ``faults`` (a dict of FaultConfig fields).
"""

import argparse
import json
import signal
import sys
import threading
from typing import Any

from i3dmgx2_driver.lifetime import StopSignal


def build_config(spec: dict) -> Any:
    """Turn a JSON dict into a SimulatorConfig."""
    from i3dmgx2_driver.simulator import FaultConfig, SimulatorConfig

    spec = dict(spec)
    return SimulatorConfig(faults=FaultConfig(**spec.pop('faults', {})), **spec)


def dump_truth(sim: Any, path: str) -> None:
    """Write the ground truth and the counters as one JSON document."""
    rows = [[entry.timer, entry.sample_time, entry.write_time, entry.valid, entry.source]
            for entry in sim.truth]
    document = {'truth': rows, 'stats': sim.stats.as_dict()}
    with open(path, 'w') as handle:
        json.dump(document, handle)


def main(argv: list[str] | None = None) -> int:
    """Run the simulator until told to stop; then save what it did."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--config', default='{}', help='SimulatorConfig fields as JSON')
    parser.add_argument('--truth', required=True, help='where to write the ground truth')
    args = parser.parse_args(argv)
    # Not threading.Events: a signal handler may not take a lock (i3dmgx2_driver/lifetime.py).
    stop = StopSignal().install((signal.SIGINT, signal.SIGTERM))
    silence = StopSignal().install((signal.SIGUSR1,))
    silent = False

    def watch_stdin() -> None:
        sys.stdin.read()  # returns at end of input: the benchmark went away
        stop.set()

    threading.Thread(target=watch_stdin, daemon=True).start()
    config = build_config(json.loads(args.config))
    from i3dmgx2_driver.simulator import PtySimulator

    sim = PtySimulator(config)
    sim.start()
    try:
        print(f'port: {sim.port}', flush=True)
        while not stop.wait(0.05):
            if silence.is_set() and not silent:
                silent = True
                sim.stall(1e9)
                print('silent', flush=True)
    finally:
        sim.stop()
        dump_truth(sim, args.truth)
    return 0


if __name__ == '__main__':
    sys.exit(main())
