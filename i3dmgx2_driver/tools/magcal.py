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
Calibrate the magnetometer where it is mounted: hard and soft iron, fitted on a sweep.

From a capture (``--capture``), a bag (``--bag``: the field on ``imu/mag``,
the acceleration and attitude on the Imu topic) or the running node
(``--minutes``). Turned through many attitudes, the field fills an
ellipsoid: a least-squares quadric (numpy's SVD: ten terms, no library
needed) gives the offset (hard iron) and a symmetric matrix (soft iron)
that make it a sphere. Turned in yaw alone (``--planar``, a ground robot),
it fills an ellipse in the plane the accelerometer says is level: the
horizontal offset and 2x2 matrix, nothing vertical. The field is fitted
raw: a calibration the node applies already (its parameters, or
``--applied FILE``) is undone first, so what is written replaces it.
Details, and how to read the figures: docs/magcal.md.

Listening, each field is paired with the Imu message of the same stamp
(one record makes both). A line on stderr says how many readings came and
what the sweep still lacks, with which way to turn; Ctrl-C (or SIGTERM)
ends the listening and magcal fits what came. The node's own
``mag_hard_iron`` and ``mag_soft_iron`` are read first (its get_parameters
service), so that the fit is made on the raw field whatever the node applies.
"""

import argparse
import ast
from collections.abc import Sequence
import json
import math
import sys
import time
from typing import Any, NamedTuple

import numpy as np
from rcl_interfaces.srv import GetParameters
from rclpy.node import Node
from rclpy.parameter import parameter_dict_from_yaml_file, parameter_value_to_python

from .figures import agg_figure, write_files
from .imu_samples import bag_messages, capture_records, vectors, xyz
from .sources import add_sources, listening, paired, parse_args, read_source, stamp_of
from ..codec.orientation import body_vector, ENU
from ..ros.calibration_file import params_file
from ..ros.conversions import TESLA_PER_GAUSS
from ..ros.mag_calibration import HARD_IRON, IDENTITY, is_matrix_list, SOFT_IRON, ZERO

#: Share of the readings that must lie within 45 degrees of each sensor axis (3-D).
AXIS_SHARE = 0.01
#: Widest stretch of heading a yaw-only sweep may leave unseen (deg).
MAX_GAP_DEG = 45.0
#: Offsets of the two halves of the recording further apart than this (of the field)
#: say the disturbance moved.
MOVED = 0.02
#: The sensor's own heading off by more than this (deg) calls for advice.
OWN_HEADING_DEG = 3.0
#: Seconds to wait for the node's parameters.
PARAMETERS_S = 10.0
_AXES = ('+x (front)', '-x (back)', '+y (right side)', '-y (left side)', '+z (bottom)', '-z (top)')


class Sweep(NamedTuple):
    """The readings: field (T) and gravity's direction, in the sensor's axes (FRD)."""

    field: np.ndarray               # (n, 3) T, raw
    down: np.ndarray                # (n, 3) unit vectors, from the accelerometer
    heading: np.ndarray | None      # (n,) rad, the sensor's own attitude's heading
    source: str


class Fit(NamedTuple):
    """A calibration: ``soft_iron @ (field - hard_iron)``, and how well it did."""

    hard_iron: np.ndarray
    soft_iron: np.ndarray
    planar: bool
    lines: list[str]
    warnings: list[str]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def from_capture(path: str) -> Sweep:
    """Decode the records with a field and an acceleration (0xCB, 0xCC, 0xD2) of a capture."""
    found, frames = capture_records(path, ('mag', 'accel'))
    records = [record for _, record in found if not math.isnan(record.mag[0])]
    if not records:
        raise ValueError(f'{path}: no record with a field and an acceleration (0xCB, 0xCC, '
                         f'0xD2; {frames} frames decoded)')
    own = np.array([math.atan2(r.matrix[1], r.matrix[0]) if hasattr(r, 'matrix')
                    else getattr(r, 'yaw', math.nan) for r in records])
    return Sweep(vectors(r.mag for r in records) * TESLA_PER_GAUSS,
                 -_unit(vectors(r.accel for r in records)),
                 None if np.isnan(own).all() else own, path)


def from_messages(pairs: Sequence[tuple[Any, Any]], source: str) -> Sweep:
    """Return the sweep of (Imu, MagneticField) pairs of one record, in the sensor's axes."""
    if not pairs:
        raise ValueError(f'{source}: no field (imu/mag) with an Imu message of the same stamp')
    ned = pairs[0][1].header.frame_id.endswith('_ned')
    axes = np.array((1.0, 1.0, 1.0) if ned else body_vector((1.0, 1.0, 1.0), ENU))
    field = vectors(xyz(m.magnetic_field) for _, m in pairs) * axes
    accel = vectors(xyz(i.linear_acceleration) for i, _ in pairs) * axes
    x, y, z, w = np.array([(*xyz(i.orientation), i.orientation.w) for i, _ in pairs]).T
    # The body's x axis in the world (the rotation's first column): (north, east, down)
    # in NED, (east, north, up) in ENU.
    first, second = 1 - 2 * (y * y + z * z), 2 * (x * y + z * w)
    heading = np.arctan2(second, first) if ned else np.arctan2(first, second)
    known = pairs[0][0].orientation_covariance[0] != -1.0
    return Sweep(field, -_unit(accel), heading if known else None, source)


