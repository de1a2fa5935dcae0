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
allan.py's; the sources imu_samples.py's and noise_live.py's.
"""

import argparse
from collections.abc import Sequence
import json
import math
import os
import sys
import time
from typing import Any, NamedTuple

import numpy as np

from . import allan
from .figures import agg_figure, MatplotlibMissing
from .imu_samples import from_bag, from_capture, Samples
from .sources import add_sources, parse_args

#: Units of each sensor's terms: N, B, K.
UNITS = {'gyroscope': ('rad/s/√Hz', 'rad/s', 'rad/s²/√Hz'),
         'accelerometer': ('m/s²/√Hz', 'm/s²', 'm/s³/√Hz')}
#: A one-second mean further than this from the rest says the sensor moved.
MOVED = {'gyroscope': 0.01, 'accelerometer': 0.1}
#: Missing records beyond this share make the figures doubtful.
MISSING_SHARE = 0.01


class Report(NamedTuple):
    """What the tool found: the source's figures, each sensor's terms, and what to doubt."""

    samples: Samples
    rate_hz: float
    duration_s: float
    deviation: dict[str, allan.Deviation]
    terms: dict[str, list[allan.AxisNoise]]
    warnings: list[str]
    mag_stddev: float | None


def analyse(samples: Samples) -> Report:
    """Take the Allan deviation of both sensors and read the terms; note what is doubtful."""
    n = samples.time.size
    if n < 16:
        raise ValueError(f'{samples.source}: {n} samples; the Allan deviation needs a '
                         'recording of minutes')
    rate = samples.rate_hz
    dt = 1.0 / rate
    duration = n * dt
    warnings = []
    gaps = allan.find_gaps(samples.time)
    if gaps.missing:
        doubt = (' : the figures are doubtful' if gaps.missing > MISSING_SHARE * n else '')
        warnings.append(f'{gaps.missing} records missing in {gaps.count} gaps (longest '
                        f'{gaps.longest:.3g} s); the deviation takes the rest as '
                        f'contiguous{doubt}')
    deviation, terms = {}, {}
    for name, values in (('gyroscope', samples.gyro), ('accelerometer', samples.accel)):
        still = allan.movement(samples.time, values, MOVED[name])
        for begin, end, step in still.stretches[:5]:
            warnings.append(f'the sensor moved: {name} {begin:.0f}-{end:.0f} s, a one-second '
                            f'mean {step:.3g} {UNITS[name][1]} off the rest')
        if len(still.stretches) > 5:
            warnings.append(f'the sensor moved: {name}, {len(still.stretches) - 5} more '
                            'stretches')
        deviation[name] = allan.overlapping_adev(values, dt)
        terms[name] = allan.read_terms(deviation[name], duration)
        if any(math.isnan(axis.white.value) for axis in terms[name]):
            raise ValueError(f'{samples.source}: {n} samples over {duration:.3g} s are too '
                             'few for even the white noise: record at least a minute')
    mag = None
    if samples.mag is not None and samples.mag.shape[0] > 2:
        # The field's white noise a reading: the scatter of steps over sqrt(2) (a slow
        # drift or an offset does not enter it).
        mag = float(np.max(np.std(np.diff(samples.mag, axis=0), axis=0)) / math.sqrt(2.0))
    return Report(samples, rate, duration, deviation, terms, warnings, mag)


def yaml_float(value: float) -> str:
    """Return ``value`` as YAML 1.1 reads a float (PyYAML, kalibr): always with a dot."""
    text = f'{value:.6g}'
    mantissa, e, exponent = text.partition('e')
    if '.' not in mantissa and mantissa.lstrip('-').isdigit():
        mantissa += '.0'
    return mantissa + e + exponent


def _axes(terms: list[allan.AxisNoise], part: str) -> list[float]:
    return [getattr(axis, part).value for axis in terms]


def parameters(report: Report) -> dict[str, float]:
    """Return the covariance parameters: N sqrt(rate), a sample's white noise, worst axis."""
    root = math.sqrt(report.rate_hz)
    out = {
        'angular_velocity_stddev': max(_axes(report.terms['gyroscope'], 'white')) * root,
        'linear_acceleration_stddev': max(_axes(report.terms['accelerometer'], 'white')) * root,
    }
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
            'bias_instability_tau_s': [axis.bias_tau for axis in terms],
            'clusters': {part: [getattr(axis, part).clusters for axis in terms]
                         for part in ('white', 'bias_instability', 'random_walk')},
            'too_short': [s for axis in terms for s in
                          (axis.white.short, axis.bias_instability.short, axis.random_walk.short)
                          if s],
            'allan_deviation': {'tau_s': report.deviation[name].tau.tolist(),
                                'adev': report.deviation[name].adev.T.tolist()},
        }
    out['parameters'] = parameters(report)
    out['warnings'] = report.warnings
    return out


