"""Microcode of Madgwick's gradient-descent filter: ``reference.madgwick_fixed.MadgwickFixed``,
operation for operation, on the attitude engine (instruction set: ``hdl/engine/attitude_isa.py``).

Its quaternion is its state and its output (QOUT). Its working registers are the flagship's
(``_REGISTERS``): only one filter runs, and a switch to either restarts it (the flagship from
its start-up, Madgwick from its alignment), so neither finds the other's values in them. One
of them carries a value from a sample to the next: RM, R(q) of the output, which the next
gradient uses. Its own registers (``REGISTERS``) keep the inverse lengths of the last unit
vectors, which the next normalisations start from (``_unit``; a stale or zero one only sends
a normalisation the long way).

Cost: ``python -m mpu9250_ahrs report`` (``cycles_per_update.madgwick``).
"""

from ..attitude_isa import Q14, Q24, Q30, Cond, Flag
from .flagship import _PAIRS, _matrix, _normalise
from .shared import euler_quat, heading, magnetometer_in, matrix_angles, step_n, tilt


__all__ = ["CONFIG_REGISTERS", "REGISTERS", "emit"]

# Run-time registers (host-visible, from 0x70 after the flagship's): ``MadgwickFixedConfig``
CONFIG_REGISTERS = ("BETA_K",)
# the inverse lengths of the last accelerometer and field vectors normalised: the next
# normalisation's seeds (``_unit``), kept from a sample to the next
REGISTERS = ("M_SEED_A", "M_SEED_M")

# the routine's names -> the flagship's registers it works in (vectors and quaternions by
# prefix; pairs are a CORDIC's (d, d + 1))
_REGISTERS = {
    "HK": "F_C", "BN": "F_S", "TH": "F_V2", "RINV": "F_GAIN", "BY": "F_HORIZ",
    "P": "F_PHI", "P1": "F_TH", "P2": "F_CPHI", "P3": "F_CH", "BYP": "F_PSI", "YAW": "F_YAW",
    # ``_unit``'s working registers (not scratch: its out-of-line part, after END, shares them)
    "NU0": "F_SG", "NU1": "F_SA", "NU2": "F_SXY", "NUY": "F_CX",
}
_VECTORS = {"HV": "V", "S": "AI", "MH": "LP", "H": "GLP", "FA": "DG", "FM": "DA", "PB": "ALP",
            "QB": "BAND"}
_QUATERNIONS = {"QD": "QAG", "QN": "QT", "Q8": "QA", "GR": "QG"}


def _aliases(r):
    aliases = {name: r[base] for name, base in _REGISTERS.items()}
    for names, n in ((_VECTORS, 3), (_QUATERNIONS, 4)):
        for name, base in names.items():
            aliases.update({f"{name}{i}": r[f"{base}{i}"] for i in range(n)})
    assert not aliases.keys() & r.keys(), "a working name hides a register of the map"
    r = {**r, **aliases}
    for pair in ("P", "P1", "P2", "P3", "BYP", "YAW"):
        base = _REGISTERS[pair]
        assert r[base] + 1 == r[_PAIRS[_PAIRS.index(base) + 1]], f"{pair} is not a pair"
    return r


def _unit(asm, r, out, v, seed, name):
    """``out`` = ``v`` / |``v``| (three registers each, Q2.30 from counts): ``seed`` (the last
    inverse length y = 2³⁶/|v|) corrected by one Newton step, y·(3 − |v·y|²)/2, when |v·y|² is
    within 1/16 of one; else from two short vectoring CORDICs and one division, out of line.
    ``seed`` takes the new inverse length. Returns the out-of-line part's emitter, to be placed
    after the routine's END, so that the usual path falls through (a taken branch costs three
    cycles more)."""
    o = [r[f"{out}{i}"] for i in range(3)]
    u, y = [r["NU0"], r["NU1"], r["NU2"]], r["NUY"]
    for i in range(3):
        asm.mul(o[i], r[f"{v}{i}"], r["SHL8"], Q14)             # v·2⁸
    for i in range(3):
        asm.mul(u[i], r[f"{v}{i}"], seed, Q14)                  # v·y / 2¹⁴: v/|v| · 2²²
    asm.mac(u[0], [(c, c) for c in u], Q30)                    # |v·y|², Q.14
    asm.sub(u[1], u[0], r["UNIT_LO"])
    asm.br(f"{name}_afresh", Cond.A_NEG, a=u[1])
    asm.sub(u[1], r["UNIT_HI"], u[0])
    asm.br(f"{name}_afresh", Cond.A_NEG, a=u[1])
    asm.mul(u[1], u[0], r["SHL15"], Q14)                       # |v·y|²/2, Q2.30
    asm.sub(u[1], r["THREE_HALVES"], u[1])
    asm.mul(y, seed, u[1], Q30)
    asm.add(seed, y, r["ZERO"])
    asm.label(f"{name}_normalised")
    for i in range(3):
        asm.mul(o[i], o[i], y, Q14)

    def afresh():
        """y = ⌊2⁴⁴ / |v·2⁸|⌋, |v·2⁸|·K² by two short CORDICs; kept as the seed only below
        2²⁹ (|v| over 128 counts: no later vector outgrows it enough to overflow |v·y|²)."""
        p, t = r["P"], u[1]
        asm.label(f"{name}_afresh")
        asm.vec(p, o[0], o[1], short=True)
        asm.mul(t, p + 1, r["INV_GAIN"], Q30)
        asm.vec(p, t, o[2], short=True)
        asm.mul(t, p + 1, r["INV_GAIN"], Q30)
        asm.div(y, r["SHR10"], t)
        asm.add(seed, r["ZERO"], r["ZERO"])
        asm.sub(t, y, r["HALF"])
        asm.br(f"{name}_normalised", Cond.A_NEG, a=t, inv=True)
        asm.add(seed, y, r["ZERO"])
        asm.br(f"{name}_normalised")
    return afresh


