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
What ``noise`` recovers of the simulator's noise from an hour's capture, and how far to trust it.

Makes a still capture with the simulator's noise model (``--minutes``, 60 by
default, at ``--rate`` Hz, 0xC2 through the base station), writes it, reads
it back and analyses it as ``noise --capture`` does, and prints each term per
axis against the model's truth with the time of each step. ``--seeds N`` runs
the many-seed check instead (the model's arrays, no bytes, through
``noise.analyse``): for two noise configurations, at 30 s, 2, 10 and 60
minutes (``--short-seeds`` seeds, N at the hour), per term: how
many figures are trusted, how many of those lie within their printed
2-sigma of the truth, the printed 1-sigma over the real scatter (rms over
axes and seeds), and the hour's worst axis per seed. Figures in docs/noise.md.
"""

import argparse
import math
import os
import tempfile
import time

from i3dmgx2_driver.capture.file_format import CaptureWriter, default_header
from i3dmgx2_driver.ros.conversions import STANDARD_GRAVITY
from i3dmgx2_driver.simulator.noise_model import NoiseConfig, NoiseModel
from i3dmgx2_driver.simulator.still_capture import still_chunks
from i3dmgx2_driver.tools import allan, noise
from i3dmgx2_driver.tools.imu_samples import from_capture, Samples
import numpy as np

_DEFAULT = NoiseConfig()
#: The configurations of the check: the default, and a sensor with half its white noise
#: and twice its random walk (the floor between them shorter and earlier).
CONFIGS = {'default': _DEFAULT, 'white /2, walk x2': NoiseConfig(
    **{f: tuple(v * (0.5 if 'white' in f else 2.0 if 'walk' in f else 1.0)
                for v in getattr(_DEFAULT, f)) for f in _DEFAULT.__dataclass_fields__})}
DURATIONS = (30.0, 120.0, 600.0, 3600.0)


def truth(config: NoiseConfig) -> dict[str, np.ndarray]:
    """Return each term's truth per axis (gyro x, y, z, accel x, y, z), in the node's units."""
    scale = np.array([1.0] * 3 + [STANDARD_GRAVITY] * 3)
    return {name: true * scale for name, true in zip(allan.TERMS, config.terms(), strict=True)}


def figures(terms: dict[str, list[allan.AxisNoise]], field: str = 'value'
            ) -> dict[str, np.ndarray]:
    """Return a field of each term per axis: its value, error (relative sigma) or bound."""
    return {name: np.array([getattr(getattr(axis, name), field) for sensor in terms.values()
                            for axis in sensor]) for name in allan.TERMS}


def errors(terms: dict[str, list[allan.AxisNoise]], config: NoiseConfig = _DEFAULT
           ) -> dict[str, np.ndarray]:
    """Return each term's relative error per axis (gyro x, y, z, accel x, y, z)."""
    true = truth(config)
    return {name: found / true[name] - 1.0 for name, found in figures(terms).items()}


def model_samples(config: NoiseConfig, seconds: float, rate: float, seed: int) -> Samples:
    """``seconds`` of ``config``'s noise, as the tool's samples in the node's units."""
    draw = NoiseModel(config, seed).draw(round(seconds * rate), 1.0 / rate)
    accel = (draw[:, 3:] + np.array([0.0, 0.0, -1.0])) * STANDARD_GRAVITY
    return Samples(np.arange(draw.shape[0]) / rate, draw[:, :3], accel, None, 'model')


