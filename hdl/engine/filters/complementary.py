"""The complementary filter: each angle the gyro's prediction blended with the accelerometer's
tilt and the magnetometer's heading, a = τ/(τ + dt) (``ONE_MINUS_A`` = 1 − a; in the base map,
``hdl/engine/register_map.py``, as its state)."""

from ..attitude_isa import Q14, Q24, Q30, Cond, Flag
from .shared import euler_rates, heading, magnetometer_in, step_n, tilt


__all__ = ["CONFIG_REGISTERS", "REGISTERS", "emit"]

CONFIG_REGISTERS = ()
REGISTERS = ()


def emit(asm, r):
    """The routine, from the calibrated sample to QOUT, THETA and BIAS."""
    step_n(asm, r, "RATE")
    asm.br("c_euler", Cond.A_ZERO, a=r["EULER_RATES"], inv=True)
    # the three axes side by side, so that products follow products (a MUL followed by a MUL
    # that does not read its result takes one cycle, by anything else three)
    with asm.scratch(3) as T:
        for i in range(3):
            asm.mul(T[i], r[f"G{i}"], r["STEP_N"], Q14)                 # ω·RATE·n >> 14
        for i in range(3):
            asm.add(r[f"PRED{i}"], r[f"THETA{i}"], T[i], wrap=True)
            asm.add(r[f"PREV{i}"], r[f"G{i}"], r["ZERO"])
        asm.label("c_predicted")
        asm.add(r["MEAS0"], r["PRED0"], r["ZERO"])
        asm.add(r["MEAS1"], r["PRED1"], r["ZERO"])
        asm.br("c_no_tilt", Cond.A_ZERO, a=r["ACC_OK"])
        tilt(asm, r, r["MEAS0"])
        asm.setf(Flag.ACC_USED)
        asm.label("c_no_tilt")
        asm.add(r["MEAS2"], r["PRED2"], r["ZERO"])
        magnetometer_in(asm, "complementary")     # the field from here on (the early start)
        asm.br("c_blend", Cond.A_ZERO, a=r["MAG_OK"])
        heading(asm, r, r["PRED0"], r["PRED1"], r["MEAS2"])
        asm.setf(Flag.MAG_USED)
        asm.label("c_blend")
        for i in range(3):
            asm.sub(T[i], r[f"MEAS{i}"], r[f"PRED{i}"], wrap=True)
        for i in range(3):
            asm.mul(T[i], r["ONE_MINUS_A"], T[i], Q24)
        for i in range(3):
            asm.add(r[f"THETA{i}"], r[f"PRED{i}"], T[i], wrap=True)
        asm.br("angles_out")
    # out of line: the prediction with Euler-angle rates, in Q16 counts
    asm.label("c_euler")
    with asm.scratch(3) as U:
        for i in range(3):
            asm.mul(U[i], r[f"G{i}"], r["ONE"], Q14)                    # << 16
        euler_rates(asm, r, U, "c")
        for i in range(3):
            asm.mul(U[i], U[i], r["STEP_N"], Q30)
            asm.add(r[f"PRED{i}"], r[f"THETA{i}"], U[i], wrap=True)
            asm.add(r[f"PREV{i}"], r[f"G{i}"], r["ZERO"])
    asm.br("c_predicted")