def params_yaml(report: Report) -> str:
    """Return noise.yaml: the covariance parameters as a params file the node takes."""
    lines = [
        '# Measured by `ros2 run i3dmgx2_driver noise` at rest from',
        f'# {report.samples.source}: {report.duration_s / 60:.1f} min at {report.rate_hz:.4g} Hz.',
        '# The white noise of one sample (N * sqrt(rate)), the worst axis. Load it after the',
        "# driver's own file: --params-file config/i3dmgx2.yaml --params-file noise.yaml",
        '/**:',
        '  ros__parameters:',
    ]
    lines += [f'    {name}: {yaml_float(value)}' for name, value in parameters(report).items()]
    return '\n'.join(lines) + '\n'


def kalibr_yaml(report: Report, topic: str) -> str:
    """Return imu.yaml, kalibr's IMU file: densities and random walks, the worst axis."""
    gyro, accel = report.terms['gyroscope'], report.terms['accelerometer']
    return '\n'.join([
        '# kalibr IMU file, measured by `ros2 run i3dmgx2_driver noise` (worst axis of each).',
        f'# From {report.samples.source}: {report.duration_s / 60:.1f} min.',
        f'rostopic: {topic}',
        f'update_rate: {yaml_float(report.rate_hz)}',
        f'accelerometer_noise_density: {yaml_float(max(_axes(accel, "white")))}'
        '  # m/s^2/sqrt(Hz)',
        f'accelerometer_random_walk: {yaml_float(max(_axes(accel, "random_walk")))}'
        '  # m/s^3/sqrt(Hz)',
        f'gyroscope_noise_density: {yaml_float(max(_axes(gyro, "white")))}  # rad/s/sqrt(Hz)',
        f'gyroscope_random_walk: {yaml_float(max(_axes(gyro, "random_walk")))}'
        '  # rad/s^2/sqrt(Hz)',
    ]) + '\n'


def _sure(term: allan.Term) -> str:
    pct = allan.uncertainty(term.clusters) * 100
    return f'±{pct:.0f}% ({term.clusters})' if math.isfinite(pct) else '(too short)'


def table(report: Report) -> str:
    """Return the printed table: per sensor and axis, N, B (tau) and K, how sure each is."""
    lines = [f'{report.samples.source}: {report.samples.time.size} samples, '
             f'{report.duration_s / 60:.1f} min at {report.rate_hz:.4g} Hz']
    for name, terms in report.terms.items():
        n_unit, b_unit, k_unit = UNITS[name]
        lines.append(f'{name}: N {n_unit}, B {b_unit}, K {k_unit}; ± the 1-sigma error of '
                     'the deviation behind each (its clusters)')
        lines.append(f'  {"axis":4} {"N":>10} {"":15} {"B":>10} {"(tau)":>9} {"":15} '
                     f'{"K":>10}')
        for label, axis in zip('xyz', terms, strict=True):
            lines.append(
                f'  {label:4} {axis.white.value:10.3e} {_sure(axis.white):15} '
                f'{axis.bias_instability.value:10.3e} {f"({axis.bias_tau:.3g} s)":>9} '
                f'{_sure(axis.bias_instability):15} {axis.random_walk.value:10.3e} '
                f'{_sure(axis.random_walk)}')
        for label, axis in zip('xyz', terms, strict=True):
            for term, short in (('N', axis.white.short), ('B', axis.bias_instability.short),
                                ('K', axis.random_walk.short)):
                if short:
                    lines.append(f'  {name} {label}: {term} {short}')
    lines += [f'warning: {w}' for w in report.warnings]
    return '\n'.join(lines)


