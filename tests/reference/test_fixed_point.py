"""Fixed-point golden models against the float filters, and their primitives."""

import glob
import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mpu9250_ahrs.reference.complementary import complementary_filter
from mpu9250_ahrs.reference.fixed_point import (ATAN_TABLE, CORDIC_GAIN, bam_to_deg,
    complementary_fixed, cordic_rotate, cordic_vector, deg_to_bam, div_floor, kalman_fixed,
    rshift_round, wrap32)
from mpu9250_ahrs.hdl.contract.numeric_contract import KalmanFixedConfig
from mpu9250_ahrs.reference.kalman import KalmanParams, kalman_filter
from mpu9250_ahrs.sim.models.motion import SensorModel, concat, random_motion, static, turntable
from mpu9250_ahrs.reference.recording import load_broad, quantise

LSB = 16.4


def angle_diff(a_deg, b_deg):
    return np.abs((np.asarray(a_deg) - np.asarray(b_deg) + 180) % 360 - 180)


def both_kalman(gc, ac, mc, dt):
    th, b = kalman_fixed(gc, ac, mc, KalmanFixedConfig(dt=dt))
    ef, bf, _ = kalman_filter(gc / LSB, ac.astype(float), mc.astype(float), dt,
                              KalmanParams(rates="body"))
    return bam_to_deg(th), ef, b / 65536 / LSB, bf


def both_complementary(gc, ac, mc, dt, a=0.98):
    ec, _ = complementary_filter(gc / LSB, ac.astype(float), mc.astype(float), dt, a=a,
                                 rates="body")
    return bam_to_deg(complementary_fixed(gc, ac, mc, dt=dt, a=a)), ec


# -- primitives --------------------------------------------------------------------------------

def test_rounding_and_wrap_rules():
    assert [rshift_round(x, 2) for x in (5, 6, -5, -6, -7)] == [1, 2, -1, -1, -2]
    assert wrap32(2 ** 31) == -2 ** 31 and wrap32(-2 ** 31 - 1) == 2 ** 31 - 1
    assert div_floor(7, 2, 0) == 3 and div_floor(-7, 2, 0) == -4
    assert deg_to_bam(180) == -2 ** 31 and deg_to_bam(-90) == -2 ** 30
    assert ATAN_TABLE[0] == 2 ** 29                      # atan(1) = 45° = 2²⁹ BAM


@settings(max_examples=300, deadline=None)
@given(st.integers(-2 ** 23, 2 ** 23), st.integers(-2 ** 23, 2 ** 23))
def test_cordic_vector_matches_atan2(x, y):
    angle, mag = cordic_vector(x, y)
    if x == 0 and y == 0:
        assert (angle, mag) == (0, 0)
        return
    r = math.hypot(x, y)
    tol = 0.002 + math.degrees(24 / r)                    # LSB-limited for tiny vectors
    assert angle_diff(bam_to_deg(angle), math.degrees(math.atan2(y, x))) <= tol
    assert abs(mag / CORDIC_GAIN - r) <= 30


@settings(max_examples=300, deadline=None)
@given(st.integers(-2 ** 31, 2 ** 31 - 1))
def test_cordic_rotate_matches_sin_cos(angle):
    c, s = cordic_rotate(angle)
    t = math.radians(bam_to_deg(angle))
    # 16 iterations leave at most atan(2⁻¹⁵) = 3.05e-5 rad of angle
    assert abs(c / 2 ** 30 - math.cos(t)) < 3.5e-5 and abs(s / 2 ** 30 - math.sin(t)) < 3.5e-5


# -- filters against float -----------------------------------------------------------------------

SENSOR = SensorModel(gyro_noise=np.radians(0.05), accel_noise=0.02, mag_noise=0.3,
                     gyro_bias=np.radians([0.3, -0.2, 0.1]), seed=7)


def test_simulated_motion():
    traj = concat(static((35, 0, 20), 20), turntable((1, 0, 0), 30, 3),
                  random_motion(20, seed=1, max_rate_dps=100, max_acc=1),
                  static((-20, 10, 170), 10))
    gc, ac, mc = SENSOR.counts(traj)
    fx, fl, bx, bl = both_kalman(gc, ac, mc, traj.dt)
    assert angle_diff(fx, fl).max() < 0.01
    assert np.abs(bx - bl).max() < 0.005                   # °/s
    # static 35° tilt (issue 5's figure): the last second of the first pose
    # (the target is 0.05°; 16 CORDIC iterations leave up to 0.0018° each)
    assert angle_diff(fx[1900:2000], fl[1900:2000]).max() < 0.005
    cx, cl = both_complementary(gc, ac, mc, traj.dt)
    assert angle_diff(cx, cl).max() < 0.01


