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
What ``noise`` recovers of the simulator's noise from an hour's capture, and how fast.

Makes a still capture with the simulator's noise model (``--minutes``, 60 by
default, at ``--rate`` Hz, 0xC2 through the base station), writes it, reads
it back and analyses it as ``noise --capture`` does, and prints each term per
axis against the model's truth with the time of each step. ``--seeds N``
adds the spread over N seeds of the analysis alone (the model's arrays, no
bytes): the worst axis of each term, per seed. Figures in docs/noise.md.
"""

import argparse
import os
import tempfile
import time

from i3dmgx2_driver.capture.file_format import CaptureWriter, default_header
from i3dmgx2_driver.ros.conversions import STANDARD_GRAVITY
from i3dmgx2_driver.simulator.noise_model import NoiseConfig, NoiseModel
from i3dmgx2_driver.simulator.still_capture import still_chunks
from i3dmgx2_driver.tools import allan, noise
from i3dmgx2_driver.tools.imu_samples import from_capture
import numpy as np

PARTS = (('N', 'white'), ('B', 'bias_instability'), ('K', 'random_walk'))


def errors(terms: dict[str, list[allan.AxisNoise]]) -> dict[str, np.ndarray]:
    """Return each term's relative error per axis (gyro x, y, z, accel x, y, z)."""
    truth = NoiseConfig().terms()
    scale = np.array([1.0] * 3 + [STANDARD_GRAVITY] * 3)
    out = {}
    for (label, part), true in zip(PARTS, truth, strict=True):
        found = np.array([getattr(axis, part).value
                          for name in ('gyroscope', 'accelerometer') for axis in terms[name]])
        out[label] = found / (true * scale) - 1.0
    return out


def main() -> None:
    """Run the hour, and the seeds if asked; print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=60.0)
    parser.add_argument('--rate', type=float, default=250.0)
    parser.add_argument('--seed', type=int, default=2)
    parser.add_argument('--seeds', type=int, default=0, metavar='N',
                        help='also the spread of the analysis over N seeds')
    args = parser.parse_args()
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
        print(f'{label}: gyro x y z {np.round(error[:3] * 100, 1)} %, '
              f'accel x y z {np.round(error[3:] * 100, 1)} %')
    for seed in range(args.seeds):
        draw = NoiseModel(NoiseConfig(), seed).draw(round(seconds * args.rate), 1.0 / args.rate)
        draw[:, 3:] *= STANDARD_GRAVITY      # g to m/s^2, as the tool reads them
        dev = allan.overlapping_adev(draw, 1.0 / args.rate)
        terms = allan.read_terms(dev, seconds)
        split = {'gyroscope': terms[:3], 'accelerometer': terms[3:]}
        worst = {label: float(np.abs(e).max() * 100) for label, e in errors(split).items()}
        print(f'seed {seed}: worst axis ' + ', '.join(f'{k} {v:.0f} %' for k, v in worst.items()))


if __name__ == '__main__':
    main()