def from_bag(path: str, topic: str, applied: str | None = None) -> Sweep:
    """Read the Imu topic and its sibling ``mag`` of a bag, paired by stamp; undo ``applied``."""
    imu, fields = {}, []
    for is_imu, msg in bag_messages(path, topic):
        if is_imu:
            imu[stamp_of(msg)] = msg
        else:
            fields.append(msg)
    sweep = from_messages(paired(imu, fields), f'{path} ({topic})')
    return undo(sweep, *applied_file(applied)) if applied else sweep


def undo(sweep: Sweep, hard_iron: Sequence[float], soft_iron: Sequence[float]) -> Sweep:
    """Return the raw sweep of one a calibration was applied to (the node's, as published)."""
    raw = np.linalg.solve(np.reshape(soft_iron, (3, 3)), sweep.field.T).T + hard_iron
    return sweep._replace(field=raw)


def applied_file(path: str) -> tuple[list[float], list[float]]:
    """Return the calibration a params file (magcal.yaml) sets, read as rclpy reads it."""
    values = {name: parameter_value_to_python(p.value)
              for name, p in parameter_dict_from_yaml_file(path, use_wildcard=True).items()}
    if HARD_IRON not in values and SOFT_IRON not in values:
        raise ValueError(f'{path}: no {HARD_IRON} or {SOFT_IRON} in it')
    # rclpy's reader gives a list with a number like 5e-06 back as its text.
    return tuple([float(v) for v in (ast.literal_eval(given) if isinstance(given, str) else given)]
                 for given in (values.get(HARD_IRON, ZERO), values.get(SOFT_IRON, IDENTITY)))


def level(down: np.ndarray) -> np.ndarray:
    """Return the rotation that takes the mean of ``down`` to +z, keeping x forward."""
    z = _unit(down.mean(axis=0))
    x = _unit(np.array([1.0, 0.0, 0.0]) - z[0] * z)
    return np.array([x, np.cross(z, x), z])


def headings(field: np.ndarray, down: np.ndarray) -> np.ndarray:
    """Return the heading (rad, clockwise from magnetic north) of x, levelled by ``down``."""
    east = _unit(np.cross(down, field))
    north = np.cross(east, down)
    return np.arctan2(east[:, 0], north[:, 0])


def _wrap_deg(angle: np.ndarray) -> np.ndarray:
    return np.degrees(np.angle(np.exp(1j * angle)))


