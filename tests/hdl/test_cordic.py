"""CORDIC against the fixed-point reference (``cordic_vector`` / ``cordic_rotate``), bit for
bit: edge vectors (zero, the axes, the corners of the 32-bit square) and random ones, angles
around ±90° and ±180°. (Every input at 8 bits: ``tests/formal/test_cordic.py``.)"""

import numpy as np

from mpu9250_ahrs.hdl.engine.cordic import CORDIC, cordic_word
from mpu9250_ahrs.reference.fixed_point import (CORDIC_ITERATIONS, CORDIC_SHORT_ITERATIONS, Status,
                                                cordic_rotate, cordic_vector)

from .start_done import operate, run_unit


def test_cordic_against_reference():
    rng = np.random.default_rng(5)
    vectors = [(0, 0), (-5, 0), (0, -7), (-(2 ** 31), -(2 ** 31)), (2 ** 31 - 1, 2 ** 31 - 1),
               (-(2 ** 31), 2 ** 31 - 1), (1, 0), (-1, -1)]
    vectors += [tuple(int(v) for v in rng.integers(-2 ** 31, 2 ** 31, 2)) for _ in range(12)]
    angles = [0, 2 ** 30, -2 ** 30, 2 ** 30 + 1, -(2 ** 31), 2 ** 31 - 1]
    angles += [int(v) for v in rng.integers(-2 ** 31, 2 ** 31, 10)]
    dut = CORDIC()
    # the two results as the engine writes them (``cordic_word``)
    mag_sin, angle_cos = cordic_word(dut, 1, 0), cordic_word(dut, 0, 1)

    async def testbench(ctx):
        for short, n in ((0, CORDIC_ITERATIONS), (1, CORDIC_SHORT_ITERATIONS)):
            for x, y in vectors:
                await operate(ctx, dut, x_in=x, y_in=y, mode=0, short=short)
                st = Status()
                want = cordic_vector(x, y, st, n)
                got = (ctx.get(angle_cos), ctx.get(mag_sin))
                assert got == want, f"vector({x}, {y}), {n} iterations: {got} != {want}"
                assert ctx.get(dut.saturated) == st.saturated
        ctx.set(dut.short, 0)
        for a in angles:
            await operate(ctx, dut, angle_in=a, mode=1)
            got = (ctx.get(angle_cos), ctx.get(mag_sin))
            assert got == cordic_rotate(a), f"rotate({a}): {got} != {cordic_rotate(a)}"
            assert ctx.get(dut.saturated) == 0
    run_unit(dut, testbench)


def test_cordic_short_latency():
    """A short operation is done ``CORDIC_SHORT_ITERATIONS`` + 1 cycles after its start, a
    whole one ``CORDIC_ITERATIONS`` + 1 (the engine's VEC: 11 and 19 cycles)."""
    dut = CORDIC()
    took = []

    async def testbench(ctx):
        for short in (1, 0, 1):
            ctx.set(dut.x_in, 1000)
            ctx.set(dut.y_in, -3000)
            ctx.set(dut.mode, 0)
            ctx.set(dut.short, short)
            ctx.set(dut.start, 1)
            await ctx.tick()
            ctx.set(dut.start, 0)
            cycles = 1
            while not ctx.get(dut.done):
                await ctx.tick()
                cycles += 1
            took.append(cycles)
            await ctx.tick()
    run_unit(dut, testbench)
    assert took == [CORDIC_SHORT_ITERATIONS + 1, CORDIC_ITERATIONS + 1,
                    CORDIC_SHORT_ITERATIONS + 1]
