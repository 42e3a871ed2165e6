"""The fixed-point Madgwick filter's normalisation (``madgwick_fixed._unit``): the Newton step
from the last inverse length when the length has hardly changed, afresh otherwise, and no
overflow (no ``saturated`` flag) on the jumps a free fall and a landing make."""

import math

import numpy as np

from mpu9250_ahrs.reference import madgwick_fixed as mf
from mpu9250_ahrs.reference.fixed_point import Status


def unit(v, seed):
    """(unit vector, seed, took the division) of ``_unit``, counting its divisions."""
    calls = []
    divide = mf.div_q24

    def counted(*args):
        calls.append(args)
        return divide(*args)
    mf.div_q24 = counted
    try:
        st = Status()
        u, keep = mf._unit(v, seed, st)
    finally:
        mf.div_q24 = divide
    assert not st.saturated, (v, seed)
    return u, keep, bool(calls)


def length_error(u):
    return abs(math.sqrt(sum(c * c for c in u)) / 2 ** 30 - 1)


def test_newton_step_at_rest_afresh_after_a_change():
    rng = np.random.default_rng(3)
    seed, afresh = 0, []
    for k in range(200):
        scale = 1.0 if k < 100 else 1.1             # a 10 % step in length at sample 100
        v = [int(round(c)) for c in scale * np.array([300.0, -1200.0, 1700.0])
             + rng.normal(0, 6, 3)]                 # ±16 g counts, noise as a MPU9250's
        u, seed, divided = unit(v, seed)
        afresh.append(divided)
        # afresh: the short CORDICs' 3·10⁻⁵; Newton: 0.15 % at its bounds, here far less
        assert length_error(u) < (1e-4 if k in (0, 100) else 5e-4), (k, length_error(u))
    # afresh on the first call (no seed) and at the step, the Newton step otherwise
    assert [k for k, d in enumerate(afresh) if d] == [0, 100]


def test_bounds_of_the_newton_step():
    """|v·seed|² within 1/16 of one takes the Newton step; beyond, the division."""
    v = [0, 0, 4096]
    _, exact, _ = unit(v, 0)
    for ratio, newton in ((1.03, True), (0.97, True), (1.04, False), (0.96, False)):
        u, _, divided = unit(v, int(exact * ratio))
        assert divided != newton, ratio
        assert length_error(u) < 2e-3


def test_free_fall_then_landing_does_not_overflow():
    """A seed is kept only from a vector over 128 counts: a free fall's few counts leave none,
    so the landing's long vector is normalised afresh, without an overflow. (A vector under
    32 counts saturates the division, and is flagged so, as it always was.)"""
    seed = 0
    vectors = [[0, 0, 2048]] * 3 + [[40, 20, -60], [50, -60, 70]] + [[30000, -20000, 32000]] * 2
    for v in vectors:
        u, seed, _ = unit(v, seed)
        assert length_error(u) < 2e-3, v
    assert 0 < seed < mf.SEED_LIMIT
