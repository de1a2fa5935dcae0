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
Measure a sensor's own noise at rest: the Allan deviation, and the files fusion tools read.

From a capture (``--capture``), a rosbag2 bag (``--bag``, sqlite3 or MCAP)
or the running node (``--topic``, ``--minutes``), in the units and axes the
node publishes. Prints N, B (its tau) and K per axis, with the clusters
behind each; ``-o DIR`` writes noise.json, noise.yaml (the node's
covariance parameters, a ``--params-file``), imu.yaml (kalibr's IMU file)
and allan.png (with matplotlib). The deviation and its reading are
allan.py's; the samples of a capture or a bag imu_samples.py's.

Listening to the node, a progress bar on stderr says the time left and
the white noise so far (N of each gyro axis, from what came); Ctrl-C (or
SIGTERM) ends the listening early and the tool analyses what came.
"""

import argparse
from collections.abc import Sequence
import json
import math
import sys
import time
from typing import Any, NamedTuple

import numpy as np

from . import allan
from .figures import agg_figure, COLOURS, write_files
from .imu_samples import from_bag, from_capture, from_rows, imu_row, Samples, xyz
from .sources import add_sources, listening, parse_args, read_source
from ..ros.calibration_file import params_file, yaml_float

#: Units of each sensor's terms: N, B, K.
UNITS = {'gyroscope': ('rad/s/√Hz', 'rad/s', 'rad/s²/√Hz'),
         'accelerometer': ('m/s²/√Hz', 'm/s²', 'm/s³/√Hz')}
#: Missing records beyond this share make the figures doubtful.
MISSING_SHARE = 0.01
#: Exit status when some figure printed or written is a bound, marked, or warned about.
MARKED = 3
#: The three terms as the table labels them.
LABELS = dict(zip(allan.TERMS, 'NBK', strict=True))


class Report(NamedTuple):
    """What the tool found: the source's figures, each sensor's terms, and what to doubt."""

    samples: Samples
    rate_hz: float
    duration_s: float
    deviation: dict[str, allan.Deviation]
    terms: dict[str, list[allan.AxisNoise]]
    warnings: list[str]
    mag_stddev: float | None

    def trusted(self) -> bool:
        """Return whether every figure is trusted and nothing is warned about."""
        return not self.warnings and all(
            getattr(axis, part).short is None for terms in self.terms.values()
            for axis in terms for part in allan.TERMS)


def analyse(samples: Samples) -> Report:
    """Take the Allan deviation of both sensors' still stretches and read the terms."""
    n, rate = samples.time.size, samples.rate_hz
    duration = n / rate if rate > 0 else 0.0
    if duration < allan.MIN_STILL_S:
        raise ValueError(f'{samples.source}: {n} samples over {duration:.3g} s: too short for '
                         f'even the white noise; record at least {allan.MIN_STILL_S:.0f} s')
    warnings = list(samples.notes)
    missing, longest, gaps = allan.find_gaps(samples.time)
    if missing:
        doubt = '; the figures are doubtful' if missing > MISSING_SHARE * n else ''
        warnings.append(f'{missing} records missing in {gaps} gaps (longest {longest:.3g} s); '
                        f'the deviation takes the rest as contiguous{doubt}')
    values = np.concatenate([samples.gyro, samples.accel], axis=1)
    still = allan.movement(samples.time, values,
                           [f'{name} {axis}' for name in UNITS for axis in 'xyz'], rate)
    warnings += [f'the sensor moved: {begin:.0f}-{end:.0f} s, {what}'
                 for begin, end, what in still.moved[:5]]
    if len(still.moved) > 5:
        warnings.append(f'the sensor moved: {len(still.moved) - 5} more times')
    still_s = duration
    if still.moved:
        if not still.stretches:
            raise ValueError(f'{samples.source}: the sensor moved ({still.moved[0][2]} at '
                             f'{still.moved[0][0]:.0f} s, {len(still.moved)} times in all) and '
                             f'no still stretch of {allan.MIN_STILL_S:.0f} s is left: keep it '
                             'still and record again')
        still_s = sum(stop - start for start, stop in still.stretches) / rate
        warnings.append(f'analysed {len(still.stretches)} still stretches ({still_s:.0f} s of '
                        f'{duration:.0f} s), their Allan variances combined')
    deviation = {name: allan.overlapping_adev(values[:, 3 * j:3 * j + 3], 1.0 / rate,
                                              still.stretches if still.moved else None)
                 for j, name in enumerate(UNITS)}
    terms = {name: allan.read_terms(dev, still_s) for name, dev in deviation.items()}
    # The field's white noise a reading: the scatter of steps over sqrt(2) (a slow drift or
    # an offset does not enter it).
    mag = (float(np.max(np.std(np.diff(samples.mag, axis=0), axis=0)) / math.sqrt(2.0))
           if samples.mag is not None and samples.mag.shape[0] > 2 else None)
    return Report(samples, rate, duration, deviation, terms, warnings, mag)


def _axes(terms: list[allan.AxisNoise], part: str, what: str = 'value') -> list[float | None]:
    """Return ``what`` of a term (its figure) per axis, None where there is none (JSON: no NaN)."""
    return [_number(getattr(getattr(axis, part), what)) for axis in terms]


def _number(value: float) -> float | None:
    return value if math.isfinite(value) else None


class Unbounded(ValueError):
    """A file would need a figure that no axis gives, not even as a bound."""


def figure(terms: list[allan.AxisNoise], part: str) -> tuple[float, str]:
    """
    Return what a file holds for a term: the worst trusted axis, or an upper bound.

    An axis not trusted enters as its bound (never its figure), so that the
    file never claims less noise than the recording allows; a dead axis not
    at all. Also the comment that says which it is.
    """
    values, bounded = [], []
    for label, axis in zip('xyz', terms, strict=True):
        term = getattr(axis, part)
        if term.short is None:
            values.append(term.value)
        elif math.isfinite(term.bound):
            values.append(term.bound)
            bounded.append(label)
    worst = max(values, default=0.0)
    if not worst > 0:
        raise Unbounded(f'{LABELS[part]} has neither a figure nor a bound on any axis')
    return worst, (f'an upper bound: {LABELS[part]} not resolved on {", ".join(bounded)}'
                   if bounded else 'the worst axis')


def parameters(report: Report) -> dict[str, float]:
    """Return the covariance parameters: N sqrt(rate), a sample's white noise, worst axis."""
    root = math.sqrt(report.rate_hz)
    out = {key: figure(report.terms[name], 'white')[0] * root for key, name in
           (('angular_velocity_stddev', 'gyroscope'),
            ('linear_acceleration_stddev', 'accelerometer'))}
    if report.mag_stddev is not None:
        out['magnetic_field_stddev'] = report.mag_stddev
    return out


def as_json(report: Report) -> dict[str, Any]:
    """Return noise.json's content."""
    out: dict[str, Any] = {'source': report.samples.source, 'rate_hz': report.rate_hz,
                           'duration_s': report.duration_s,
                           'samples': int(report.samples.time.size)}
    for name, terms in report.terms.items():
        out[name] = {
            'noise_density': _axes(terms, 'white'),
            'random_walk': _axes(terms, 'random_walk'),
            'bias_instability': _axes(terms, 'bias_instability'),
            'bias_instability_tau_s': [_number(axis.bias_tau) for axis in terms],
            'clusters': {part: _axes(terms, part, 'clusters') for part in allan.TERMS},
            'one_sigma': {part: _axes(terms, part, 'error') for part in allan.TERMS},
            'too_short': [{'axis': label, 'term': LABELS[part], 'why': term.short.why,
                           'record_s': term.short.record_s, 'upper_bound': _number(term.bound)}
                          for label, axis in zip('xyz', terms, strict=True)
                          for part in allan.TERMS
                          if (term := getattr(axis, part)).short is not None],
            'allan_deviation': {'tau_s': report.deviation[name].tau.tolist(),
                                'adev': report.deviation[name].adev.T.tolist()},
        }
    return {**out, 'parameters': parameters(report), 'warnings': report.warnings}


def params_yaml(report: Report) -> str:
    """Return noise.yaml: the covariance parameters as a params file the node takes."""
    notes = ' / '.join(sorted({figure(report.terms[name], 'white')[1] for name in UNITS}))
    return params_file(['Measured by `ros2 run i3dmgx2_driver noise` at rest from',
                        f'{report.samples.source}: {report.duration_s / 60:.1f} min at '
                        f'{report.rate_hz:.4g} Hz.',
                        f'The white noise of one sample (N * sqrt(rate)), {notes}. Load',
                        "it after the driver's own file: --params-file config/i3dmgx2.yaml "
                        '--params-file noise.yaml'], '/**', parameters(report))


#: kalibr's four noise keys: the sensor, the term, the unit.
KALIBR = (('accelerometer_noise_density', 'accelerometer', 'white', 'm/s^2/sqrt(Hz)'),
          ('accelerometer_random_walk', 'accelerometer', 'random_walk', 'm/s^3/sqrt(Hz)'),
          ('gyroscope_noise_density', 'gyroscope', 'white', 'rad/s/sqrt(Hz)'),
          ('gyroscope_random_walk', 'gyroscope', 'random_walk', 'rad/s^2/sqrt(Hz)'))


def kalibr_yaml(report: Report, topic: str, inflate: float = 1.0) -> str:
    """Return imu.yaml, kalibr's IMU file: densities and random walks, times ``inflate``."""
    lines = ['# kalibr IMU file, measured by `ros2 run i3dmgx2_driver noise`.',
             f'# From {report.samples.source}: {report.duration_s / 60:.1f} min.']
    if inflate != 1.0:
        lines.append(f'# Inflated x{inflate:g} (--inflate), for the noise a still recording '
                     'does not see; noise.json holds the measured figures.')
    lines += [f'rostopic: {topic}', f'update_rate: {yaml_float(report.rate_hz)}']
    for key, name, part, unit in KALIBR:
        value, note = figure(report.terms[name], part)
        scaled = f', x{inflate:g}' if inflate != 1.0 else ''
        lines.append(f'{key}: {yaml_float(value * inflate)}  # {unit}, {note}{scaled}')
    return '\n'.join(lines) + '\n'


def _cell(term: allan.Term) -> str:
    """Return a term as the table prints it: figure and 1-sigma, or its bound, or why not."""
    if term.short is None:
        return f'{term.value:10.3e} {f"±{100 * term.error:.2g}% ({term.clusters})":15}'
    if math.isfinite(term.bound):
        return f'{"<" + format(term.bound, ".3e"):>10} {"bound *":15}'
    return f'{"-":>10} {"*":15}'


def table(report: Report) -> str:
    """Return the printed table: per sensor and axis, N, B (tau) and K, how sure each is."""
    lines = [f'{report.samples.source}: {report.samples.time.size} samples, '
             f'{report.duration_s / 60:.1f} min at {report.rate_hz:.4g} Hz']
    for name, terms in report.terms.items():
        n_unit, b_unit, k_unit = UNITS[name]
        lines += [f'{name}: N {n_unit}, B {b_unit}, K {k_unit}; ± the 1-sigma of each after '
                  'the fit (clusters behind it); * not trusted, see below',
                  f'  {"axis":4} {"N":>10} {"":15} {"B":>10} {"(tau)":>9} {"":15} {"K":>10}']
        for label, axis in zip('xyz', terms, strict=True):
            lines.append(f'  {label:4} {_cell(axis.white)} {_cell(axis.bias_instability)[:10]} '
                         f'{f"({axis.bias_tau:.3g} s)":>9} {_cell(axis.bias_instability)[11:]} '
                         f'{_cell(axis.random_walk)}'.rstrip())
        for label, axis in zip('xyz', terms, strict=True):
            shorts = [(LABELS[p], getattr(axis, p).short) for p in allan.TERMS
                      if getattr(axis, p).short is not None]
            dead = shorts and shorts[0][1].why.startswith('dead')   # one line says it all
            lines += ([f'  {name} {label}: {shorts[0][1]}'] if dead else
                      [f'  {name} {label}: {term} {short}' for term, short in shorts])
    lines += [f'warning: {w}' for w in report.warnings]
    return '\n'.join(lines)


def draw(report: Report, path: str) -> Any:
    """
    Write allan.png: the deviation per axis with its 1-sigma, the fitted lines, N, B and K.

    Hollow: the points the fit leaves out (under 4 clusters) and the terms
    not trusted (at their bound); the y range holds every marker.
    """
    fig = agg_figure(figsize=(10.0, 8.0), dpi=120)
    from matplotlib.lines import Line2D     # there, as agg_figure found it
    for row, (name, terms) in enumerate(report.terms.items()):
        ax = fig.add_subplot(2, 1, row + 1)
        dev = report.deviation[name]
        fitted = dev.clusters >= allan.MIN_CLUSTERS
        error = np.array([allan.uncertainty(int(c)) for c in dev.clusters])
        shown = [dev.adev[dev.adev > 0]]
        for t, adev, colour in zip(terms, dev.adev.T, COLOURS, strict=True):
            ax.errorbar(dev.tau[fitted], adev[fitted], yerr=adev[fitted] * error[fitted],
                        fmt='o-', color=colour, ms=3, lw=1, capsize=2)
            ax.loglog(dev.tau[~fitted], adev[~fitted], 'o', mfc='none', color=colour, ms=4)
            lines = ((t.white, ':', allan.N_TAU, 1.0 / np.sqrt(dev.tau / allan.N_TAU)),
                     (t.bias_instability, '-.', t.bias_tau,
                      np.full(dev.tau.shape, allan.FLICKER_FLOOR)),
                     (t.random_walk, '--', allan.K_TAU, np.sqrt(dev.tau / allan.K_TAU)))
            for (term, style, tau, shape), marker in zip(lines, ('s', 'v', '^'), strict=True):
                level = term.value if term.short is None else term.bound
                if not math.isfinite(level) or not level > 0:
                    continue
                scale = allan.FLICKER_FLOOR if marker == 'v' else 1.0
                ax.loglog(dev.tau, level * shape, style, color=colour, lw=0.8)
                ax.plot([tau], [level * scale], marker, color=colour, ms=7,
                        mfc=colour if term.short is None else 'none')
                shown.append(np.array([level * scale]))
        low, high = (float(f(np.concatenate(shown))) for f in (np.min, np.max))
        ax.set(xscale='log', yscale='log', ylim=(low / 2, high * 2),
               ylabel=f'Allan deviation ({UNITS[name][1]})')
        key = [Line2D([], [], color=c, marker='o', ms=3, label=f'{label} (±1 sigma)')
               for label, c in zip('xyz', COLOURS, strict=True)]
        key += [Line2D([], [], color='k', ls=ls, lw=0.8, label=label) for ls, label in
                ((':', 'white, -1/2'), ('-.', 'floor, 0.664 B'), ('--', 'random walk, +1/2'))]
        key += [Line2D([], [], color='k', ls='', marker=m, mfc=f, label=label) for m, f, label in
                (('s', 'k', 'N at 1 s'), ('v', 'k', '0.664 B at its tau'),
                 ('^', 'k', 'K at 3 s'), ('o', 'none', 'hollow: not fitted / a bound'))]
        ax.legend(handles=key, fontsize=7, ncol=2, loc='lower left')
        ax.set_title(f'{name}: the overlapping Allan deviation and the terms read off it',
                     fontsize=9)
        ax.grid(True, which='both', alpha=0.3)
    fig.axes[-1].set_xlabel('tau (s)')
    fig.tight_layout()
    fig.savefig(path)
    return fig


def write_outputs(report: Report, directory: str, topic: str,
                  inflate: float = 1.0) -> list[str]:
    """Write noise.json, noise.yaml, imu.yaml and (with matplotlib) allan.png; return them."""
    texts = (('noise.json', json.dumps(as_json(report), indent=2) + '\n'),
             ('noise.yaml', params_yaml(report)),
             ('imu.yaml', kalibr_yaml(report, topic, inflate)))    # all made before any write
    return write_files('noise', directory, texts, 'allan.png', lambda path: draw(report, path))


#: Seconds between two updates of the progress bar, and of its estimate.
PROGRESS_S = 1.0
ESTIMATE_S = 10.0
BAR = 30


def progress(elapsed: float, total: float, count: int, estimate: str) -> str:
    """Return one line of the progress bar: the bar, the time left, the estimate so far."""
    done = min(1.0, elapsed / total) if total > 0 else 1.0
    left = max(0.0, total - elapsed)
    bar = '#' * round(done * BAR) + '-' * (BAR - round(done * BAR))
    return f'\r[{bar}] {int(left // 60):3d}:{int(left % 60):02d} left, {count} samples{estimate}'


def _estimate(samples: Samples | None) -> str:
    """Return the gyro's white noise so far, for the progress bar."""
    if samples is None or samples.time.size < 64:
        return ''
    dev = allan.overlapping_adev(samples.gyro, 1.0 / samples.rate_hz)
    terms = allan.read_terms(dev, samples.time.size / samples.rate_hz)
    values = ' '.join(f'{axis.white.value:.2e}' for axis in terms
                      if math.isfinite(axis.white.value))
    return f', gyro N {values} rad/s/√Hz' if values else ''


def listen(topic: str, seconds: float) -> Samples:
    """Listen to ``topic`` for ``seconds`` (or until Ctrl-C); return what came."""
    rows, fields = [], []

    def samples() -> Samples | None:
        # Copies (the spinner thread appends); None before the second message.
        got, mag = rows[:], np.array(fields[:])
        return (from_rows(got, mag if mag.shape[0] > 2 else None, source)
                if len(got) > 1 else None)

    with listening('i3dmgx2_noise', topic, lambda msg: rows.append(imu_row(msg)),
                   lambda msg: fields.append(xyz(msg.magnetic_field))) as (node, stopped):
        source = f'{node.resolve_topic_name(topic)} (live)'
        start = time.monotonic()
        estimate, next_estimate = '', start + ESTIMATE_S
        while (elapsed := time.monotonic() - start) < seconds and not stopped.wait(PROGRESS_S):
            if time.monotonic() >= next_estimate:
                estimate = _estimate(samples())
                next_estimate += ESTIMATE_S
            print(progress(elapsed, seconds, len(rows), estimate), end='',
                  file=sys.stderr, flush=True)
    found = samples()
    if found is None:
        raise ValueError(f'no message on {source}: is the driver running?')
    return found


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='noise', description=__doc__.split('\n\n')[0],
        epilog='Keep the sensor still for the whole recording: an hour or more for the '
               'bias instability and the random walk, minutes for the white noise. Exit '
               f'status 0: every figure trusted; {MARKED}: some are bounds, marked or warned '
               'about; 1: nothing to analyse or to write; 2: usage.')
    add_sources(parser, 'analyses', 'noise.json, noise.yaml, imu.yaml and allan.png')
    parser.add_argument('--inflate', type=float, default=1.0, metavar='F',
                        help="multiply imu.yaml's four figures by F >= 1 (kalibr's advice: "
                             'noise a still recording does not see); the other files keep '
                             'the measured ones')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the noise tool; return the exit status."""
    parser = _parser()
    args = parse_args(parser, argv)
    if args.minutes is not None and not args.minutes > 0:
        parser.error(f'--minutes must be positive, got {args.minutes:g}')
    if not args.inflate >= 1.0:
        parser.error(f'--inflate must be 1 or more, got {args.inflate:g}')
    start = time.monotonic()
    try:
        samples = read_source(args, from_capture, from_bag, listen)
        read = time.monotonic() - start
        report = analyse(samples)
    except (ImportError, OSError, ValueError) as exc:
        print(f'noise: {exc}', file=sys.stderr)
        return 1
    print(table(report))
    print(f'(read in {read:.1f} s, analysed in {time.monotonic() - start - read:.1f} s)')
    if args.output:
        try:
            written = write_outputs(report, args.output, args.topic, args.inflate)
        except Unbounded as exc:
            print(f'noise: no files written: {exc}', file=sys.stderr)
            return 1
        print('\n'.join(f'wrote {path}' for path in written))
    if report.trusted():
        return 0
    print(f'noise: not every figure is trusted (the * and warnings above): exit {MARKED}',
          file=sys.stderr)
    return MARKED


if __name__ == '__main__':
    sys.exit(main())
