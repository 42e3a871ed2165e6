"""Per-axis filters at the sensor's own rates: coefficients in physical units, the published
preset reproduced at 100 Hz, and a short soak of the fixed-point Kalman filter against the float
one (the 10⁶-sample soaks are ``python -m mpu9250_ahrs.reference.soak``)."""

import pytest

from mpu9250_ahrs.reference.fixed_point import FilterRates, KalmanFixedConfig
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
