import numpy as np
import pytest

from mpu9250_ahrs.reference.frames import (accel_tilt, euler_to_quat, mag_to_body, matrix_to_quat,
                                           orientation_errors, quat_from_accel_mag, quat_mul,
                                           quat_to_euler, quat_to_matrix, tilt_compensated_heading,
                                           wrap_angle)
from mpu9250_ahrs.sim.models.motion import earth_field

RNG = np.random.default_rng(3)
EULER = RNG.uniform([-np.pi, -1.5, -np.pi], [np.pi, 1.5, np.pi], (500, 3))
G_UP = np.array([0.0, 0.0, 9.81])


def body(q, v):
    return np.einsum("nji,j->ni", quat_to_matrix(q), v)


def test_euler_round_trip():
    q = euler_to_quat(EULER)
    assert np.abs(wrap_angle(quat_to_euler(q) - EULER)).max() < 1e-12


def test_matrix_round_trip():
    q = euler_to_quat(EULER)
    assert np.abs(np.abs(np.sum(matrix_to_quat(quat_to_matrix(q)) * q, axis=1)) - 1).max() < 1e-12


def test_tilt_and_heading_from_ideal_readings():
    q = euler_to_quat(EULER)
    acc, mag = body(q, G_UP), body(q, earth_field(48, 64))
    assert np.abs(wrap_angle(accel_tilt(acc) - EULER[:, :2])).max() < 1e-12
    yaw = tilt_compensated_heading(mag, EULER[:, 0], EULER[:, 1])
    assert np.abs(wrap_angle(yaw - EULER[:, 2])).max() < 1e-9


def test_yaw_convention_east_is_zero_north_is_90():
    facing_north = euler_to_quat(np.radians([0, 0, 90]))
    assert np.allclose(quat_to_matrix(facing_north) @ [1, 0, 0], [0, 1, 0])


def test_alignment_from_accel_and_mag():
    q = euler_to_quat(EULER)
    q2 = quat_from_accel_mag(body(q, G_UP), body(q, earth_field()))
    assert np.degrees(orientation_errors(q2, q)[:, 0]).max() < 1e-4


def test_error_metric_splits_heading_and_inclination():
    q = euler_to_quat(EULER[:5])
    yaw10 = euler_to_quat(np.radians([0, 0, 10]))
    e = np.degrees(orientation_errors(quat_mul(yaw10, q), q))        # earth-frame yaw error
    assert np.allclose(e[:, 0], 10) and np.allclose(e[:, 1], 10) and np.allclose(e[:, 2], 0)
    tilt = euler_to_quat(np.radians([7, 0, 0]))
    e = np.degrees(orientation_errors(quat_mul(tilt, q), q))
    assert np.allclose(e[:, 2], 7) and np.allclose(e[:, 1], 0, atol=1e-9)


def test_mag_axis_mapping():
    assert mag_to_body([1, 2, 3]).tolist() == [2, 1, -3]


def test_error_metric_is_of_rotations_whatever_the_norm():
    """A quaternion a little off unit norm (truth stored rounded, an estimate in fixed point)
    scores as the rotation it is: near zero error too, where |e_w| was clipped at 1."""
    rng = np.random.default_rng(1)
    q = euler_to_quat(rng.uniform(-180, 180, (200, 3)))
    small = euler_to_quat(rng.normal(0, 0.5, (200, 3)))             # errors of about 1°
    est = quat_mul(small, q)
    exact = np.degrees(orientation_errors(est, q))
    for scale in (1 - 1e-2, 1 - 1e-3, 1 - 1e-4, 1 + 1e-4, 1 + 1e-3, 1 + 1e-2):
        assert np.degrees(orientation_errors(est, q * scale)) == pytest.approx(exact, abs=1e-6)
        assert np.degrees(orientation_errors(est * scale, q)) == pytest.approx(exact, abs=1e-6)