def _gravity_terms(r):
    """G = ∇f / 16 of the gravity error FA, with Q8 = q / 8: one term list per component."""
    w, x, y, z = (r[f"Q8{i}"] for i in range(4))
    fa = [r[f"FA{i}"] for i in range(3)]
    return [[(y, fa[0], -1), (x, fa[1])],
            [(z, fa[0]), (w, fa[1]), (x, fa[2], -1), (x, fa[2], -1)],
            [(w, fa[0], -1), (z, fa[1]), (y, fa[2], -1), (y, fa[2], -1)],
            [(x, fa[0]), (y, fa[1])]]


def _field_terms(r):
    """The field's terms of G, from PB = b_y·FM and QB = b_z·FM."""
    w, x, y, z = (r[f"Q8{i}"] for i in range(4))
    pb, qb = ([r[f"{v}{i}"] for i in range(3)] for v in ("PB", "QB"))
    return [[(z, pb[0]), (y, qb[0], -1), (x, qb[1]), (x, pb[2], -1)],
            [(y, pb[0]), (z, qb[0]), (x, pb[1], -1), (x, pb[1], -1), (w, qb[1]),
             (w, pb[2], -1), (x, qb[2], -1), (x, qb[2], -1)],
            [(x, pb[0]), (w, qb[0], -1), (z, qb[1]), (z, pb[2]), (y, qb[2], -1),
             (y, qb[2], -1)],
            [(w, pb[0]), (x, qb[0]), (z, pb[1], -1), (z, pb[1], -1), (y, qb[1]), (y, pb[2])]]


def _field(asm, r):
    """The field's error from m̂ (MH): h = R·m̂, b = (0, |h_xy|, h_z), FM = Rᵀ·b − m̂, PB, QB."""
    rm = [r[f"RM{i}"] for i in range(9)]
    for i in range(3):
        asm.mac(r[f"H{i}"], [(rm[3 * i + j], r[f"MH{j}"]) for j in range(3)], Q30)
    asm.vec(r["BYP"], r["H0"], r["H1"], short=True)
    asm.mul(r["BY"], r["BYP"] + 1, r["INV_GAIN"], Q30)
    for j in range(3):
        asm.mac(r[f"FM{j}"], [(rm[3 + j], r["BY"]), (rm[6 + j], r["H2"]),
                              (r[f"MH{j}"], r["ONE"], -1)], Q30)
    for j in range(3):
        asm.mul(r[f"PB{j}"], r["BY"], r[f"FM{j}"], Q30)
    for j in range(3):
        asm.mul(r[f"QB{j}"], r["H2"], r[f"FM{j}"], Q30)


def _gradient(asm, r):
    """GR = G (QG's words) from ŝ (S), with the field's terms from m̂ (MH) when MAG_OK; sets
    ACC_USED (and MAG_USED). R(q) is in RM from the last sample's output (``_angles``; q has
    not changed since, and the first sample after a start, which has no R(q) yet, takes no
    gradient step)."""
    asm.setf(Flag.ACC_USED)
    for j in range(3):
        asm.sub(r[f"FA{j}"], r[f"RM{6 + j}"], r[f"S{j}"])
    for i in range(4):
        asm.mul(r[f"Q8{i}"], r[f"QOUT{i}"], r["EIGHTH"], Q30)
    gravity = _gravity_terms(r)
    asm.br("m_gravity_only", Cond.A_ZERO, a=r["MAG_OK"])
    _field(asm, r)
    for i, (g, f) in enumerate(zip(gravity, _field_terms(r))):
        asm.mac(r[f"GR{i}"], g + f, Q30)
    asm.setf(Flag.MAG_USED)
    asm.br("m_gradient")
    asm.label("m_gravity_only")
    for i, g in enumerate(gravity):
        asm.mac(r[f"GR{i}"], g, Q30)
    asm.label("m_gradient")