# Derandomised: a random draw can put a yaw innovation on the ±180° wrap, where one LSB decides
# its sign and the fixed and float filters turn opposite ways (seed 226834315: 0.14° at sample
# 12, see test_innovation_tie_at_180); a CI run must not fail by the luck of the draw.
@settings(max_examples=15, deadline=None, derandomize=True)
@given(st.integers(0, 2 ** 32 - 1))
def test_random_inputs(seed):
    rng = np.random.default_rng(seed)
    n = 200
    gc = rng.integers(-3000, 3000, (n, 3))
    ac = rng.integers(-32768, 32768, (n, 3))
    mc = rng.integers(-2000, 2000, (n, 3))
    fx, fl, _, _ = both_kalman(gc, ac, mc, 0.01)
    # Random vectors put roll/pitch anywhere; the two must still agree closely.
    assert angle_diff(fx, fl).max() < 0.05


def test_innovation_tie_at_180():
    """The one known kind of larger difference: a yaw innovation on the ±180° wrap. Roll and
    pitch still agree; yaw differs by the gain times the turn, and only there."""
    rng = np.random.default_rng(226834315)
    gc = rng.integers(-3000, 3000, (200, 3))
    ac = rng.integers(-32768, 32768, (200, 3))
    mc = rng.integers(-2000, 2000, (200, 3))
    fx, fl, _, _ = both_kalman(gc, ac, mc, 0.01)
    d = angle_diff(fx, fl)
    assert d[:, :2].max() < 0.05 and d[:12].max() < 0.05
    assert 0.05 < d[12, 2] < 0.2


@pytest.mark.parametrize("euler", [(0, 89.9, 0), (0, -89.9, 30), (0, 0, 179.95),
                                   (0, 0, -179.95), (20, -30, 180)])
def test_edge_poses(euler):
    """±90° pitch and headings either side of ±180°."""
    gc, ac, mc = SENSOR.counts(static(euler, 10))
    fx, fl, _, _ = both_kalman(gc, ac, mc, 0.01)
    assert angle_diff(fx[:, 1], fl[:, 1]).max() < 0.01     # pitch
    # Near ±90° pitch roll is undefined (ay, az are noise), the Euler yaw wanders by tens of
    # degrees and rounding differences grow along it: the two still agree, more loosely.
    near_lock = abs(euler[1]) > 80
    assert angle_diff(fx[:, 2], fl[:, 2]).max() < (0.1 if near_lock else 0.01)
    if not near_lock:
        assert angle_diff(fx[:, 0], fl[:, 0]).max() < 0.01
    # against the pose itself after 10 s (sensor noise; the yaw converges at the filter's
    # Kalman gain): pitch within 0.1°, yaw within 0.75° (measured 0.46-0.61°)
    assert angle_diff(fx[-1, 1], euler[1]).max() < 0.1
    if abs(euler[1]) < 80:
        assert angle_diff(fx[-1, 2], euler[2]) < 0.75      # no spin through 0° at the wrap


def test_full_scale_and_zero_vectors():
    n = 300
    gc = np.tile([32767, -32768, 32767], (n, 1))
    ac = np.tile([-32768, 32767, -32768], (n, 1))
    mc = np.tile([32760, -32760, 32760], (n, 1))
    ac[100:150] = 0                                        # free fall: no tilt update
    mc[200:250] = 0                                        # dead magnetometer: no yaw update
    fx, fl, _, _ = both_kalman(gc, ac, mc, 0.01)
    assert np.all(np.isfinite(fl)) and angle_diff(fx, fl).max() < 0.05
    cx, cl = both_complementary(gc, ac, mc, 0.01, a=0.98)
    d = angle_diff(cx, cl)
    assert d[:, :2].max() < 0.05
    # Spinning at full scale (20° a sample) the yaw innovation passes through ±180°, where one
    # LSB decides which way it wraps: there the two yaws part by (1 − a)·360° = 7.2° and then
    # converge again. Up to the first such tie they agree; the parting is exactly one tie.
    tie = np.argmax(d[:, 2] > 1) if (d[:, 2] > 1).any() else n
    assert d[:tie, 2].max() < 0.05
    if tie < n:
        assert abs(d[tie, 2] - d[tie - 1, 2] - 0.02 * 360) < 0.05


RECORDINGS = sorted(glob.glob("../shared/data/broad/*.hdf5")) or \
    sorted(glob.glob(str(__import__("pathlib").Path(__file__).resolve().parents[3]
                         / "shared/data/broad/*.hdf5")))


@pytest.mark.skipif(not RECORDINGS, reason="shared/data/broad not beside the checkout")
def test_recorded_stretch():
    rec = load_broad(RECORDINGS[0])
    gc, ac, mc = quantise(rec.gyr[:6000], rec.acc[:6000], rec.mag[:6000])
    fx, fl, _, _ = both_kalman(gc, ac, mc, rec.dt)
    assert angle_diff(fx, fl).max() < 0.05
