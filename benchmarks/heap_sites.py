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
Issue #31: where the CPython blocks a node keeps were allocated, against the faults it met.

Reads what ``memory_curve.py --tracemalloc DIR`` leaves in ``DIR``: the
node's own tracemalloc snapshots (``NNNN.tracemalloc`` and ``NNNN.json``,
written by ``harness/instrumented_node.py`` every minute) and
``faults.csv`` (when each row of the curve was taken, and the faults met
by then). Each live block is put in one of three groups by its traceback:

- ``type cache``: allocated in rclpy's ``Publisher.publish``: the attribute
  names the generated message code looks up by C string, which CPython's
  type method cache keeps (4,096 entries at most; docs/soak.md);
- ``rig``: allocated by the instrumented node's own code (``harness/``):
  its list of port events and its writes;
- ``node``: everything else (the driver, rclpy, the standard library).

For each group it prints the blocks alive in each snapshot, from
``--first`` on (the warm-up left out) to the last taken while the node ran,
and the least-squares slope in blocks per fault; then the ``--top`` sites
of the ``node`` group whose count grew most between those snapshots, with
their slopes and tracebacks. tracemalloc's and importlib's frames are left
out. A site that keeps something of every fault shows as a slope that
stays above zero run after run; a cache that fills, as one that falls off.

Prints numbers; passes or fails nothing.
"""

import argparse
import bisect
import collections
import glob
import json
import os
import statistics
import tracemalloc

import bench_common  # noqa: F401 - puts the repository on the path

#: The groups, in the order printed.
GROUPS = ('type cache', 'rig', 'node')
#: Frames that say nothing of who keeps a block.
IGNORED = ('<frozen importlib._bootstrap>', '<frozen importlib._bootstrap_external>',
           tracemalloc.__file__, '<unknown>')


def group(filenames: tuple[str, ...]) -> str:
    """Return a traceback's group from its frames' file names (oldest first)."""
    if filenames and filenames[-1].endswith(os.path.join('rclpy', 'publisher.py')):
        return 'type cache'
    if any(os.sep + 'harness' + os.sep in name for name in filenames):
        return 'rig'
    return 'node'


def faults_at(times: list[float], faults: list[int], when: float) -> float:
    """Return the faults met at ``when``, interpolated between the curve's rows."""
    index = bisect.bisect_left(times, when)
    if index == 0:
        return float(faults[0])
    if index == len(times):
        return float(faults[-1])
    t0, t1 = times[index - 1], times[index]
    f0, f1 = faults[index - 1], faults[index]
    return f0 + (f1 - f0) * (when - t0) / (t1 - t0)


def slope(xs: list[float], ys: list[float]) -> float:
    """Least-squares slope of ys on xs (0 when xs do not vary)."""
    mx, my = statistics.fmean(xs), statistics.fmean(ys)
    sxx = sum((x - mx) ** 2 for x in xs)
    return sum((x - mx) * (y - my) for x, y in zip(xs, ys, strict=True)) / sxx if sxx else 0.0


def main() -> None:
    """Run from the command line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('directory', help='what memory_curve.py --tracemalloc wrote')
    parser.add_argument('--first', type=int, default=1,
                        help='the first snapshot used (0: the one at start-up)')
    parser.add_argument('--top', type=int, default=10, help='node sites printed')
    parser.add_argument('--frames', type=int, default=8, help='frames printed of each site')
    args = parser.parse_args()

    times, faults = [], []
    with open(os.path.join(args.directory, 'faults.csv')) as source:
        for line in source:
            when, count = line.strip().split(',')
            times.append(float(when))
            faults.append(int(count))
    stems, figures = [], []
    for path in sorted(glob.glob(os.path.join(args.directory, '*.tracemalloc'))):
        stem = path[:-len('.tracemalloc')]
        with open(f'{stem}.json') as source:
            written = json.load(source)
        # The node's exit comes after the curve's last row, its core dropped: not a point.
        if not written.get('final', written['time'] > times[-1]):
            stems.append(stem)
            figures.append(written)
    stems, figures = stems[args.first:], figures[args.first:]
    filters = [tracemalloc.Filter(False, name) for name in IGNORED]
    groups = {name: [0] * len(stems) for name in GROUPS}
    sites: dict[tuple[str, ...], list[int]] = collections.defaultdict(lambda: [0] * len(stems))
    xs = [faults_at(times, faults, written['time']) for written in figures]
    blocks = [written['python_blocks'] for written in figures]
    for index, stem in enumerate(stems):
        snapshot = tracemalloc.Snapshot.load(f'{stem}.tracemalloc').filter_traces(filters)
        for trace in snapshot.traces:
            frames = tuple(f'{frame.filename}:{frame.lineno}' for frame in trace.traceback)
            kind = group(tuple(frame.filename for frame in trace.traceback))
            groups[kind][index] += 1
            if kind == 'node':
                sites[frames][index] += 1

    print(f'{len(stems)} snapshots from {xs[0]:.0f} to {xs[-1]:.0f} faults')
    print(f'  {"faults":18s} ' + ' '.join(f'{x:7.0f}' for x in xs))
    print(f'  {"CPython blocks":18s} ' + ' '.join(f'{b:7d}' for b in blocks)
          + f'   {slope(xs, blocks):+.2f} a fault')
    for name in GROUPS:
        print(f'  {name:18s} ' + ' '.join(f'{c:7d}' for c in groups[name])
              + f'   {slope(xs, groups[name]):+.2f} a fault')
    grown = sorted(sites.items(), key=lambda item: item[1][0] - item[1][-1])[:args.top]
    print('\nnode sites that grew most from the first to the last snapshot:')
    for frames, counts in grown:
        print(f'{counts[-1] - counts[0]:+d} blocks ({slope(xs, counts):+.3f} a fault): '
              + ' '.join(str(c) for c in counts))
        for frame in frames[-args.frames:]:
            print(f'    {frame}')


if __name__ == '__main__':
    main()