def coverage_problem(sweep: Sweep, planar: bool) -> str | None:
    """Say what the sweep lacks, and which way to turn; None when it is enough."""
    n = sweep.field.shape[0]
    mid = (sweep.field.max(axis=0) + sweep.field.min(axis=0)) / 2
    if planar:
        flat = (sweep.field - mid) @ level(sweep.down).T
        seen = np.sort(np.degrees(np.arctan2(-flat[:, 1], flat[:, 0])) % 360.0)
        gaps = np.diff(np.concatenate([seen, seen[:1] + 360.0]))
        widest = int(np.argmax(gaps))
        if gaps[widest] <= MAX_GAP_DEG and n >= 50:
            return None
        last = seen[widest]
        return (f'the headings {last:.0f} to {(last + gaps[widest]) % 360:.0f} degrees '
                f'(magnetic, roughly) were not seen in {n} readings: keep turning in place, '
                f'right (clockwise seen from above) through them, a full turn or more')
    near = _unit(sweep.field - mid) @ np.vstack([np.eye(3), -np.eye(3)])[[0, 3, 1, 4, 2, 5]].T
    shares = (near > math.cos(math.radians(45))).mean(axis=0)
    missing = [axis for axis, share in zip(_AXES, shares, strict=True) if share < AXIS_SHARE]
    if not missing and n >= 100:
        return None
    return (f'the field never came along the sensor\'s {", ".join(missing) or "axes"} '
            f'({n} readings): turn the sensor so that each of them in turn points along the '
            'field (north, and down by the dip), rolling and pitching it as well as turning')


