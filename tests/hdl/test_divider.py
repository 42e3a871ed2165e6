"""Divider against the fixed-point reference (``div_q24``), bit for bit: saturation edges,
negative numerators, a zero or negative denominator, random pairs. (Every input at 8 bits:
``tests/formal/test_divider.py``.)"""

import numpy as np

from mpu9250_ahrs.hdl.engine.divider import Divider, divider_word
from mpu9250_ahrs.reference.fixed_point import Status, div_q24

from .start_done import operate, run_unit


def test_divider_against_reference():
    rng = np.random.default_rng(6)
    cases = [(1, 0), (5, -3), (-(2 ** 31), 1), (2 ** 31 - 1, 1), (2 ** 31 - 1, 2 ** 31 - 1),
             (-(2 ** 31), 2 ** 31 - 1), (0, 5), (-7, 3), (3, 7), (2 ** 24, 2 ** 17),
             (2 ** 24, 2 ** 17 + 1), (-(2 ** 24), 2 ** 17 + 1),
             # the saturation edges: 127·2²⁴ fits, 128·2²⁴ = 2³¹ does not; −128·2²⁴ = −2³¹ fits
             (127, 1), (128, 1), (-128, 1), (-129, 1), (-1, 1), (-1, 2 ** 31 - 1), (-6, 3)]
    cases += [tuple(int(v) for v in (rng.integers(-2 ** 31, 2 ** 31), rng.integers(1, 2 ** 31)))
              for _ in range(15)]
    cases += [(int(rng.integers(-2 ** 26, 2 ** 26)), int(rng.integers(2 ** 20, 2 ** 28)))
              for _ in range(15)]
    dut = Divider()

    async def testbench(ctx):
        for num, den in cases:
            await operate(ctx, dut, num=num, den=den)
            st = Status()
            want = div_q24(num, den, st)
            assert ctx.get(divider_word(dut, 1)) == want, f"div({num}, {den})"
            assert ctx.get(dut.saturated) == st.saturated, f"div({num}, {den}) flag"
    run_unit(dut, testbench)
