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

"""The plot tool: the series equal the decoded data, and the PNG gets written."""

import itertools
import math
from pathlib import Path
import struct

from i3dmgx2_driver.capture.file_format import CaptureWriter
from i3dmgx2_driver.capture.fixtures import (
    fixture_chunks, FIXTURE_GAP, load_fixture, record_timer, timeline,
)
from i3dmgx2_driver.codec import decode_record, encode_data_packet, encode_record
from i3dmgx2_driver.codec.orientation import euler_from_matrix
from i3dmgx2_driver.codec.records import AccelAngRateMagOrientation, TICKS_PER_SECOND
from i3dmgx2_driver.tools import plot
from matplotlib.backends.backend_agg import FigureCanvasAgg
import numpy as np
import pytest

G = 9.80665
PERIOD = (1 << 32) / TICKS_PER_SECOND


@pytest.fixture(scope='module')
def records(fixture_path):
    return [decode_record(r) for s in load_fixture(fixture_path) for r in s.records]


@pytest.fixture(scope='module')
def enu(fixture_path):
    return plot.series_from_fixture(str(fixture_path), 'enu')


@pytest.fixture(scope='module')
def ned(fixture_path):
    return plot.series_from_fixture(str(fixture_path), 'ned')


def _png_size(path):
    raw = Path(path).read_bytes()
    assert raw[:8] == b'\x89PNG\r\n\x1a\n'
    return struct.unpack('>II', raw[16:24])


# Series ------------------------------------------------------------------------------


def test_fixture_series_are_the_decoded_values_in_rep103_axes(enu, records):
    assert len(enu.time) == len(records) == 1900
    accel = np.array([r.accel for r in records]) * G
    rate = np.array([r.angular_rate for r in records])
    flu = np.array([1.0, -1.0, -1.0])  # FRD to FLU: y and z change sign
    np.testing.assert_allclose(enu.accel, accel * flu, rtol=1e-12)
    np.testing.assert_allclose(enu.angular_rate, rate * flu, rtol=1e-12)


def test_ned_series_keep_device_axes_and_protocol_euler_angles(ned, records):
    np.testing.assert_allclose(ned.accel, np.array([r.accel for r in records]) * G,
                               rtol=1e-12)
    expected = np.degrees([euler_from_matrix(r.matrix) for r in records])
    np.testing.assert_allclose(ned.euler, expected, atol=1e-4)


def test_enu_euler_angles_relate_to_ned_as_rep103_says(enu, ned):
    # Same rotation seen with x/y swapped in the world and y/z flipped in the body:
    # roll is kept, pitch changes sign, yaw becomes 90 degrees minus yaw.
    np.testing.assert_allclose(enu.euler[:, 0], ned.euler[:, 0], atol=1e-4)
    np.testing.assert_allclose(enu.euler[:, 1], -ned.euler[:, 1], atol=1e-4)
    yaw = (enu.euler[:, 2] - (90.0 - ned.euler[:, 2]) + 180.0) % 360.0 - 180.0
    np.testing.assert_allclose(yaw, 0.0, atol=1e-4)


def test_fixture_time_is_the_unwrapped_timer_with_gaps_between_captures(enu, fixture_path):
    sets = load_fixture(fixture_path)
    assert enu.time[0] == 0.0
    assert np.all(np.diff(enu.time) > 0)
    i = 0
    for n, fixture_set in enumerate(sets):
        timers = [record_timer(r) for r in fixture_set.records]
        steps = [((b - a) % (1 << 32)) / TICKS_PER_SECOND
                 for a, b in itertools.pairwise(timers)]
        np.testing.assert_allclose(np.diff(enu.time[i:i + len(timers)]), steps, atol=1e-6)
        if n:
            assert enu.time[i] - enu.time[i - 1] == pytest.approx(FIXTURE_GAP)
        i += len(timers)
    # The three joins between captures are restarts, not mere gaps, and are labelled.
    assert len(enu.breaks) == 3
    assert [text.split(':')[0] for _, text in enu.labels] == [s.name for s in sets]
    # set1's 168.5 s pause is a gap in a running timer, not a restart.
    assert any(b - a == pytest.approx(168.513, abs=0.01) for a, b in enu.gaps)


