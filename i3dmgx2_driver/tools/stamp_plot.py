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
Plot a stamp-error series: how far each stamp was from the true sample time.

``plot --stamp-errors FILE.csv`` draws what the stamp benchmark
(``benchmarks/stamp_errors.py``) writes: one row per record, ``time`` (the
true sample time, s) and ``error`` (stamp minus sample time, s), with events
(a power cycle, a clock step) as comment lines ``# event,TIME,LABEL``. The
error is drawn in milliseconds against seconds from the first record, each
event as a vertical line, so that a stamp that runs slow after an event (a
slope) or jumps (a step) is plain to see.
"""

from typing import Any, NamedTuple

import numpy as np

from .figures import agg_figure


class StampErrors(NamedTuple):
    """A stamp-error series and the events in it (times in s)."""

    time: np.ndarray
    error: np.ndarray
    events: list[tuple[float, str]]


def read_stamp_errors(path: str) -> StampErrors:
    """Read a stamp-error CSV; raise ValueError naming what is wrong."""
    rows, events, header = [], [], None
    with open(path, newline='') as source:
        for number, raw in enumerate(source, 1):
            line = raw.strip()
            fields = line.split(',')
            if line.startswith('#'):
                parts = line[1:].strip().split(',', 2)
                if parts[0] == 'event' and len(parts) == 3:
                    events.append((float(parts[1]), parts[2]))
            elif line and header is None:
                header = fields
                if header[:2] != ['time', 'error']:
                    raise ValueError(f'{path}: the header must start with time,error '
                                     f'(got {line!r})')
            elif line:
                try:
                    rows.append((float(fields[0]), float(fields[1])))
                except (IndexError, ValueError):
                    raise ValueError(f'{path}:{number}: not two numbers: {line!r}') from None
    times, errors = np.array(rows, dtype=float).reshape(-1, 2).T
    return StampErrors(times, errors, events)


def render_stamp_errors(series: StampErrors, output: str, title: str | None = None) -> Any:
    """Draw the error (ms) over time (s from the first record) to ``output`` (PNG)."""
    fig = agg_figure(figsize=(10, 4.5), dpi=100)
    ax = fig.add_subplot(1, 1, 1)
    start = series.time[0] if series.time.size else 0.0
    ax.plot(series.time - start, series.error * 1e3, '.', markersize=2, color='tab:blue',
            label='stamp - true sample time')
    for at, label in series.events:
        ax.axvline(at - start, color='tab:red', linestyle='--', linewidth=1)
        ax.annotate(label, (at - start, 1.0), xycoords=('data', 'axes fraction'),
                    xytext=(3, -12), textcoords='offset points', color='tab:red', fontsize='small')
    ax.set(xlabel='time since the first record (s)', ylabel='stamp error (ms)')
    ax.grid(True, alpha=0.3)
    ax.legend(loc='lower right', fontsize='small')
    fig.suptitle(title or 'Stamp error against the true sample time', fontsize='medium')
    fig.savefig(output)
    return fig
