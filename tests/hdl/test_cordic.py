"""CORDIC against the fixed-point reference (``cordic_vector`` / ``cordic_rotate``), bit for
bit: edge vectors (zero, the axes, the corners of the 32-bit square) and random ones, angles
around ±90° and ±180°. (Every input at 8 bits: ``tests/formal/test_cordic.py``.)"""

import numpy as np

from mpu9250_ahrs.hdl.cordic import CORDIC
from mpu9250_ahrs.reference.fixed_point import Status, cordic_rotate, cordic_vector

from .start_done import operate, run_unit


def test_cordic_against_reference():
    rng = np.random.default_rng(5)
    vectors = [(0, 0), (-5, 0), (0, -7), (-(2 ** 31), -(2 ** 31)), (2 ** 31 - 1, 2 ** 31 - 1),
               (-(2 ** 31), 2 ** 31 - 1), (1, 0), (-1, -1)]
    vectors += [tuple(int(v) for v in rng.integers(-2 ** 31, 2 ** 31, 2)) for _ in range(12)]
    angles = [0, 2 ** 30, -2 ** 30, 2 ** 30 + 1, -(2 ** 31), 2 ** 31 - 1]
    angles += [int(v) for v in rng.integers(-2 ** 31, 2 ** 31, 10)]
    dut = CORDIC()

    async def testbench(ctx):
        for x, y in vectors:
            await operate(ctx, dut, x_in=x, y_in=y, mode=0)
            st = Status()
            want = cordic_vector(x, y, st)
            got = (ctx.get(dut.angle), ctx.get(dut.magnitude))
            assert got == want, f"vector({x}, {y}): {got} != {want}"
            assert ctx.get(dut.saturated) == st.saturated
        for a in angles:
            await operate(ctx, dut, angle_in=a, mode=1)
            got = (ctx.get(dut.cos), ctx.get(dut.sin))
            assert got == cordic_rotate(a), f"rotate({a}): {got} != {cordic_rotate(a)}"
    run_unit(dut, testbench)
