"""The per-axis Kalman filter (``reference.fixed_point._KalmanFixed``, as the engine model
steps it): two states (angle, bias) per axis, predicted with the gyro and corrected by
the accelerometer's tilt and the magnetometer's heading. Its run-time registers (``Q_ANGLE``,
``Q_BIAS``, ``R``, ``P0``, ``BIAS_SCALE``) and state predate the registry: they are in the
base map (``hdl/register_map.py``)."""

from ..attitude_isa import Q14, Q24, Q30, Cond, Flag
from .shared import euler_rates, heading, step_n, tilt, zero_tests


__all__ = ["CONFIG_REGISTERS", "REGISTERS", "emit"]

CONFIG_REGISTERS = ()       # run-time registers from 0x70: none (its own are in the base map)
REGISTERS = ()              # state and working registers beyond the base map: none


def _kalman_update(asm, r, i, z):
    with asm.scratch(12) as T:
        th, b = r[f"THETA{i}"], r[f"BIAS{i}"]
        p00, p01, p10, p11 = (r[f"P{i}_{e}"] for e in ("00", "01", "10", "11"))
        asm.add(T[4], p00, r["R"])                           # s
        asm.div(T[5], p00, T[4])                             # k0, Q0.24
        asm.div(T[6], p10, T[4])                             # k1, Q8.24
        asm.sub(T[7], z, th, wrap=True)                      # innovation y
        # the products in one run (a MUL followed by a MUL that does not read its result
        # takes one cycle, by anything else three), then the sums
        asm.mul(T[8], T[5], T[7], Q24)
        asm.mul(T[9], T[6], T[7], Q24)                        # k1·y, BAM/s
        asm.mul(T[0], T[5], p00, Q24)
        asm.mul(T[1], T[5], p01, Q24)
        asm.mul(T[10], T[6], p00, Q24)
        asm.mul(T[11], T[6], p01, Q24)
        asm.mul(T[9], T[9], r["BIAS_SCALE"], Q24)
        asm.add(th, th, T[8], wrap=True)
        asm.add(b, b, T[9])
        asm.sub(p00, p00, T[0])
        asm.sub(p01, p01, T[1])
        asm.sub(p10, p10, T[10])
        asm.sub(p11, p11, T[11])


def emit(asm, r):
    """The routine, from the calibrated sample to QOUT, THETA and BIAS."""
    # the first sample after a reset takes ω₍ₖ₋₁₎ = ωₖ: out of line (FIRST is decided as the
    # branch is fetched: one cycle, taken or not)
    asm.br("k_first", Cond.FIRST)
    asm.label("k_predict")
    step_n(asm, r, "RATE")
    # the three axes interleaved, so that products follow products: a MUL followed by a MUL
    # that does not read its result takes one cycle instead of two
    P = [[r[f"P{i}_{e}"] for e in ("00", "01", "10", "11")] for i in range(3)]
    # the Euler-rate transform out of line (after the routine), so that body rates, the
    # default, fall through: a branch on a register costs three bubbles when taken. U first:
    # the transform takes four more scratch registers before TP and D live
    asm.br("k_euler", Cond.A_ZERO, a=r["EULER_RATES"], inv=True)
    with asm.scratch(3) as U:
        body_u = list(U)
        _summed_rates(asm, r, U)
        asm.label("k_body_rates")
        with asm.scratch(6) as T:
            TP, D = T[0:3], T[3:6]
            for i in range(3):
                asm.sub(U[i], U[i], r[f"BIAS{i}"])           # u = avg rate − bias, Q16 counts
            for i in range(3):
                asm.mul(U[i], U[i], r["STEP_N"], Q30)
            for i in range(3):
                asm.mul(TP[i], r["T"], P[i][3], Q24)              # T·P11
            for i in range(3):
                asm.add(r[f"THETA{i}"], r[f"THETA{i}"], U[i], wrap=True)
                asm.add(r[f"PREV{i}"], r[f"G{i}"], r["ZERO"])
                asm.sub(D[i], TP[i], P[i][2])
                asm.sub(D[i], D[i], P[i][1])
            for i in range(3):
                asm.mul(D[i], r["T"], D[i], Q24)
            for i in range(3):
                p00, p01, p10, p11 = P[i]
                asm.add(p00, p00, D[i])
                asm.add(p00, p00, r["Q_ANGLE"])
                asm.sub(p01, p01, TP[i])
                asm.sub(p10, p10, TP[i])
                asm.add(p11, p11, r["Q_BIAS"])
    zero_tests(asm, r, "k")
    asm.br("k_no_tilt", Cond.A_ZERO, a=r["ACC_OK"])
    tilt(asm, r, r["MEAS0"])
    asm.label("k_no_tilt")
    asm.br("k_no_heading", Cond.A_ZERO, a=r["MAG_OK"])
    heading(asm, r, r["THETA0"], r["THETA1"], r["MEAS2"])    # with the predicted tilt
    asm.label("k_no_heading")
    asm.br("k_skip_rp", Cond.A_ZERO, a=r["ACC_OK"])
    _kalman_update(asm, r, 0, r["MEAS0"])
    _kalman_update(asm, r, 1, r["MEAS1"])
    asm.setf(Flag.ACC_USED)
    asm.setf(Flag.BIAS_UPDATED)
    asm.label("k_skip_rp")
    asm.br("angles_out", Cond.A_ZERO, a=r["MAG_OK"])
    _kalman_update(asm, r, 2, r["MEAS2"])
    asm.setf(Flag.MAG_USED)
    asm.setf(Flag.BIAS_UPDATED)
    asm.br("angles_out")
    asm.label("k_first")
    for i in range(3):
        asm.add(r[f"PREV{i}"], r[f"G{i}"], r["ZERO"])
    asm.br("k_predict")
    asm.label("k_euler")
    with asm.scratch(3) as U:
        # the same registers as at k_body_rates, where this joins (nothing else is held)
        assert list(U) == body_u
        _summed_rates(asm, r, U)
        euler_rates(asm, r, U, "k")
    asm.br("k_body_rates")


def _summed_rates(asm, r, U):
    """U = (ω₍ₖ₋₁₎ + ωₖ) << 15, Q16 counts: twice the average rate."""
    for i in range(3):
        asm.add(U[i], r[f"PREV{i}"], r[f"G{i}"])
    for i in range(3):
        asm.mul(U[i], U[i], r["SHL15"], Q14)              # << 15 (exact: |ω| < 2¹⁶)