def test_device_times_unwrap_rollover_long_pause_and_restart():
    tps = TICKS_PER_SECOND
    wrap = (1 << 32) - tps // 2  # half a second before the rollover
    timers = [wrap, (wrap + tps) % (1 << 32),             # across the rollover: +1 s
              (wrap + tps + 200 * tps) % (1 << 32),        # a 200 s pause (> half period)
              5 * tps]                                     # a restart (power cycle)
    host = [0.0, 1.0, 201.02, 260.0]
    times, breaks = plot.device_times(timers, host)
    assert times[1] == pytest.approx(1.0)
    assert times[2] == pytest.approx(201.0)
    assert breaks == [3]
    assert times[3] == pytest.approx(201.0 + 58.98)


def test_euler_of_an_unknown_orientation_is_nan():
    assert all(math.isnan(a) for a in plot.euler_deg((0.0, 0.0, 0.0, 0.0)))
    assert plot.euler_deg((0.0, 0.0, math.sin(math.radians(15)), math.cos(math.radians(15)))) \
        == pytest.approx((0.0, 0.0, 30.0))


def write_fixture_capture(fixture_path, path, start_time):
    """Write the fixture as a capture whose header's ``segments`` name its sets, as plot reads."""
    sets = load_fixture(fixture_path)
    segments, seen = [], set()
    for seconds, index, _ in timeline(sets):
        if index not in seen:
            seen.add(index)
            segments.append({'label': f'{sets[index].name}: {sets[index].description}',
                             'start_time': start_time + seconds})
    with CaptureWriter(path, {'port': 'fixture', 'segments': segments}) as writer:
        for receive_time, packet in fixture_chunks(fixture_path, start_time=start_time):
            writer.write(packet, receive_time)


def test_capture_series_equal_fixture_series(tmp_path, fixture_path, enu):
    capture = tmp_path / 'fixture.gx2cap'
    write_fixture_capture(fixture_path, capture, start_time=1.7e9)
    series = plot.series_from_capture(str(capture))
    np.testing.assert_allclose(series.time, enu.time, atol=1e-6)
    np.testing.assert_array_equal(series.accel, enu.accel)
    assert len(series.breaks) == 3 and len(series.labels) == 4


