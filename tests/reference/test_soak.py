"""Per-axis filters at the sensor's own rates: coefficients in physical units, the published
preset reproduced at 100 Hz, and a short soak of the fixed-point Kalman filter against the float
one (the 10⁶-sample soaks are ``python -m mpu9250_ahrs.reference.soak``)."""

import pytest

from mpu9250_ahrs.hdl.contract.numeric_contract import FilterRates, KalmanFixedConfig
from mpu9250_ahrs.reference.soak import soak


def test_published_preset_at_its_own_rate():
    assert FilterRates().at(0.01).registers() == KalmanFixedConfig().registers()
    back = FilterRates.from_step(KalmanFixedConfig())
    assert back.at(0.01).registers() == KalmanFixedConfig().registers()


def test_per_step_values_scale_with_the_rate():
    slow, fast = FilterRates().at(0.01), FilterRates().at(0.001)
    assert fast.q_angle == pytest.approx(slow.q_angle / 10)
    assert fast.q_bias == pytest.approx(slow.q_bias / 10)
    assert fast.r == slow.r                                 # per measurement
    # the complementary filter keeps its time constant: a = τ/(τ + dt)
    assert fast.a * 0.001 / (1 - fast.a) == pytest.approx(0.49)
    with pytest.raises(ValueError):
        FilterRates(tau=0).at(0.01)


@pytest.mark.parametrize("rate", [1000, 8000])
def test_fixed_kalman_soak_no_saturation(rate):
    """20,000 samples (past the ~2,000 after which the per-step preset clamped at 1 kHz)."""
    result = soak(20_000, rate)
    assert result["saturated_results"] == 0
    assert max(result["max_diff_deg"]) <= 0.05, result


def test_per_step_preset_at_1khz_saturates():
    """What the issue found: the 100 Hz per-step values used at 1 kHz clamp the covariance."""
    per_step = FilterRates.from_step(KalmanFixedConfig(dt=0.001))
    assert soak(5_000, 1000, per_step)["saturated_results"] > 0


@pytest.mark.parametrize("rate", [100, 1000, 8000])
def test_flagship_at_every_supported_rate(rate):
    """The flagship's parameters are times in seconds: at 100 Hz, 1 kHz and 8 kHz the fixed-point
    filter (the engine's, bit for bit) stays with its float version and keeps the inclination
    of the synthetic motion, without a saturated result."""
    import numpy as np
    from mpu9250_ahrs.reference.engine_model import attitude_fixed
    from mpu9250_ahrs.reference.flagship import flagship_filter
    from mpu9250_ahrs.hdl.contract.numeric_contract import FlagshipFixedConfig
    from mpu9250_ahrs.reference.flagship_fixed import q30_to_float
    from mpu9250_ahrs.reference.frames import body_to_mag, quat_conj, quat_mul
    from mpu9250_ahrs.reference.soak import (ACCEL_LSB_PER_G, GYRO_LSB_PER_DPS, MAG_UT_PER_LSB,
                                             synthetic_motion)
    n = int(3 * rate)
    gc, ac, mc, valid, up = synthetic_motion(n, rate, seed=2, with_up=True)
    flagship = FlagshipFixedConfig(1 / rate, GYRO_LSB_PER_DPS * 180 / np.pi,
                                   ACCEL_LSB_PER_G / 9.80665)
    fixed = attitude_fixed(gc, ac, body_to_mag(mc), valid, select="flagship",
                           flagship=flagship)
    assert not fixed.saturated.any()
    qf = q30_to_float(fixed.quat)
    qr = flagship_filter(np.radians(gc / GYRO_LSB_PER_DPS), ac / ACCEL_LSB_PER_G * 9.80665,
                         mc * MAG_UT_PER_LSB, 1 / rate, mag_valid=valid)
    dq = quat_mul(quat_conj(qr), qf)
    gap = np.degrees(2 * np.arcsin(np.clip(np.linalg.norm(dq[:, 1:], axis=1), 0, 1)))
    assert np.sqrt(np.mean(gap ** 2)) < 0.05, np.sqrt(np.mean(gap ** 2))
    # inclination: the estimated up (ENU z in body axes) against the true one, after 1 s
    w, x, y, z = qf.T
    up_est = np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1)
    err = np.degrees(np.arccos(np.clip((up_est * up).sum(1), -1, 1)))[rate:]
    assert np.sqrt(np.mean(err ** 2)) < 2.0, np.sqrt(np.mean(err ** 2))
