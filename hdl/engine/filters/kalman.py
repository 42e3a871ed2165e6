"""The per-axis Kalman filter (``reference.fixed_point._KalmanFixed``, as the engine model
steps it): two states (angle, bias) per axis, predicted with the gyro and corrected by
the accelerometer's tilt and the magnetometer's heading. Its run-time registers (``Q_ANGLE``,
``Q_BIAS``, ``R``, ``P0``, ``BIAS_SCALE``) and state predate the registry: they are in the
base map (``hdl/engine/register_map.py``)."""

from ..attitude_isa import Q14, Q24, Q30, Cond, Flag
from .shared import (background_divisions, euler_rates, heading, magnetometer_in, step_n,
                     tilt)


__all__ = ["CONFIG_REGISTERS", "REGISTERS", "emit"]

CONFIG_REGISTERS = ()       # run-time registers from 0x70: none (its own are in the base map)
REGISTERS = ()              # state and working registers beyond the base map: none


def _gains(r, i, s, k0, k1):
    """The divisions of axis ``i``'s gains, (d, a, b) each: k0 = P00 / s (Q0.24) and k1 = P10 / s
    (Q8.24), ``s`` = P00 + R (``_innovation_sum``)."""
    return [(k0, r[f"P{i}_00"], s), (k1, r[f"P{i}_10"], s)]


def _innovation_sum(asm, r, i, s):
    asm.add(s, r[f"P{i}_00"], r["R"])


def _kalman_update(asm, r, i, z, k0, k1, before_k1=None):
    """Axis ``i``'s measurement update with its gains in ``k0``, ``k1`` (``_gains``). With
    ``before_k1`` (the start and the collect of a division made in the background, k1's),
    what needs k0 only is done while it runs."""
    with asm.scratch(7) as T:
        th, b = r[f"THETA{i}"], r[f"BIAS{i}"]
        p00, p01, p10, p11 = (r[f"P{i}_{e}"] for e in ("00", "01", "10", "11"))
        y, t0, t1, t10, t11, kth, kb = T
        if before_k1 is not None:
            before_k1[0]()
        asm.sub(y, z, th, wrap=True)                         # innovation y
        # the products in one run (a MUL followed by a MUL that does not read its result
        # takes one cycle, by anything else three), then the sums; k0's first
        asm.mul(kth, k0, y, Q24)
        asm.mul(t0, k0, p00, Q24)
        asm.mul(t1, k0, p01, Q24)
        if before_k1 is not None:
            before_k1[1]()
        asm.mul(kb, k1, y, Q24)                              # k1·y, BAM/s
        asm.mul(t10, k1, p00, Q24)
        asm.mul(t11, k1, p01, Q24)
        asm.mul(kb, kb, r["BIAS_SCALE"], Q24)
        asm.add(th, th, kth, wrap=True)
        asm.add(b, b, kb)
        asm.sub(p00, p00, t0)
        asm.sub(p01, p01, t1)
        asm.sub(p10, p10, t10)
        asm.sub(p11, p11, t11)


def _measurements(asm, r):
    """The tilt and heading measurements and the updates they feed. The gains' divisions are
    made in the background (``attitude_isa``) of what does not need them: axis 0's while the
    tilt is vectored and axis 1's while axis 0 is updated (both on an accelerometer
    measurement), axis 2's (on a field) while the heading is computed. The heading uses the
    predicted roll and pitch, so axis 2 is updated first; the axes' updates are independent."""
    # Each innovation sum before the branch that skips its update: the division after it reads
    # it as b, which the word just before it cannot write (``attitude_isa``: a NOP, a ROM word
    # the ROM has not to spare, would go between them)
    with asm.scratch(2) as (k0_0, k1_0):
        with asm.scratch(1) as (s,):
            _innovation_sum(asm, r, 0, s)
            # without a tilt, straight to the field's part (``magnetometer_in``, which
            # follows the tilt: a branch of its own there would cost a ROM word)
            asm.br("magnetometer", Cond.A_ZERO, a=r["ACC_OK"])
            tilt(asm, r, r["MEAS0"], divisions=_gains(r, 0, s, k0_0, k1_0))
        magnetometer_in(asm, "kalman")    # the field from here on (the early start)
        with asm.scratch(3) as (s, k0_2, k1_2):
            _innovation_sum(asm, r, 2, s)
            asm.br("k_no_heading", Cond.A_ZERO, a=r["MAG_OK"])
            heading(asm, r, r["THETA0"], r["THETA1"], r["MEAS2"],      # the predicted tilt
                    divisions=_gains(r, 2, s, k0_2, k1_2))
            _kalman_update(asm, r, 2, r["MEAS2"], k0_2, k1_2)
        asm.setf(Flag.MAG_USED)
        asm.setf(Flag.BIAS_UPDATED)
        asm.label("k_no_heading")
        with asm.scratch(3) as (s, k0_1, k1_1):
            _innovation_sum(asm, r, 1, s)
            asm.br("angles_out", Cond.A_ZERO, a=r["ACC_OK"])
            k0, k1 = background_divisions(asm, _gains(r, 1, s, k0_1, k1_1))
            k0[0]()
            _kalman_update(asm, r, 0, r["MEAS0"], k0_0, k1_0)
            k0[1]()
            _kalman_update(asm, r, 1, r["MEAS1"], k0_1, k1_1, before_k1=k1)
        asm.setf(Flag.ACC_USED)
        asm.setf(Flag.BIAS_UPDATED)
        asm.br("angles_out")


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
    _measurements(asm, r)
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