def draw(report: Report, path: str) -> None:
    """Write allan.png: the deviation per axis, the three fitted terms marked."""
    fig = agg_figure(figsize=(10.0, 8.0), dpi=120)
    colours = ('tab:red', 'tab:green', 'tab:blue')
    for row, (name, terms) in enumerate(report.terms.items()):
        ax = fig.add_subplot(2, 1, row + 1)
        dev = report.deviation[name]
        for axis, (label, colour) in enumerate(zip('xyz', colours, strict=True)):
            t = terms[axis]
            ax.loglog(dev.tau, dev.adev[:, axis], 'o-', color=colour, ms=3, label=label)
            ax.loglog(dev.tau, t.white.value / np.sqrt(dev.tau), ':', color=colour, lw=0.8)
            ax.loglog(dev.tau, t.random_walk.value * np.sqrt(dev.tau / allan.K_TAU), '--',
                      color=colour, lw=0.8)
            ax.axhline(t.bias_instability.value * allan.FLICKER_FLOOR, color=colour, lw=0.6,
                       ls='-.')
            ax.plot([allan.N_TAU], [t.white.value], 's', color=colour)
            ax.plot([t.bias_tau], [t.bias_instability.value * allan.FLICKER_FLOOR], 'v',
                    color=colour)
            ax.plot([allan.K_TAU], [t.random_walk.value], '^', color=colour)
        lo = np.nanmin(dev.adev) / 3
        ax.set_ylim(lo, np.nanmax(dev.adev) * 3)
        ax.set_title(f'{name}: N (square, tau 1 s), B (triangle down, 0.664 B), '
                     'K (triangle up, tau 3 s)', fontsize=9)
        ax.set_ylabel(f'Allan deviation ({UNITS[name][1]})')
        ax.grid(True, which='both', alpha=0.3)
        ax.legend(fontsize=8)
    fig.axes[-1].set_xlabel('tau (s)')
    fig.tight_layout()
    fig.savefig(path)


def write_outputs(report: Report, directory: str, topic: str) -> list[str]:
    """Write noise.json, noise.yaml, imu.yaml and (with matplotlib) allan.png; return them."""
    os.makedirs(directory, exist_ok=True)
    written = []
    for name, text in (('noise.json', json.dumps(as_json(report), indent=2) + '\n'),
                       ('noise.yaml', params_yaml(report)),
                       ('imu.yaml', kalibr_yaml(report, topic))):
        path = os.path.join(directory, name)
        with open(path, 'w', encoding='utf-8') as f:
            f.write(text)
        written.append(path)
    png = os.path.join(directory, 'allan.png')
    try:
        draw(report, png)
        written.append(png)
    except MatplotlibMissing as exc:
        print(f'noise: allan.png not drawn: {exc}', file=sys.stderr)
    return written


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='noise', description=__doc__.split('\n\n')[0],
        epilog='Keep the sensor still for the whole recording: an hour or more for the '
               'bias instability and the random walk, minutes for the white noise.')
    add_sources(parser, 'analyses', 'noise.json, noise.yaml, imu.yaml and allan.png')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the noise tool; return the exit status."""
    args = parse_args(_parser(), argv)
    start = time.monotonic()
    try:
        if args.capture:
            samples = from_capture(args.capture)
        elif args.bag:
            samples = from_bag(args.bag, args.topic)
        else:
            if not args.minutes > 0:
                print('noise: --minutes must be positive', file=sys.stderr)
                return 2
            from .noise_live import listen
            samples = listen(args.topic, args.minutes * 60.0)
        read = time.monotonic() - start
        report = analyse(samples)
    except ImportError as exc:
        print(f'noise: {exc}', file=sys.stderr)
        return 1
    except (OSError, ValueError) as exc:
        print(f'noise: {exc}', file=sys.stderr)
        return 1
    print(table(report))
    print(f'(read in {read:.1f} s, analysed in {time.monotonic() - start - read:.1f} s)')
    if args.output:
        for path in write_outputs(report, args.output, args.topic):
            print(f'wrote {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
