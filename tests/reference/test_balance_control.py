"""The balance controller's fixed-point model (``reference/balance_control.py``): its
registers from the gains, its limits and saturations, and its trips (disarmed: duty 0 and the
state cleared)."""

import math
import random

import pytest

from mpu9250_ahrs.reference.balance_control import (DUTY_FULL, E_PER_RAD, BalanceFixed,
                                                    BalanceFixedConfig, BalanceGains)


def _armed(**gains):
    c = BalanceFixed(BalanceFixedConfig.from_gains(BalanceGains(**gains)))
    c.arm()
    return c


def _bam(deg):
    return round(math.radians(deg) * E_PER_RAD) << 16


def test_registers_from_the_gains():
    c = BalanceFixedConfig.from_gains(BalanceGains(kp=20, kd=1, ki=50, kv=2, tau_v=0.2))
    # kp: 20 duty/rad in the sum's units (1024·2⁸ per duty) per e unit (65536/2π per rad)
    assert c.kp == round(20 * 1024 * 256 / E_PER_RAD) == 503
    assert c.kd == round(1 * 1024 * 256 * math.radians(1 / 16.4)) == 279
    assert c.kv == 512 and c.kv_shift == 8 and c.cutoff == round(math.radians(30) * E_PER_RAD)
    with pytest.raises(ValueError, match="18 signed bits"):
        BalanceFixedConfig(kp=1 << 17)


def test_proportional_step_by_hand():
    c = _armed(kp=20, kd=0, ki=0, kv=0)
    e = round(math.radians(2) * E_PER_RAD)
    assert c.step(_bam(2), 0, 0) == (503 * e) >> 8


def test_duty_and_integral_are_bounded():
    c = _armed(kp=200, kd=5, ki=500, kv=2, out_limit=0.5, i_limit=0.01)
    rng = random.Random(3)
    for _ in range(5000):
        duty = c.step(_bam(rng.uniform(-29, 29)), rng.randrange(-32768, 32768),
                      rng.randrange(-1 << 31, 1 << 31))
        assert abs(duty) <= DUTY_FULL // 2 and abs(c.integral) <= c.config.i_limit


@pytest.mark.parametrize("trip", ["fallen", "fault", "stale"])
def test_trips_disarm_at_once_and_clear(trip):
    c = _armed(kp=20, kd=1, ki=50)
    for _ in range(10):
        assert c.step(_bam(5), 100, 0) > 0
    if trip == "fallen":
        duty = c.step(_bam(31), 0, 0)
    elif trip == "fault":
        duty = c.step(_bam(5), 0, 0, fault=True)
    else:
        for _ in range(c.config.stale):
            c.period()
        assert c.armed
        duty = c.period() and 0
    assert duty == 0 and not c.armed and c.tripped == trip
    assert (c.integral, c.w, c.duty) == (0, 0, 0)
    assert c.step(_bam(5), 100, 0) == 0                   # stays disarmed
    c.arm()
    assert c.armed and c.tripped is None and c.step(_bam(5), 100, 0) > 0


def test_a_negative_tilt_wraps_as_a_signed_angle():
    c = _armed(kp=20, kd=0, ki=0, kv=0)
    assert c.step(_bam(-2) & 0xFFFFFFFF, 0, 0) == c.step(_bam(-2), 0, 0) < 0
