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
Plot a capture, the real-records fixture or a recorded run to a PNG.

Three stacked panels over time: acceleration (m/s^2), angular rate (rad/s)
and orientation as roll, pitch, yaw (deg), per axis. Gaps in the data are
shaded and never bridged by a line, so that lost packets and the pauses
between separate captures cannot pass for smooth data.

Inputs:

- a capture (``GX2CAP``, see :mod:`i3dmgx2_driver.capture.file_format`): parsed with the
  codec's ``SensorStreamParser``; records that carry acceleration, angular
  rate and orientation matrix (0xCC, also 0xC8) are plotted, in REP-103 axes
  (ENU world, FLU body) or, with ``--convention ned``, the device's own (NED
  world, FRD body). Time comes from the device timer, unwrapped; the host
  receive times only settle what the timer cannot tell (a pause longer than
  half its 218 s period, a restart);
- the fixture (``--fixture PATH``), through the same path as a capture;
- a CSV of a recorded run of the driver, in the values it published on
  ``/imu/raw_data`` (so already in the node's ``frame_convention``)::

      time,ax,ay,az,wx,wy,wz,qx,qy,qz,qw
      1714000000.012,0.12,-0.03,9.79,0.001,-0.002,0.0005,0.0,0.0,0.0,1.0

  ``time`` is ``header.stamp`` in seconds, ``a*`` ``linear_acceleration``
  (m/s^2), ``w*`` ``angular_velocity`` (rad/s), ``q*`` ``orientation``.
  Lines starting with ``#`` are skipped; the header row is required. The
  output of ``ros2 topic echo --csv /imu/raw_data > run.csv`` (40 columns, no
  header) is read as well.
"""

import argparse
from collections.abc import Iterable, Sequence
import csv
import math
import os
import sys
from typing import Any, NamedTuple

import numpy as np

from .figures import agg_figure, COLOURS, have_matplotlib, MATPLOTLIB_HINT
from .imu_samples import decode, device_times, vectors
from .stamp_plot import read_stamp_errors, render_stamp_errors, StampErrors
from .. import lifetime
from ..capture.file_format import is_capture, read_capture
from ..capture.fixtures import FIXTURE_ADDRESS, fixture_chunks, load_fixture, timeline
from ..codec.orientation import (body_vector, CONVENTIONS, ENU, euler_from_matrix,
                                 matrix_from_quaternion, orientation, Quaternion)
from ..ros.conversions import STANDARD_GRAVITY

#: A gap is at least this long (s), and at least GAP_FACTOR typical intervals.
MIN_GAP = 0.5
GAP_FACTOR = 5.0
#: Columns of the CSV format, in order.
CSV_COLUMNS = ('time', 'ax', 'ay', 'az', 'wx', 'wy', 'wz', 'qx', 'qy', 'qz', 'qw')
#: Columns of ``ros2 topic echo --csv`` for sensor_msgs/Imu: stamp (2), frame_id,
#: orientation (4) and its covariance (9), angular velocity (3) and covariance (9),
#: linear acceleration (3) and covariance (9).
ECHO_CSV_COLUMNS = 40
#: Figure size (in) and resolution (dpi) of a report-quality page figure.
FIGSIZE = (10.0, 8.0)
DPI = 150


class Series(NamedTuple):
    """What the figure shows, as arrays: the one place tests compare with the data."""

    time: np.ndarray          # (n,) s from the first sample
    accel: np.ndarray         # (n, 3) m/s^2
    angular_rate: np.ndarray  # (n, 3) rad/s
    euler: np.ndarray         # (n, 3) roll, pitch, yaw in degrees
    gaps: list[tuple[float, float]]   # spans without data (s)
    breaks: list[tuple[float, float]]  # spans where the timer restarts (separate captures)
    labels: list[tuple[float, str]]   # (time, text) marks, e.g. the fixture's poses
    source: str
    frame: str
    time_note: str


# Orientation ------------------------------------------------------------------


def euler_deg(q: Sequence[float]) -> tuple[float, float, float]:
    """
    Roll, pitch, yaw (deg) of a quaternion (x, y, z, w), aircraft ZYX set.

    Read off M = R^T (R the attitude matrix, body to world) as
    docs/protocol.md §9 defines the set, so that in the device's convention it
    is exactly the record's. A zero or NaN quaternion (orientation unknown)
    gives NaN, not an exception.
    """
    x, y, z, w = q
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if not 0.0 < norm < math.inf:
        return (math.nan, math.nan, math.nan)
    r = matrix_from_quaternion(Quaternion(x / norm, y / norm, z / norm, w / norm))
    return tuple(math.degrees(a) for a in euler_from_matrix(r[0::3] + r[1::3] + r[2::3]))


# Time -----------------------------------------------------------------------------


def find_gaps(time: np.ndarray, breaks: Iterable[int] = (),
              threshold: float | None = None) -> tuple[list[int], float]:
    """
    Return the indices that start after a gap, and the threshold used (s).

    By default a gap is a step longer than GAP_FACTOR times the median step
    and at least MIN_GAP, so a few lost packets at 100 Hz and the pauses of
    a 3 Hz poll are both told from ordinary jitter. Breaks always count.
    """
    steps = np.diff(time)
    if threshold is None:
        positive = steps[steps > 0]
        median = float(np.median(positive)) if positive.size else 0.0
        threshold = max(MIN_GAP, GAP_FACTOR * median)
    starts = {int(i) + 1 for i in np.nonzero((steps > threshold) | (steps < 0))[0]}
    return sorted(starts.union(breaks)), threshold


# Inputs ---------------------------------------------------------------------------


def series_from_chunks(chunks: Iterable[tuple[float, bytes]], address: int | None = None,
                       convention: str = ENU, wireless: bool = True, source: str = '',
                       segments: Sequence[tuple[float, str]] = (),
                       gap: float | None = None) -> Series:
    """
    Decode ``(receive_time, bytes)`` chunks and build the plotted series.

    Events complete in a chunk take that chunk's receive time; ``segments``
    are ``(receive_time, label)`` marks, placed at the first record received
    at or after their time.
    """
    if convention not in CONVENTIONS:
        raise ValueError(f'convention must be one of {CONVENTIONS}, got {convention!r}')
    found = decode(chunks, address, wireless, ('accel', 'angular_rate', 'matrix'))[0]
    host, records = [t for t, _ in found], [r for _, r in found]
    frame = 'ENU world / FLU body (REP-103)' if convention == ENU else \
        'NED world / FRD body (device axes)'
    t, break_idx = device_times([r.timer for r in records], host)
    accel = vectors(body_vector(r.accel, convention) for r in records) * STANDARD_GRAVITY
    rate = vectors(body_vector(r.angular_rate, convention) for r in records)
    euler = vectors(euler_deg(orientation(r.matrix, convention)) for r in records)
    firsts = ((next((i for i, h in enumerate(host) if h >= when - 1e-6), None), text)
              for when, text in segments)
    labels = [(float(t[i]), text) for i, text in firsts if i is not None]
    return _with_gaps(Series(t, accel, rate, euler, [], [], labels, source, frame,
                             'from the device timer, unwrapped'), break_idx, gap)


def _with_gaps(series: Series, break_idx: Sequence[int], gap: float | None) -> Series:
    """Return ``series`` with its gaps and timer restarts found from its times."""
    t, restarts = series.time, set(break_idx)
    spans = {i: (float(t[i - 1]), float(t[i])) for i in find_gaps(t, break_idx, gap)[0]}
    return series._replace(gaps=[s for i, s in spans.items() if i not in restarts],
                           breaks=[s for i, s in spans.items() if i in restarts])


def series_from_capture(path: str, address: int | None = None, convention: str = ENU,
                        gap: float | None = None) -> Series:
    """Build the series of a capture file (see the module docstring)."""
    header, chunks = read_capture(path)
    segments = [(float(s['start_time']), str(s['label']).split(' (')[0])
                for s in header.get('segments', ()) if isinstance(s, dict)
                and 'start_time' in s and 'label' in s]
    node = header.get('address') if address is None else address
    source = os.path.basename(path) + (f' (node {node})' if node is not None else '')
    return series_from_chunks(chunks, address, convention,
                              bool(header.get('wireless', True)), source, segments, gap)


def series_from_fixture(path: str, convention: str = ENU, gap: float | None = None,
                        address: int = FIXTURE_ADDRESS) -> Series:
    """Build the series of the real-records fixture, labelled with its poses."""
    sets = load_fixture(path)
    starts: dict[int, float] = {}
    for seconds, index, _ in timeline(sets):
        starts.setdefault(index, seconds)
    segments = [(seconds, f'{sets[i].name}: {sets[i].description.split(" (")[0]}')
                for i, seconds in starts.items()]
    chunks = fixture_chunks(path, address=address, start_time=0.0)
    source = f'real records, sensor at rest in three poses ({os.path.basename(path)})'
    return series_from_chunks(chunks, address, convention, True, source, segments, gap)


def read_csv(path: str) -> dict[str, np.ndarray]:
    """Read a recorded run into columns by CSV_COLUMNS name (float arrays)."""
    with open(path, newline='', encoding='utf-8') as f:
        rows = [row for row in csv.reader(f)
                if row and ''.join(row).strip() and not row[0].lstrip().startswith('#')]
    if rows and rows[0][0].strip().lower() == 'time':
        names, rows = [c.strip().lower() for c in rows[0]], rows[1:]
        missing = [c for c in CSV_COLUMNS if c not in names]
        if missing:
            raise ValueError(f'{path}: CSV lacks columns {", ".join(missing)} '
                             f'(expected {",".join(CSV_COLUMNS)})')
        index = [names.index(c) for c in CSV_COLUMNS]
        table = [[float(row[i]) for i in index] for row in rows]
    elif rows and all(len(row) == ECHO_CSV_COLUMNS for row in rows):
        # ros2 topic echo --csv: sec, nanosec, frame_id, orientation, ..., see ECHO_CSV_COLUMNS.
        table = [[float(r[0]) + float(r[1]) * 1e-9, *map(float, r[28:31]),
                  *map(float, r[16:19]), *map(float, r[3:7])] for r in rows]
    else:
        raise ValueError(f'{path}: not a recognised CSV: expected a header row '
                         f'{",".join(CSV_COLUMNS)} or `ros2 topic echo --csv` rows of '
                         f'sensor_msgs/Imu')
    data = np.array(table, dtype=float).reshape(-1, len(CSV_COLUMNS))
    return {name: data[:, i] for i, name in enumerate(CSV_COLUMNS)}


def series_from_csv(path: str, gap: float | None = None) -> Series:
    """Build the series of a recorded run, in the frame it was published in."""
    cols = read_csv(path)
    data = np.column_stack([cols[name] for name in CSV_COLUMNS])   # time, a, w, q
    t = data[:, 0] - (data[0, 0] if data.size else 0.0)
    return _with_gaps(Series(t, data[:, 1:4], data[:, 4:7], vectors(map(euler_deg, data[:, 7:])),
                             [], [], [], os.path.basename(path),
                             'as published (frame_convention of the recording)',
                             'from the CSV time column'), [], gap)


# Drawing --------------------------------------------------------------------------


def _broken(t: np.ndarray, y: np.ndarray, starts: Sequence[int],
            wrap: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Insert NaN before each gap start (and each wrap of an angle) to lift the pen."""
    cut = set(starts)
    if wrap is not None and y.size > 1:
        cut.update(int(i) + 1 for i in np.nonzero(np.abs(np.diff(y)) > wrap)[0])
    idx = sorted(cut)
    return np.insert(t, idx, np.nan), np.insert(y, idx, np.nan)


def render(series: Series, output: str, title: str | None = None) -> Any:
    """
    Draw the three panels of ``series`` into the PNG ``output``; return the figure.

    The figure is made on an Agg canvas directly, not through pyplot: no
    display is ever needed or opened, no global state is kept, and the
    figure is freed with its last reference (``figures.agg_figure``).
    """
    fig = agg_figure(figsize=FIGSIZE, layout='constrained')
    from matplotlib.patches import Patch     # there, as agg_figure found it
    axes = fig.subplots(3, 1, sharex=True)
    t = series.time
    ends = [b for _, b in series.gaps + series.breaks]
    starts = sorted({int(i) for i in np.searchsorted(t, ends) if 0 < i < t.size})
    panels = ((series.accel, 'Acceleration (m/s²)', ('x', 'y', 'z'), None),
              (series.angular_rate, 'Angular rate (rad/s)', ('x', 'y', 'z'), None),
              (series.euler, 'Orientation (deg)', ('roll', 'pitch', 'yaw'), 180.0))
    shades = ((series.gaps, {'color': '0.85'}, 'no data'),
              (series.breaks, {'facecolor': '0.92', 'edgecolor': '0.6', 'hatch': '///'},
               'timer restarts\n(separate captures)'))
    for ax, (values, ylabel, names, wrap) in zip(axes, panels, strict=True):
        for k, (name, colour) in enumerate(zip(names, COLOURS, strict=True)):
            x, y = _broken(t, values[:, k], starts, wrap)
            ax.plot(x, y, color=colour, linewidth=0.9, label=name)
        for spans, style, _ in shades:
            for a, b in spans:
                ax.axvspan(a, b, linewidth=0, zorder=0, **style)
        ax.set_ylabel(ylabel)
        ax.grid(True, color='0.85', linewidth=0.6)
        ax.margins(x=0.01)
        handles = ax.get_legend_handles_labels()[0]
        if ax is axes[0]:
            handles += [Patch(label=label, **style) for spans, style, label in shades if spans]
        ax.legend(handles=handles, loc='upper left', bbox_to_anchor=(1.01, 1.0),
                  frameon=False, fontsize='small')
    axes[2].set_yticks(np.arange(-180, 181, 90))
    axes[2].set_ylim(-200, 200)
    if series.labels:
        for when, text in series.labels:
            axes[0].annotate(text, xy=(when, 1.0), xycoords=('data', 'axes fraction'),
                             xytext=(2, -2), textcoords='offset points', va='top',
                             fontsize='small', color='0.25')
        low, high = axes[0].get_ylim()
        axes[0].set_ylim(low, high + 0.18 * (high - low))
    axes[2].set_xlabel(f'Time (s), {series.time_note}')
    heading = title or f'3DM-GX2: {series.source}'
    fig.suptitle(f'{heading}\n{t.size:,} samples; {series.frame}', fontsize='medium')
    fig.savefig(output, dpi=DPI)
    return fig


# Command line ---------------------------------------------------------------------


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='plot', description='Plot acceleration, angular rate '
                                     'and orientation of a 3DM-GX2 capture, of the real-records '
                                     'fixture or of a CSV recorded run to a PNG.')
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument('input', nargs='?',
                        help='capture file (GX2CAP) or CSV (time,ax,ay,az,wx,wy,wz,qx,qy,'
                             'qz,qw, or `ros2 topic echo --csv /imu/raw_data` output)')
    source.add_argument('--fixture', metavar='PATH', help='plot the real-records fixture')
    source.add_argument('--stamp-errors', metavar='CSV',
                        help='plot a stamp-error series (time,error; benchmarks/'
                             'stamp_errors.py writes them)')
    parser.add_argument('--address', type=int,
                        help='only records from this node address (captures)')
    parser.add_argument('--convention', choices=CONVENTIONS, default=None,
                        help="enu: REP-103 ENU/FLU (default); ned: the device's NED/FRD "
                             'axes (captures and fixture; a CSV is plotted as recorded)')
    parser.add_argument('--output', '-o', metavar='FILE.png',
                        help='PNG to write (default: the input file name with .png, in '
                             'the current directory)')
    parser.add_argument('--title', help='figure title')
    parser.add_argument('--gap', type=float, metavar='S',
                        help='steps longer than S seconds are gaps (default: automatic)')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the plot command line; return the exit status."""
    args = _parser().parse_args(argv)
    lifetime.die_with_parent()
    if not have_matplotlib():
        print(f'plot: {MATPLOTLIB_HINT}', file=sys.stderr)
        return 1
    source_path = args.fixture or args.stamp_errors or args.input
    output = args.output or os.path.splitext(os.path.basename(source_path))[0] + '.png'
    try:
        if args.stamp_errors:
            series: Series | StampErrors = read_stamp_errors(args.stamp_errors)
            draw, count, empty = render_stamp_errors, 'stamp errors', 'rows'
        else:
            draw, count = render, 'samples'
            empty = 'records with acceleration, angular rate and orientation'
            if args.fixture:
                series = series_from_fixture(args.fixture, args.convention or ENU, args.gap)
            elif is_capture(args.input):
                series = series_from_capture(args.input, args.address, args.convention or ENU,
                                             args.gap)
            else:
                if args.convention:
                    print('plot: a CSV is plotted in the frame it was recorded in; '
                          '--convention ignored', file=sys.stderr)
                series = series_from_csv(args.input, args.gap)
    except (OSError, ValueError) as exc:
        print(f'plot: {exc}', file=sys.stderr)
        return 1
    if not series.time.size:
        print(f'plot: no {empty} in {source_path}', file=sys.stderr)
        return 1
    draw(series, output, args.title)
    print(f'plot: {series.time.size} {count} -> {output}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
