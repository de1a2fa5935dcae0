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
Does the node always end? SIGINT or SIGTERM at a random moment of every phase, thousands of times.

The trials are ``harness/shutdown_trials.py``'s: the plain node before its
port exists, during the dialogue, right after the first record, during a
reconnect after an unplug, during a gyro bias capture, with two sensors on
one base station; the managed node unconfigured and during each transition.
Each node is forked from a server that imported the driver once
(``harness/node_forks.py``: a start costs milliseconds instead of an
interpreter's start), several side by side, each in a ROS domain of its own;
the simulated sensors run in this process. Target: 0 hangs, 0 forced kills,
every exit within the node's 3 s deadline and with code 0. Reported, never
judged: the table says what happened.

    python benchmarks/shutdown.py --runs 2000 --slots 4
"""

import argparse
import statistics
import sys

from bench_common import emit, machine_table, RunNote
from harness.processes import isolate_ros_domain
from harness.shutdown_trials import Outcome, run_trials, Tally

from i3dmgx2_driver.lifetime import SHUTDOWN_DEADLINE


def _counts(outcomes: list[Outcome]) -> tuple[int, int, int]:
    """Count the exits with code 0, by the signal itself (before the handlers), other codes."""
    ended = [o for o in outcomes if not o.hung]
    zero = sum(o.code == 0 for o in ended)
    by_signal = sum(o.before_handlers for o in ended)
    return zero, by_signal, len(ended) - zero - by_signal


def _table(tally: Tally) -> str:
    lines = ['| phase | runs | SIGINT / SIGTERM | hangs | forced kills '
             '| exit 0 / by the signal / other | past 3 s | exit p50 / max (s) |',
             '|---|---|---|---|---|---|---|---|']
    for phase, outcomes in sorted(tally.by_phase().items()):
        ended = [o.seconds for o in outcomes if not o.hung]
        sigint = sum(o.signal == 'SIGINT' for o in outcomes)
        zero, by_signal, other = _counts(outcomes)
        lines.append(
            f'| {phase} | {len(outcomes)} | {sigint} / {len(outcomes) - sigint} '
            f'| {sum(o.hung for o in outcomes)} | {sum(o.killed for o in outcomes)} '
            f'| {zero} / {by_signal} / {other} '
            f'| {sum(s > SHUTDOWN_DEADLINE for s in ended)} '
            f'| {statistics.median(ended) if ended else 0.0:.2f} / '
            f'{max(ended, default=0.0):.2f} |')
    summary = tally.summary()
    zero, by_signal, other = _counts(tally.ran())
    lines.append(f'| **all** | **{summary["runs"]}** | | **{summary["hangs"]}** '
                 f'| **{summary["forced kills"]}** | {zero} / {by_signal} / **{other}** '
                 f'| **{summary["past the deadline"]}** '
                 f'| max **{summary["slowest exit"]:.2f}** |')
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the trials; print the table with the machine."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--runs', type=int, default=2000, help='trials in all (default 2000)')
    parser.add_argument('--slots', type=int, default=4, help='nodes side by side (default 4)')
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args(argv)
    isolate_ros_domain()
    note = RunNote('shutdown.py', argv)
    failures: list[Outcome] = []

    def progress(done: int, outcome: Outcome) -> None:
        if not outcome.clean and not outcome.setup_error:
            failures.append(outcome)
            print(f'[{done}] {outcome.phase} {outcome.signal}: code {outcome.code}, '
                  f'{outcome.seconds:.2f} s, hung {outcome.hung}, killed {outcome.killed}\n'
                  f'{outcome.log[-6000:]}', file=sys.stderr, flush=True)
        elif done % 100 == 0:
            print(f'[{done}/{args.runs}]', file=sys.stderr, flush=True)

    tally = run_trials(args.runs, slots=args.slots, seed=args.seed, progress=progress)
    summary = tally.summary()
    notes = [
        note.text(f'{summary["runs"]} trials ({summary["not reached"]} more did not reach '
                  f'their phase), {args.slots} side by side; '),
        f'Exit codes: {summary["exit codes"]}. An exit is the time from the signal to the '
        f'end of the process (its pidfd readable in the fork server).',
        'A hang: not ended 10 s after the signal (then SIGABRT: its stacks; a forced kill: '
        'SIGKILL after that). "By the signal": the node ended by the signal\'s own action, '
        'sent before its handlers were installed (the first milliseconds of a forked start).',
    ]
    text = '\n'.join(['## Shutdown at random moments', '', machine_table(), '',
                      _table(tally), '', notes[0], *[f'- {n}' for n in notes[1:]]]) + '\n'
    emit(text, 'shutdown.md')
    return 0


if __name__ == '__main__':
    sys.exit(main())
