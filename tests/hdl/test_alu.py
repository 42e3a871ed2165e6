"""The engine's ALU against the reference's saturation and wrapping rules."""

import numpy as np
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.engine.alu import ALU
from mpu9250_ahrs.reference.fixed_point import Status, sat16, sat32, wrap32


def model(a, b, sub, wrap, to16):
    value = a - b if sub else a + b
    if wrap:
        return wrap32(value), False
    st = Status()
    value = sat32(value, st)
    if to16:
        value = sat16(value, st)
    return value, st.saturated


def test_alu_against_the_reference_rules():
    rng = np.random.default_rng(3)
    edges = [0, 1, -1, 2 ** 31 - 1, -2 ** 31, 2 ** 15 - 1, -2 ** 15, 2 ** 15, -2 ** 15 - 1]
    pairs = [(a, b) for a in edges for b in edges]
    pairs += [tuple(int(v) for v in rng.integers(-2 ** 31, 2 ** 31, 2)) for _ in range(40)]
    modes = [(sub, wrap, to16) for sub in (0, 1) for wrap in (0, 1) for to16 in (0, 1)]
    dut = ALU()

    async def testbench(ctx):
        for a, b in pairs:
            for sub, wrap, to16 in modes:
                for name, value in (("a", a), ("b", b), ("sub", sub), ("wrap", wrap),
                                    ("sat16", to16)):
                    ctx.set(getattr(dut, name), value)
                got = (ctx.get(dut.result), bool(ctx.get(dut.saturated)))
                assert got == model(a, b, sub, wrap, to16), (a, b, sub, wrap, to16)
    sim = Simulator(dut)
    sim.add_testbench(testbench)
    sim.run()
