"""The multiplier's four-block decomposition is exact."""

from amaranth.sim import Simulator
from hypothesis import given, settings, strategies as st

from mpu9250_ahrs.hdl.primitives.multiplier import Multiplier


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(-2 ** 31, 2 ** 31 - 1), st.integers(-2 ** 31, 2 ** 31 - 1)),
                min_size=1, max_size=8))
def test_multiplier_from_18x18_blocks(pairs):
    """The four-block decomposition is exact, extremes included, and so are its two parts
    (what the multiply-accumulate registers)."""
    pairs = pairs + [(-2 ** 31, -2 ** 31), (-2 ** 31, 2 ** 31 - 1), (2 ** 17 - 1, -1)]
    dut = Multiplier()

    async def testbench(ctx):
        for a, b in pairs:
            ctx.set(dut.a, a)
            ctx.set(dut.b, b)
            assert ctx.get(dut.p) == a * b, f"{a} × {b}"
            assert ctx.get(dut.outer) + (ctx.get(dut.middle) << 17) == a * b, f"{a} × {b}"
    sim = Simulator(dut)
    sim.add_testbench(testbench)
    sim.run()