def check(rate: float, short_seeds: int, hour_seeds: int) -> None:
    """Print the many-seed table, the hour's worst axes and the time an hour takes."""
    print('config | length | term | axis-runs | trusted % | within 2-sigma % | ±/scatter '
          '| bound >= truth %')
    for label, config in CONFIGS.items():
        runs: dict[float, list] = {d: [] for d in DURATIONS}
        worst, took, warned = [], [], 0
        for seed in range(max(short_seeds, hour_seeds)):
            whole = model_samples(config, 3600.0 if seed < hour_seeds else 600.0, rate, seed)
            for seconds in DURATIONS:
                n = round(seconds * rate)
                if n > whole.time.size or seed >= (hour_seeds if seconds > 600 else short_seeds):
                    continue
                start = time.monotonic()
                report = noise.analyse(whole._replace(time=whole.time[:n], gyro=whole.gyro[:n],
                                                      accel=whole.accel[:n]))
                if seconds == 3600.0:
                    took.append(time.monotonic() - start)
                    worst.append({k: np.abs(v).max() for k, v in
                                  errors(report.terms, config).items()})
                runs[seconds].append(report.terms)
                warned += bool(report.warnings)
        for seconds, terms in runs.items():
            trusted_all = []
            for name in allan.TERMS:
                error = np.array([errors(t, config)[name] for t in terms])
                sigma = np.array([figures(t, 'error')[name] for t in terms])
                bound = np.array([figures(t, 'bound')[name] for t in terms])
                trusted = np.array([[getattr(a, name).short is None for s in t.values()
                                     for a in s] for t in terms])
                trusted_all.append(trusted.mean())
                within = np.abs(error[trusted]) <= 2.0 * sigma[trusted]
                ratio = (np.sqrt(np.mean(sigma[trusted] ** 2) / np.mean(error[trusted] ** 2))
                         if trusted.any() else math.nan)
                bounded = bound[~trusted] >= truth(config)[name][None, :].repeat(
                    len(terms), 0)[~trusted]
                print(f'{label} | {allan.minutes(seconds)} | {noise.LABELS[name]} | '
                      f'{error.size} | {100 * trusted.mean():.0f} | '
                      f'{100 * within.mean() if within.size else math.nan:.1f} | {ratio:.2f} | '
                      f'{100 * bounded.mean() if bounded.size else math.nan:.0f}')
            print(f'{label} | {allan.minutes(seconds)} | all | | '
                  f'{100 * np.mean(trusted_all):.0f} | | |')
        print(f'{label}: {warned} analyses warned about (moved, gaps)')
        print(f'{label}, an hour, worst axis per seed (%): ' + '; '.join(
            ' '.join(f'{noise.LABELS[k]} {100 * v:.1f}' for k, v in w.items()) for w in worst))
        print(f'{label}: an hour analysed in {min(took):.2f} to {max(took):.2f} s', flush=True)


def main() -> None:
    """Run the hour, or the many-seed check; print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=60.0)
    parser.add_argument('--rate', type=float, default=250.0)
    parser.add_argument('--seed', type=int, default=2)
    parser.add_argument('--seeds', type=int, default=0, metavar='N',
                        help='the many-seed check instead, N seeds at an hour')
    parser.add_argument('--short-seeds', type=int, default=40, metavar='N',
                        help="the check's seeds up to 10 minutes")
    args = parser.parse_args()
    if args.seeds:
        check(args.rate, args.short_seeds, args.seeds)
        return
    seconds = args.minutes * 60.0
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, 'still.gx2cap')
        start = time.monotonic()
        with CaptureWriter(path, default_header(address=95), flush_interval=None) as writer:
            for receive_time, data in still_chunks(seconds, args.rate, seed=args.seed):
                writer.write(data, receive_time)
        made = time.monotonic() - start
        size = os.path.getsize(path)
        start = time.monotonic()
        samples = from_capture(path)
        read = time.monotonic() - start
        start = time.monotonic()
        report = noise.analyse(samples)
        analysed = time.monotonic() - start
    print(f'{samples.time.size} records, {size / 1e6:.0f} MB: made and written {made:.1f} s, '
          f'decoded {read:.1f} s, analysed {analysed:.1f} s')
    for label, error in errors(report.terms).items():
        print(f'{noise.LABELS[label]}: gyro x y z {np.round(error[:3] * 100, 1)} %, '
              f'accel x y z {np.round(error[3:] * 100, 1)} %')


if __name__ == '__main__':
    main()
