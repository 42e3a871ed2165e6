"""The multiply-accumulate unit against ``reference.fixed_point.mac``: chains of products
issued back to back, every shift, subtracted terms, extremes that saturate; the write-back two
cycles after the last issue."""

import numpy as np
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.engine.attitude_isa import MUL_SHIFTS
from mpu9250_ahrs.hdl.engine.multiply_accumulate import MultiplyAccumulate
from mpu9250_ahrs.reference.fixed_point import Status, mac


def test_chains_against_the_reference():
    rng = np.random.default_rng(7)
    big = [2 ** 31 - 1, -2 ** 31]
    chains = []
    for shift in MUL_SHIFTS:
        for length in (1, 2, 3, 4):
            terms = [(int(rng.integers(-2 ** 31, 2 ** 31)), int(rng.integers(-2 ** 31, 2 ** 31)),
                      int(rng.choice([1, -1]))) for _ in range(length)]
            chains.append((terms, shift))
        chains.append(([(big[0], big[0], 1), (big[1], big[1], 1)], shift))       # saturates
        chains.append(([(big[1], big[1], -1)], shift))
        chains.append(([(3, 5, 1), (-7, 11, -1)], shift))                         # small
    dut = MultiplyAccumulate()

    async def testbench(ctx):
        for terms, shift in chains:
            st = Status()
            want = mac(terms, shift, st)
            for i, (a, b, sign) in enumerate(terms):
                last = i == len(terms) - 1
                ctx.set(dut.a, a)
                ctx.set(dut.b, b)
                ctx.set(dut.ins, {"sh": MUL_SHIFTS.index(shift), "acc": i > 0, "neg": sign < 0,
                                  "wb": last, "d": 0x42 if last else 0})
                ctx.set(dut.issue, 1)
                await ctx.tick()
                # the term is being accumulated now; only the last will write back, next cycle
                assert ctx.get(dut.pending) and ctx.get(dut.wb_next) == last
                assert not ctx.get(dut.wb_en)
            ctx.set(dut.issue, 0)
            await ctx.tick()
            # latency 2: the chain's sum, shifted and saturated, two cycles after its last issue
            assert ctx.get(dut.wb_en) and ctx.get(dut.wb_addr) == 0x42
            got = (ctx.get(dut.wb_data), bool(ctx.get(dut.wb_saturated)))
            assert got == (want, st.saturated), (terms, shift)
            assert not ctx.get(dut.pending)
            await ctx.tick()
            assert not ctx.get(dut.wb_en)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
