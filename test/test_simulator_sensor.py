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
The simulated device without its pseudo-terminal: motion model and SimulatedSensor.

No threads and no clock: times are passed in, so these run in milliseconds and check the
physics and the protocol behaviour exactly.
"""

from itertools import pairwise
import math
import random
import statistics

from i3dmgx2_driver.codec import commands as cmd
from i3dmgx2_driver.codec import decode_record
from i3dmgx2_driver.codec import layouts as lay
from i3dmgx2_driver.codec import records as rec
from i3dmgx2_driver.codec.orientation import euler_from_matrix
from i3dmgx2_driver.simulator import Motion, MotionConfig, SimulatedSensor
from i3dmgx2_driver.simulator.motion import mat_vec, matrix_from_euler
from i3dmgx2_driver.simulator.sensor import DEFAULT_TIMER_START, SensorSpec, STREAMABLE
import pytest

TPS = rec.TICKS_PER_SECOND
T0 = 1_700_000_000.0


def transpose(m):
    return (m[0], m[3], m[6], m[1], m[4], m[7], m[2], m[5], m[8])


def matmul(a, b):
    return tuple(sum(a[3 * i + k] * b[3 * k + j] for k in range(3))
                 for i in range(3) for j in range(3))


def skew(w):
    x, y, z = w
    return (0.0, -z, y, z, 0.0, -x, -y, x, 0.0)


def sensor(motion: Motion | None = None, seed: int = 1, **spec) -> SimulatedSensor:
    return SimulatedSensor(SensorSpec(**spec), motion, seed=seed, power_up_time=T0)


@pytest.mark.parametrize('t', [0.0, 1.3, 7.7, 42.0, 123.4])
def test_orientation_matrix_is_a_rotation_matching_its_euler_angles(t):
    state = Motion().state(t)
    m = state.matrix
    identity = matmul(m, transpose(m))
    assert identity == pytest.approx((1, 0, 0, 0, 1, 0, 0, 0, 1), abs=1e-12)
    assert euler_from_matrix(m) == pytest.approx(state.euler, abs=1e-12)
    assert matrix_from_euler(*state.euler) == pytest.approx(m, abs=1e-15)


@pytest.mark.parametrize('t', [0.5, 3.0, 10.0, 60.0])
def test_angular_rate_is_consistent_with_the_attitude(t):
    # v_sensor = M v_earth for a fixed earth vector: dM/dt = -[w]x M.
    motion = Motion()
    h = 1e-5
    m = motion.state(t).matrix
    dm = [(a - b) / (2 * h) for a, b in zip(motion.state(t + h).matrix,
                                            motion.state(t - h).matrix, strict=True)]
    expected = [-v for v in matmul(skew(motion.state(t).angular_rate), m)]
    assert dm == pytest.approx(expected, abs=1e-7)
    assert 0.01 < math.hypot(*motion.state(t).angular_rate) < 0.5, 'a few deg/s'


def test_gravity_reaction_and_earth_field_are_seen_through_m():
    motion = Motion(MotionConfig(static=True, initial_attitude_deg=(0.0, 0.0, 0.0)))
    state = motion.state(5.0)
    assert state.accel == pytest.approx((0.0, 0.0, -1.0))
    assert state.angular_rate == (0.0, 0.0, 0.0)
    moving = Motion()
    for t in (1.0, 9.0):
        s = moving.state(t)
        m_t = transpose(s.matrix)
        assert mat_vec(m_t, s.accel) == pytest.approx((0.0, 0.0, -1.0), abs=1e-12)
        assert mat_vec(m_t, s.mag) == pytest.approx(moving.earth_field, abs=1e-12)
        assert math.hypot(*s.mag) == pytest.approx(0.5)
    north, east, down = moving.earth_field
    assert math.degrees(math.atan2(down, math.hypot(north, east))) == pytest.approx(60.0)


def test_freezing_and_releasing_the_motion_never_jumps():
    motion = Motion()
    before = motion.state(10.0).matrix
    motion.set_static(True, 10.0)
    assert motion.static
    assert motion.state(15.0).matrix == pytest.approx(before, abs=1e-12)
    assert motion.state(15.0).angular_rate == (0.0, 0.0, 0.0)
    motion.set_static(False, 15.0)
    assert motion.state(15.0).matrix == pytest.approx(before, abs=1e-12)
    assert motion.state(15.1).matrix != pytest.approx(before, abs=1e-6)


def test_noise_and_bias_have_the_configured_size():
    config = MotionConfig(static=True)
    motion = Motion(config)
    rng = random.Random(3)
    samples = [motion.measure(1.0, rng) for _ in range(2000)]
    for axis in range(3):
        rates = [s.angular_rate[axis] for s in samples]
        assert statistics.mean(rates) == pytest.approx(config.gyro_bias[axis], abs=2e-4)
        assert statistics.stdev(rates) == pytest.approx(config.gyro_noise, rel=0.1)
        accels = [s.accel[axis] for s in samples]
        assert statistics.stdev(accels) == pytest.approx(config.accel_noise, rel=0.1)


def test_nan_magnetometer():
    rng = random.Random(1)
    always = Motion(MotionConfig(nan_mag=True))
    assert all(math.isnan(v) for v in always.measure(1.0, rng).mag)
    sometimes = Motion(MotionConfig(mag_nan_probability=0.3))
    nans = sum(math.isnan(sometimes.measure(0.01 * k, rng).mag[0]) for k in range(1000))
    assert 230 < nans < 370


def test_timer_formula_and_default_start_near_the_rollover():
    s = sensor(clock_ppm=40.0)
    assert s.clock.timer_at(T0) == DEFAULT_TIMER_START == 2**32 - 5 * TPS
    assert s.clock.timer_at(T0 + 1.0) == (DEFAULT_TIMER_START + round(TPS * (1 + 40e-6))) % 2**32
    assert s.clock.timer_at(T0 + 6.0) < 2**31, 'the timer wraps five seconds after power-up'
    custom = sensor(timer_start=1000, clock_ppm=-100.0)
    assert custom.clock.timer_at(T0 + 2.0) == 1000 + round(2 * TPS * (1 - 100e-6))


def test_streamed_timers_are_spaced_exactly_across_the_rollover():
    s = sensor(rate_hz=500.0, clock_ppm=40.0)
    s.start_streaming(lay.ACCEL_ANG_RATE, T0)
    step = TPS * (1 + 40e-6) / 500.0
    samples = [s.stream_sample() for _ in range(5000)]         # 10 s: crosses the rollover
    times = [r.sample_time for r in samples]
    timers = [r.record.timer for r in samples]
    assert all(abs((b - a) % 2**32 - step) <= 1 for a, b in pairwise(timers))
    assert any(b < a for a, b in pairwise(timers))
    assert times[0] > T0 and all(abs(b - a - 0.002) < 1e-6 for a, b in pairwise(times))
    assert s.next_sample_time == pytest.approx(times[-1] + 0.002)


def test_default_rate_is_the_factory_divider_and_skip_to_keeps_the_grid():
    s = sensor()
    assert s.rate_hz == 100.0 and s.eeprom[0xFCA2] == 512
    s.start_streaming(lay.ACCEL_ANG_RATE_MAG_ORIENTATION, T0 + 0.005)
    assert s.next_sample_time == pytest.approx(T0 + 0.01)
    skipped = s.clock.skip_to(T0 + 1.0)
    assert skipped == 99 and s.next_sample_time == pytest.approx(T0 + 1.0)


def test_every_command_gets_its_reply_through_the_codec():
    s = sensor()
    now = T0 + 1.0
    for code in sorted(STREAMABLE):
        [reply] = s.handle(cmd.encode_command(code), now)
        assert reply.code == code
        assert decode_record(reply.data) == reply.record
        assert now <= reply.due < now + 0.011, 'sent at the next calculation cycle'
    assert s.handle(cmd.stop_continuous(), now) == []
    [ident] = s.handle(cmd.device_identifier(2), now)
    assert ident.record == rec.DeviceIdentifier(2, '3DM-GX2 Wireless')
    [bit] = s.handle(cmd.built_in_test(0x3C), now)
    assert bit.record == rec.BuiltInTest(0x3C)
    [fw] = s.handle(cmd.encode_command(lay.FIRMWARE_VERSION), now)
    assert fw.record == rec.FirmwareVersion(2113)


def test_continuous_mode_requests():
    s = sensor()
    [reply] = s.handle(cmd.set_continuous(0xCC), T0 + 1.0)
    assert reply.record.command == 0xCC and s.streaming == 0xCC
    assert s.next_sample_time > T0 + 1.0
    [reply] = s.handle(cmd.set_continuous(0), T0 + 2.0)
    assert reply.record.command == 0 and s.streaming == 0 and s.next_sample_time is None
    # 0xE5 takes arguments: it cannot stream, and the device says nothing.
    assert s.handle(cmd.encode_command(lay.SET_CONTINUOUS, lay.READ_EEPROM), T0 + 3.0) == []
    assert s.ignored == 1
    assert s.handle(b'\xC4\x00\x00\xCC', T0 + 3.0) == [], 'wrong confirmation bytes'
    assert s.ignored == 2


def test_eeprom_divider_changes_the_rate_and_persists_over_power_cycles():
    s = sensor()
    [written] = s.handle(cmd.write_eeprom(0xFCA2, 170), T0 + 1.0)
    assert written.record == rec.EepromWritten(170)
    assert s.rate_hz == pytest.approx(51200 / 170)
    [kept] = s.handle(cmd.write_eeprom(0xFCA2, 51201), T0 + 1.0)
    assert kept.record == rec.EepromWritten(170)
    s.handle(cmd.write_eeprom(0xFCA6, 0x80C2), T0 + 1.0)
    s.power_up(T0 + 10.0)
    assert s.rate_hz == pytest.approx(51200 / 170)
    assert s.streaming == 0xC2, 'auto-start from EEPROM 0xFCA6'
    assert s.clock.timer_at(T0 + 10.0) == DEFAULT_TIMER_START


def test_rate_override_wins_over_the_divider():
    s = sensor(rate_hz=2000.0)
    assert s.rate_hz == 2000.0
    s.handle(cmd.write_eeprom(0xFCA2, 1024), T0)
    assert s.rate_hz == 2000.0 and s.eeprom[0xFCA2] == 1024
    s.set_rate_override(None, T0)
    assert s.rate_hz == 50.0


def test_gyro_bias_capture_is_due_after_its_sampling_time_and_then_applied():
    config = MotionConfig(static=True)
    s = sensor(motion=Motion(config))
    [reply] = s.handle(cmd.capture_gyro_bias(10000), T0 + 1.0)
    assert reply.due == pytest.approx(T0 + 11.0)
    assert reply.record.bias == pytest.approx(config.gyro_bias, abs=3e-4)
    assert reply.record.timer == s.clock.timer_at(T0 + 11.0)
    early = s.record_at(lay.ACCEL_ANG_RATE, T0 + 5.0).record.angular_rate
    assert early == pytest.approx(config.gyro_bias, abs=0.01)
    late = s.record_at(lay.ACCEL_ANG_RATE, T0 + 12.0).record.angular_rate
    assert late == pytest.approx((0.0, 0.0, 0.0), abs=0.008)
    [stored] = s.handle(cmd.transfer_to_non_volatile(2), T0 + 13.0)
    assert stored.record.quantity == 2
    s.power_up(T0 + 20.0)
    assert s.biases.gyro == reply.record.bias


def test_written_biases_live_in_ram_and_a_stored_one_survives_a_power_cycle():
    s = sensor(motion=Motion(MotionConfig(static=True)))
    [gyro] = s.handle(cmd.write_gyro_bias((0.01, -0.02, 0.03)), T0 + 1.0)
    [accel] = s.handle(cmd.write_accel_bias((0.001, 0.002, -0.003)), T0 + 1.0)
    # Echoed as float32, the sensor's own numbers.
    assert gyro.record.bias == pytest.approx((0.01, -0.02, 0.03), abs=1e-7)
    assert accel.record.bias == pytest.approx((0.001, 0.002, -0.003), abs=1e-7)
    assert s.biases.gyro == gyro.record.bias and s.biases.accel == accel.record.bias
    # RAM only: a power cycle loses both.
    s.power_off()
    s.power_up(T0 + 2.0)
    assert s.biases.gyro == s.biases.accel == (0.0, 0.0, 0.0)
    # Stored (0xD0, 2: the gyro bias), the gyro bias is what the next power-up loads.
    s.handle(cmd.write_gyro_bias((0.01, -0.02, 0.03)), T0 + 3.0)
    [stored] = s.handle(cmd.transfer_to_non_volatile(rec.GYRO_BIAS_QUANTITY), T0 + 3.0)
    assert stored.record.quantity == rec.GYRO_BIAS_QUANTITY
    s.power_off()
    s.power_up(T0 + 4.0)
    assert s.biases.gyro == gyro.record.bias
    assert s.biases.accel == (0.0, 0.0, 0.0)


def test_a_memory_that_refuses_answers_0xffff_and_keeps_what_it_had():
    s = sensor()
    s.settings.refuse_bias_store = True
    s.handle(cmd.write_gyro_bias((0.01, 0.01, 0.01)), T0 + 1.0)
    [refused] = s.handle(cmd.transfer_to_non_volatile(rec.GYRO_BIAS_QUANTITY), T0 + 1.0)
    assert refused.record.quantity == rec.INVALID_QUANTITY == 0xFFFF
    s.power_off()
    s.power_up(T0 + 2.0)
    assert s.biases.gyro == (0.0, 0.0, 0.0)


def test_a_capture_while_moving_is_off():
    config = MotionConfig()
    s = sensor(motion=Motion(config))
    [reply] = s.handle(cmd.capture_gyro_bias(2000), T0 + 1.0)
    assert math.dist(reply.record.bias, config.gyro_bias) > 0.01


def test_delta_and_update_records_follow_the_rate():
    s = sensor()
    now = T0 + 3.0
    [delta] = s.handle(cmd.encode_command(lay.DELTA_ANGLE_VELOCITY), now)
    [rate] = s.handle(cmd.encode_command(lay.ACCEL_ANG_RATE), now)
    assert delta.record.delta_angle == pytest.approx(
        [w * 0.01 for w in rate.record.angular_rate], abs=1e-4)
    assert delta.record.delta_velocity == pytest.approx(
        [a * 0.01 for a in rate.record.accel], abs=1e-4)
    [update] = s.handle(cmd.encode_command(lay.ORIENTATION_UPDATE_MATRIX), now)
    c = update.record.matrix
    assert matmul(c, transpose(c)) == pytest.approx((1, 0, 0, 0, 1, 0, 0, 0, 1), abs=1e-6)
    assert c == pytest.approx((1, 0, 0, 0, 1, 0, 0, 0, 1), abs=0.005)
    [euler] = s.handle(cmd.encode_command(lay.EULER_ANGLES), now)
    [matrix] = s.handle(cmd.encode_command(lay.ORIENTATION_MATRIX), now)
    assert (euler.record.roll, euler.record.pitch, euler.record.yaw) == pytest.approx(
        euler_from_matrix(matrix.record.matrix), abs=1e-5)


def test_temperatures_ping_and_link_quality():
    s = sensor()
    [temps] = s.handle(cmd.encode_command(lay.TEMPERATURES), T0 + 1.0)
    assert temps.record.accel_celsius == pytest.approx(25.0, abs=1.0)
    assert s.ping_reply(95) == b'\x02' and s.ping_reply(96) == b'\x21'
    quality = [s.link_quality() for _ in range(500)]
    assert all(0 <= lqi <= 255 and 0 <= rssi <= 255 for lqi, rssi in quality)
    assert len(set(quality)) > 10, 'LQI and RSSI vary'


def test_seeded_sensors_are_reproducible():
    a, b = sensor(seed=9), sensor(seed=9)
    for k in range(20):
        now = T0 + 0.1 * k
        [ra] = a.handle(cmd.encode_command(0xCC), now)
        [rb] = b.handle(cmd.encode_command(0xCC), now)
        assert ra.data == rb.data
