"""Calibration recovers known parameters from simulated data."""

import numpy as np
import pytest

from mpu9250_ahrs.reference.calibration import (accel_six_pose, asa_sensitivity, estimate_noise,
                                                gyro_bias, kalman_params_from_noise,
                                                mag_ellipsoid)
from mpu9250_ahrs.reference.frames import euler_to_quat, quat_to_matrix
from mpu9250_ahrs.sim.models.motion import SensorModel, earth_field, random_motion, static


def test_gyro_bias():
    sensor = SensorModel(gyro_noise=0.01, gyro_bias=(0.02, -0.03, 0.005), seed=1)
    gyr, _, _ = sensor.measure(static(duration=20))
    bias, err = gyro_bias(gyr)
    assert np.allclose(bias, [0.02, -0.03, 0.005], atol=4 * err.max())


def test_accel_six_pose():
    sensor = SensorModel(accel_bias=(0.3, -0.2, 0.5), accel_scale=(1.02, 0.98, 1.01),
                         accel_noise=0.01, seed=2)
    poses = {"+x": (0, -90, 0), "-x": (0, 90, 0), "+y": (90, 0, 0), "-y": (-90, 0, 0),
             "+z": (0, 0, 0), "-z": (180, 0, 0)}
    means = {k: sensor.measure(static(e, duration=2))[1].mean(0) for k, e in poses.items()}
    offset, scale = accel_six_pose(means)
    assert np.allclose(offset, [0.3, -0.2, 0.5], atol=0.01)
    assert np.allclose(scale, [1.02, 0.98, 1.01], atol=0.002)


def test_mag_ellipsoid_recovers_hard_and_soft_iron():
    soft = np.array([[1.10, 0.05, -0.02], [0.05, 0.92, 0.03], [-0.02, 0.03, 1.00]])
    sensor = SensorModel(hard_iron=(12.0, -7.0, 25.0), soft_iron=soft, mag_noise=0.2,
                         earth_field_ut=earth_field(50, 60), seed=3)
    _, _, mag = sensor.measure(random_motion(120, seed=5, max_rate_dps=150))
    cal = mag_ellipsoid(mag, intensity=50)
    assert np.allclose(cal.offset, [12, -7, 25], atol=0.3)
    assert np.allclose(cal.matrix, np.linalg.inv(soft) * 1.0, atol=0.02)
    assert cal.spread_percent < 1.0
    raw = SensorModel(hard_iron=(12.0, -7.0, 25.0), soft_iron=soft, seed=3)
    assert mag_ellipsoid(raw.measure(random_motion(60, seed=6))[2], 50).spread_percent < 0.05


def test_mag_ellipsoid_rejects_too_little_data():
    with pytest.raises(ValueError, match="at least 9"):
        mag_ellipsoid(np.ones((5, 3)))


def test_asa_sensitivity():
    assert np.allclose(asa_sensitivity([128, 0, 255]), [1.0, 0.5, 1.49609375])


def test_noise_estimation_and_kalman_parameters():
    sensor = SensorModel(gyro_noise=np.radians(0.1), accel_noise=0.05, seed=4)
    gyr, acc, mag = sensor.measure(static((10, 0, 0), duration=60))
    noise = estimate_noise(np.degrees(gyr), acc)
    assert np.allclose(noise["gyro_std"], 0.1, rtol=0.05)
    assert np.allclose(noise["accel_std"], 0.05, rtol=0.05)
    params = kalman_params_from_noise(np.degrees(gyr), acc, 0.01)
    assert params.r == pytest.approx(np.degrees(0.05 / 9.81) ** 2, rel=0.15)
    assert params.q_angle == pytest.approx((0.1 * 0.01) ** 2, rel=0.1)