def test_address_filter_keeps_one_node(tmp_path):
    m = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
    path = tmp_path / 'two.gx2cap'
    with CaptureWriter(path, {}) as writer:
        for i in range(10):
            record = encode_record(AccelAngRateMagOrientation(
                (0.0, 0.0, -1.0 - i), (0.0,) * 3, (0.0,) * 3, m, i * TICKS_PER_SECOND // 10))
            writer.write(encode_data_packet(7 if i % 2 else 9, record, 1, 2), 100.0 + i / 10)
    assert len(plot.series_from_capture(str(path)).time) == 10
    seven = plot.series_from_capture(str(path), address=7)
    np.testing.assert_allclose(seven.accel[:, 2], [(2.0 + i) * G for i in range(0, 10, 2)])
    np.testing.assert_allclose(seven.time, [0.0, 0.2, 0.4, 0.6, 0.8])


# CSV ---------------------------------------------------------------------------------


def _csv_rows(n=60, gap_at=30):
    rows = []
    for i in range(n):
        t = 1714000000.0 + 0.01 * i + (5.0 if i >= gap_at else 0.0)
        half = math.radians(i) / 2  # yaw of i degrees
        rows.append((t, 0.1 * i, -0.2, 9.8, 0.001 * i, 0.0, -0.01,
                     0.0, 0.0, math.sin(half), math.cos(half)))
    return rows


def test_csv_series_are_the_columns(tmp_path):
    path = tmp_path / 'run.csv'
    rows = _csv_rows()
    path.write_text('# recorded from /imu/raw_data\n' + ','.join(plot.CSV_COLUMNS) + '\n'
                    + ''.join(','.join(repr(v) for v in row) + '\n' for row in rows))
    series = plot.series_from_csv(str(path))
    table = np.array(rows)
    np.testing.assert_allclose(series.time, table[:, 0] - table[0, 0])
    np.testing.assert_allclose(series.accel, table[:, 1:4])
    np.testing.assert_allclose(series.angular_rate, table[:, 4:7])
    np.testing.assert_allclose(series.euler[:, 2], np.arange(60), atol=1e-9)
    np.testing.assert_allclose(series.euler[:, :2], 0.0, atol=1e-9)
    assert len(series.gaps) == 1 and series.gaps[0][1] - series.gaps[0][0] > 5.0


def test_csv_from_ros2_topic_echo_is_read(tmp_path):
    path = tmp_path / 'echo.csv'
    lines = []
    for t, ax, ay, az, wx, wy, wz, qx, qy, qz, qw in _csv_rows(5, gap_at=99):
        sec = int(t)
        lines.append([sec, round((t - sec) * 1e9), 'imu_link', qx, qy, qz, qw, *[0.0] * 9,
                      wx, wy, wz, *[0.0] * 9, ax, ay, az, *[0.0] * 9])
    path.write_text(''.join(','.join(map(str, line)) + '\n' for line in lines))
    cols = plot.read_csv(str(path))
    np.testing.assert_allclose(cols['ax'], [0.1 * i for i in range(5)])
    np.testing.assert_allclose(cols['wx'], [0.001 * i for i in range(5)])
    np.testing.assert_allclose(cols['qz'], [math.sin(math.radians(i) / 2) for i in range(5)])
    np.testing.assert_allclose(np.diff(cols['time']), 0.01, atol=1e-6)


def test_csv_without_the_columns_is_refused(tmp_path):
    path = tmp_path / 'bad.csv'
    path.write_text('time,ax,ay\n1,2,3\n')
    with pytest.raises(ValueError, match='lacks columns'):
        plot.read_csv(str(path))


# PNG -----------------------------------------------------------------------------------


def test_fixture_png_is_written_with_agg(tmp_path, enu):
    out = tmp_path / 'fixture.png'
    fig = plot.render(enu, str(out))
    assert isinstance(fig.canvas, FigureCanvasAgg)
    assert _png_size(out) == (1500, 1200)  # 10 x 8 in at 150 dpi
    assert 50_000 < out.stat().st_size < 300_000
    # The lines in the figure are the series, with the pen lifted at every gap.
    lines = fig.axes[0].get_lines()
    x, y = lines[0].get_xdata(), lines[0].get_ydata()
    kept = ~np.isnan(y)
    np.testing.assert_array_equal(x[kept], enu.time)
    np.testing.assert_array_equal(y[kept], enu.accel[:, 0])
    assert np.isnan(y).sum() == len(enu.gaps) + len(enu.breaks)


def test_main_plots_the_fixture_a_capture_and_a_csv(tmp_path, fixture_path):
    out = tmp_path / 'f.png'
    assert plot.main(['--fixture', str(fixture_path), '--output', str(out),
                      '--convention', 'ned']) == 0
    assert out.stat().st_size > 50_000
    csv_path = tmp_path / 'run.csv'
    csv_path.write_text(','.join(plot.CSV_COLUMNS) + '\n' + ''.join(
        ','.join(map(str, row)) + '\n' for row in _csv_rows()))
    csv_png = tmp_path / 'run.png'
    assert plot.main([str(csv_path), '-o', str(csv_png)]) == 0
    assert _png_size(csv_png) == (1500, 1200) and csv_png.stat().st_size > 20_000
    empty = tmp_path / 'empty.gx2cap'
    CaptureWriter(empty, {}).close()
    assert plot.main([str(empty), '-o', str(tmp_path / 'e.png')]) == 1
    assert not (tmp_path / 'e.png').exists()


def test_stamp_errors_round_trip_and_plot(tmp_path, capsys):
    """The stamp benchmark's CSV reads back exactly and plots with its events."""
    from harness.stamp_runs import write_stamp_errors
    from i3dmgx2_driver.tools.stamp_plot import read_stamp_errors
    rows = [(100.0 + k / 100, (-7.3 if k < 50 else -7.1) * 1e-3) for k in range(100)]
    path = tmp_path / 'errors.csv'
    write_stamp_errors(str(path), rows, [(100.5, 'power cycle')])
    read = read_stamp_errors(str(path))
    assert read.events == [(100.5, 'power cycle')]
    assert np.allclose(read.time, [t for t, _ in rows])
    assert np.allclose(read.error, [e for _, e in rows])
    out = tmp_path / 'errors.png'
    assert plot.main(['--stamp-errors', str(path), '-o', str(out)]) == 0
    assert out.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert '100 stamp errors' in capsys.readouterr().out
    bad = tmp_path / 'bad.csv'
    bad.write_text('t,e\n1,2\n')
    assert plot.main(['--stamp-errors', str(bad), '-o', str(out)]) == 1
    assert 'time,error' in capsys.readouterr().err