def _quadric_fit(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return the centre and the symmetric matrix (det 1) that make the points a sphere/circle."""
    mean, scale = points.mean(axis=0), points.std()
    p = (points - mean) / scale
    k = p.shape[1]
    pairs = [(i, j) for i in range(k) for j in range(i, k)]
    design = np.column_stack([p[:, i] * p[:, j] * (1 if i == j else 2) for i, j in pairs]
                             + [2 * p, np.ones(len(p))])
    v = np.linalg.svd(design, full_matrices=False)[2][-1]
    a = np.zeros((k, k))
    for (i, j), value in zip(pairs, v, strict=False):
        a[i, j] = a[j, i] = value
    if np.linalg.eigvalsh(a)[0] < 0:
        a, v = -a, -v
    w, basis = np.linalg.eigh(a)
    if w[0] <= 0:
        raise ValueError('the readings lie on no ellipsoid: the sweep or the field is wrong')
    centre = -np.linalg.solve(a, v[len(pairs):len(pairs) + k])
    root = basis @ np.diag(np.sqrt(w)) @ basis.T
    root = (root + root.T) / 2  # symmetric to the last bit, as the node checks it
    return centre * scale + mean, root / np.linalg.det(root) ** (1.0 / k)


def _solve(sweep: Sweep, planar: bool) -> tuple[np.ndarray, np.ndarray]:
    """Return the hard and soft iron fitted on the sweep, 3-D or in the level plane."""
    if not planar:
        return _quadric_fit(sweep.field)
    rot = level(sweep.down)
    centre, matrix = _quadric_fit((sweep.field @ rot.T)[:, :2])
    soft = np.eye(3)
    soft[:2, :2] = matrix
    # The offset's unseen vertical part: whatever leaves its z in the sensor's axes 0.
    unseen = -(rot[0, 2] * centre[0] + rot[1, 2] * centre[1]) / rot[2, 2]
    return rot.T @ np.append(centre, unseen), rot.T @ soft @ rot


def fit(sweep: Sweep, planar: bool) -> Fit:
    """Fit the calibration; refuse a sweep that covers too little (ValueError says why)."""
    problem = coverage_problem(sweep, planar)
    if problem:
        raise ValueError(f'{sweep.source}: {problem}')
    field, rot = sweep.field, level(sweep.down)
    hard_iron, soft_iron = _solve(sweep, planar)
    warnings = ['a yaw-only fit sees neither the vertical offset nor the vertical scale, nor '
                'iron that turns vertical field into horizontal (it goes into the offset): '
                'left 0 and 1; tumble the sensor for a 3-D fit'] if planar else []
    corrected = (field - hard_iron) @ soft_iron.T
    before, after = (np.linalg.norm(v @ rot.T[:, :2] if planar else v, axis=1)
                     for v in (field, corrected))
    radius = float(np.median(after))
    residual = after - radius
    # Each half fitted alone: an offset that differs says the disturbance moved.
    halves = [sweep._replace(field=field[part], down=sweep.down[part])
              for part in (slice(None, len(field) // 2), slice(len(field) // 2, None))]
    if all(coverage_problem(half, planar) is None for half in halves):
        first, second = (_solve(half, planar)[0] for half in halves)
        moved = float(np.linalg.norm(soft_iron @ (second - first))) / radius
        if moved > MOVED:
            warnings.append(f'the offset moved during the recording: the halves differ by '
                            f'{moved:.1%} of the field (the disturbance moved, or the sensor '
                            'neared other iron); the fit is doubtful, record again')
    flat = np.median(np.linalg.norm((corrected @ rot.T)[:, :2], axis=1))
    truth = headings(corrected, sweep.down)
    error = _wrap_deg(headings(field, sweep.down) - truth)
    lines = [f'{sweep.source}: {field.shape[0]} readings, {"yaw-only" if planar else "3-D"} fit',
             f'hard iron (T): {_text(hard_iron)}',
             f'soft iron: {" / ".join(map(_text, soft_iron))}',
             f'field {"horizontal " if planar else ""}magnitude: {np.mean(before) * 1e6:.2f} µT '
             f'± {np.std(before) / np.mean(before):.1%} before, {radius * 1e6:.2f} µT '
             f'± {np.std(residual) / radius:.1%} after',
             f'heading error of the distortion: {_spread(error)} before; '
             f'{math.degrees(np.std(residual) / flat):.2f} deg rms after (the residual)']
    if sweep.heading is not None:
        own = _wrap_deg(sweep.heading - truth)
        lines += ["the sensor's own orientation's heading against the corrected field: "
                  + _spread(own),
                  'advice: the sensor computes its heading from the uncorrected field (it takes '
                  'no correction): move it away from the iron, or fuse the corrected imu/mag '
                  'with the rates in your own filter rather than use its orientation'
                  if np.abs(own).max() > OWN_HEADING_DEG else "advice: the sensor's own "
                  f'orientation is within {OWN_HEADING_DEG:g} deg here: usable as it is']
    return Fit(hard_iron, soft_iron, planar, lines, warnings)


def _text(v: np.ndarray) -> str:
    return '[' + ', '.join(f'{x:.6g}' for x in v) + ']'


def _spread(deg: np.ndarray) -> str:
    return f'{np.sqrt(np.mean(deg ** 2)):.2f} deg rms, {np.abs(deg).max():.1f} max'


def params_yaml(result: Fit, source: str) -> str:
    """Return magcal.yaml: the node's parameters, a ``--params-file``."""
    return params_file([f'Measured by `ros2 run i3dmgx2_driver magcal` '
                        f'({"yaw-only" if result.planar else "3-D"} fit) from {source}.'], '/**',
                       {HARD_IRON: result.hard_iron, SOFT_IRON: result.soft_iron.ravel()})


def draw(sweep: Sweep, result: Fit, path: str) -> None:
    """Write magcal.png: the field before and after on three projections, the fitted circle."""
    fig = agg_figure(figsize=(12.0, 4.2), dpi=100)
    corrected = (sweep.field - result.hard_iron) @ result.soft_iron.T
    # The fitted sphere, or (yaw-only) the fitted circle: near enough x-y for a ground robot.
    radius = np.median(np.linalg.norm(corrected[:, :2] if result.planar else corrected,
                                      axis=1)) * 1e6
    circle = np.linspace(0, 2 * math.pi, 200)
    for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
        ax = fig.add_subplot(1, 3, k + 1)
        for points, label in ((sweep.field, 'before'), (corrected, 'after')):
            ax.plot(points[:, i] * 1e6, points[:, j] * 1e6, '.', ms=2, label=label)
        if k == 0 or not result.planar:
            ax.plot(radius * np.cos(circle), radius * np.sin(circle), 'k-', lw=0.8, label='fit')
        ax.set(xlabel=f'{"xyz"[i]} (µT)', ylabel=f'{"xyz"[j]} (µT)', aspect='equal')
        ax.grid(True, alpha=0.3)
    fig.axes[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)


def write_outputs(sweep: Sweep, result: Fit, directory: str) -> list[str]:
    """Write magcal.yaml, magcal.json and (with matplotlib) magcal.png; return their paths."""
    if not is_matrix_list(result.soft_iron.ravel().tolist()):
        raise ValueError('the fitted soft iron is no symmetric positive-definite matrix: '
                         'the node would refuse it; nothing written')
    document = {'source': sweep.source, 'planar': result.planar,
                HARD_IRON: result.hard_iron.tolist(), SOFT_IRON: result.soft_iron.ravel().tolist(),
                'report': result.lines, 'warnings': result.warnings}
    texts = (('magcal.yaml', params_yaml(result, sweep.source)),
             ('magcal.json', json.dumps(document, indent=2) + '\n'))
    return write_files('magcal', directory, texts, 'magcal.png',
                       lambda path: draw(sweep, result, path))


def calibration(node: Node, name: str) -> list[list[float]]:
    """Return node ``name``'s mag_hard_iron and mag_soft_iron; ValueError when it does not say."""
    client = node.create_client(GetParameters, f'{name}/get_parameters')
    if not client.wait_for_service(timeout_sec=PARAMETERS_S):
        raise ValueError(f'node {name} does not answer get_parameters: is it running '
                         '(--node names it)?')
    future = client.call_async(GetParameters.Request(names=[HARD_IRON, SOFT_IRON]))
    deadline = time.monotonic() + PARAMETERS_S  # the listening's thread spins
    while not future.done() and time.monotonic() < deadline:
        time.sleep(0.05)
    values = future.result().values if future.done() else []
    if len(values) != 2:
        raise ValueError(f'node {name} did not give {HARD_IRON} and {SOFT_IRON}')
    return [list(parameter_value_to_python(v)) for v in values]


def listen(topic: str, node_name: str, seconds: float, planar: bool) -> Sweep:
    """Listen for ``seconds`` (or until Ctrl-C); return the sweep, the node's own undone."""
    # The topics arrive in any order: a field finds its Imu when the pairs are asked for
    # (in a copy of the fields while the spinner thread adds to them).
    imu, fields = {}, []
    with listening('i3dmgx2_magcal', topic, lambda m: imu.update({stamp_of(m): m}),
                   fields.append) as (node, stopped):
        source = f'{node.resolve_topic_name(topic)} (live)'
        applied = calibration(node, node_name)
        start = time.monotonic()
        while time.monotonic() - start < seconds and not stopped.wait(1.0):
            pairs = paired(imu, fields[:])
            missing = (coverage_problem(from_messages(pairs, 'live'), planar) if pairs
                       else 'nothing yet')
            left = max(0.0, seconds - (time.monotonic() - start))
            print(f'\r{left:5.0f} s left, {len(pairs)} readings: '
                  f'{missing or "enough: Ctrl-C fits them"}'[:160].ljust(160), end='',
                  file=sys.stderr, flush=True)
    pairs = paired(imu, fields)
    if not pairs:
        raise ValueError(f'no field on {source} paired with an Imu message: is the driver '
                         'running, with publish_mag?')
    return undo(from_messages(pairs, f'{topic} (live)'), *applied)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog='magcal', description=__doc__.split('\n\n')[0])
    add_sources(parser, 'fits', 'magcal.yaml, magcal.json and magcal.png')
    parser.add_argument('--planar', action='store_true',
                        help='yaw-only fit: a ground robot turning in place')
    parser.add_argument('--node', default='/i3dmgx2_driver',
                        help='live: the node whose calibration in use is undone')
    parser.add_argument('--applied', metavar='FILE',
                        help='bag: the params file of the calibration the node applied')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run magcal; 0: fitted, 1: refused or failed, 3: fitted, but doubtful (warnings)."""
    args = parse_args(_parser(), argv)
    try:
        sweep = read_source(args, from_capture,
                            lambda bag, topic: from_bag(bag, topic, args.applied),
                            lambda topic, seconds: listen(topic, args.node, seconds, args.planar))
        result = fit(sweep, args.planar)
        print('\n'.join(result.lines + [f'warning: {w}' for w in result.warnings]))
        for path in write_outputs(sweep, result, args.output) if args.output else ():
            print(f'wrote {path}')
    except (ImportError, OSError, ValueError) as exc:
        print(f'magcal: {exc}', file=sys.stderr)
        return 1
    return 3 if any('moved' in w for w in result.warnings) else 0


if __name__ == '__main__':
    sys.exit(main())
