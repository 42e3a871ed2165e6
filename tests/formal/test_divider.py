"""Divider, formally: equal to its definition for every input, at a reduced width.

The definition is ``reference.fixed_point.div_q24``'s: q = ⌊num·2^frac / den⌋ (towards −∞),
saturated to the width; a denominator ≤ 0 gives 0; both set ``saturated``. Here it is written
with Amaranth's ``//`` (floor division) on the full-width product, nothing shared with the
divider's non-restoring, negation-free loop. The divider is the same logic at any width
(``Divider(width=, frac=)``): 12/8 keeps the datapath's 8 integer bits.
"""

import pytest
from amaranth import *
from amaranth.asserts import AnyConst
from amaranth.hdl import Assert, Cover

from mpu9250_ahrs.hdl.engine.divider import Divider, divider_word
from mpu9250_ahrs.reference.fixed_point import div_q24

from .harness import counter, harness_module


pytestmark = pytest.mark.formal

WIDTH, FRAC = 8, 5


def divider_harness(width=WIDTH, frac=FRAC, dut=None):
    m = harness_module()
    m.submodules.dut = dut = dut or Divider(width=width, frac=frac)
    num, den = AnyConst(signed(width)), AnyConst(signed(width))
    cycle = counter(m, range(width + 8), name="cycle")     # the start is at cycle 0
    m.d.comb += [dut.num.eq(num), dut.den.eq(den), dut.start.eq(cycle == 0)]

    lo, hi = -(1 << (width - 1)), (1 << (width - 1)) - 1
    exact = Signal(signed(2 * width + frac))
    m.d.comb += exact.eq((num << frac) // den)
    want = Signal(signed(width))
    want_sat = Signal()
    with m.If(den <= 0):
        m.d.comb += [want.eq(0), want_sat.eq(1)]
    with m.Elif(exact > hi):
        m.d.comb += [want.eq(hi), want_sat.eq(1)]
    with m.Elif(exact < lo):
        m.d.comb += [want.eq(lo), want_sat.eq(1)]
    with m.Else():
        m.d.comb += want.eq(exact)

    # one quotient bit per cycle, plus the load; a denominator ≤ 0 is done at once
    latency = Mux(den <= 0, 1, width + 1)
    m.d.comb += Assert(dut.done == (cycle == latency), "latency")
    with m.If(dut.done):
        m.d.comb += [Assert(divider_word(dut, 1) == want, "quotient"),
                     Assert(dut.saturated == want_sat, "saturated")]
    with m.If(dut.done):
        m.d.comb += [
            Cover((num < 0) & (den > 0) & ~want_sat, "negative_numerator"),
            Cover(den < 0, "negative_divisor"),
            Cover(den == 0, "zero_divisor"),
            Cover((den > 0) & (exact > hi), "overflow_up"),
            Cover((den > 0) & (exact < lo), "overflow_down"),
        ]
    return m


def test_divider_equals_definition(formal):
    # every input (AnyConst) through one whole division: depth = latency + 2
    formal(divider_harness(), name="divider", mode="bmc", depth=WIDTH + 3)


def test_divider_cover(formal):
    formal(divider_harness(), name="divider_cover", mode="cover", depth=WIDTH + 3)


def test_definition_is_the_references():
    """The formula above, in Python, is ``div_q24`` at 32/24 (so the proof is about the
    reference's divider, not a look-alike)."""
    import random
    rng = random.Random(3)
    for _ in range(2000):
        num = rng.randrange(-(1 << 31), 1 << 31) >> rng.randrange(32)
        den = rng.randrange(-(1 << 31), 1 << 31) >> rng.randrange(32)
        if den <= 0:
            want = 0
        else:
            want = max(-(1 << 31), min((1 << 31) - 1, (num << 24) // den))
        assert div_q24(num, den) == want, (num, den)