def _step(asm, r):
    """QN −= β·T·n·G/|G|: |G|·K² from three short vectoring CORDICs, one division; no step
    when the quotient would not fit (|G|·K² ≤ BN / 2⁷)."""
    p1, p2, p3 = r["P1"], r["P2"], r["P3"]
    asm.vec(p1, r["GR0"], r["GR1"], short=True)
    asm.vec(p2, r["GR2"], r["GR3"], short=True)
    asm.vec(p3, p1 + 1, p2 + 1, short=True)
    asm.mul(r["TH"], r["BN"], r["COS_PITCH_MIN"], Q30)         # BN / 2⁷ (2²³ with shift 30)
    asm.sub(r["TH"], r["TH"], p3 + 1)
    asm.br("m_no_step", Cond.A_NEG, a=r["TH"], inv=True)
    asm.div(r["RINV"], r["BN"], p3 + 1)
    for i in range(4):
        asm.mul(r[f"GR{i}"], r[f"GR{i}"], r["RINV"], Q24)
    for i in range(4):
        asm.sub(r[f"QN{i}"], r[f"QN{i}"], r[f"GR{i}"])
    asm.label("m_no_step")


def _angles(asm, r):
    """THETA: roll and pitch from R's bottom row, yaw from its first column; then END."""
    _matrix(asm, r, "RM", "QOUT")
    matrix_angles(asm, r, [r[f"RM{i}"] for i in range(9)], r["YAW"], r["ZERO"])
    asm.end()


def _align(asm, r):
    """The first sample after a reset or a switch: QOUT from the accelerometer's tilt and the
    tilt-compensated heading (0 without their sensor; the flags say which were used), then the
    gyro's step alone; reached by the branch to ``m_start``."""
    meas = [r[f"MEAS{i}"] for i in range(3)]
    asm.label("m_start")
    # no seed for this sample's normalisations: its lengths are found afresh (the reference's
    # state after a reset; a switch back finds the seeds of a long-gone sample)
    asm.add(r["M_SEED_A"], r["ZERO"], r["ZERO"])
    asm.add(r["M_SEED_M"], r["ZERO"], r["ZERO"])
    asm.add(meas[0], r["ZERO"], r["ZERO"])
    asm.add(meas[1], r["ZERO"], r["ZERO"])
    asm.br("m_no_tilt", Cond.A_ZERO, a=r["ACC_OK"])
    tilt(asm, r, meas[0])
    asm.setf(Flag.ACC_USED)
    asm.label("m_no_tilt")
    asm.add(meas[2], r["ZERO"], r["ZERO"])
    asm.br("m_aligned", Cond.A_ZERO, a=r["MAG_OK"])
    heading(asm, r, meas[0], meas[1], meas[2])
    asm.setf(Flag.MAG_USED)
    asm.label("m_aligned")
    euler_quat(asm, r, meas)
    asm.br("m_started")


def emit(asm, r):
    """The routine, from the calibrated sample to QOUT, THETA (BIAS untouched)."""
    r = _aliases(r)
    # STEP_N last: the MUL after the branch reads it (``attitude_isa``: MUL after MUL)
    step_n(asm, r, "BETA_K", "BN")
    step_n(asm, r, "K_RAD")
    # the field from here on (the early start): its paths (the alignment's too) read it
    magnetometer_in(asm, "madgwick")
    asm.br("m_start", Cond.FIRST)
    asm.label("m_started")
    # ½·q ⊗ (0, ω·T·n)
    w, x, y, z = (r[f"QOUT{i}"] for i in range(4))
    hv = [r[f"HV{i}"] for i in range(3)]
    asm.mul(r["HK"], r["STEP_N"], r["HALF"], Q30)
    for i in range(3):
        asm.mul(hv[i], r[f"G{i}"], r["HK"], Q14)               # exactly (ω·2¹⁶)·HK / 2³⁰
    asm.mac(r["QD0"], [(x, hv[0], -1), (y, hv[1], -1), (z, hv[2], -1)], Q30)
    asm.mac(r["QD1"], [(w, hv[0]), (y, hv[2]), (z, hv[1], -1)], Q30)
    asm.mac(r["QD2"], [(w, hv[1]), (x, hv[2], -1), (z, hv[0])], Q30)
    asm.mac(r["QD3"], [(w, hv[2]), (x, hv[1]), (y, hv[0], -1)], Q30)
    for i in range(4):
        asm.add(r[f"QN{i}"], r[f"QOUT{i}"], r[f"QD{i}"])
    asm.br("m_no_step", Cond.A_ZERO, a=r["ACC_OK"])
    # the unit vectors, on the first sample too: its lengths seed the next one's
    afresh = [_unit(asm, r, "S", "A", r["M_SEED_A"], "m_acc")]
    asm.br("m_units", Cond.A_ZERO, a=r["MAG_OK"])
    afresh.append(_unit(asm, r, "MH", "M", r["M_SEED_M"], "m_mag"))
    asm.label("m_units")
    asm.br("m_no_step", Cond.FIRST)                 # aligned on this sample: no gradient yet
    _gradient(asm, r)
    _step(asm, r)
    _normalise(asm, r, "QOUT", "QN")
    _angles(asm, r)
    for part in afresh:
        part()
    _align(asm, r)
