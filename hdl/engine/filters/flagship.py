"""Microcode of the flagship filter: ``reference.flagship_fixed.FlagshipFixed.step``, operation
for operation, on the attitude engine (instruction set: ``hdl/engine/attitude_isa.py``).

Every reference operation that can saturate is one instruction here, under the same conditions,
so that the result and the sample's ``saturated`` flag agree bit for bit; the order within a
section is chosen for the MAC's overlap (independent MULs back to back) and for the CORDIC's
background (work that needs no CORDIC result between a VEC or ROT started with ``go_on`` and
its collect: ``hdl/engine/attitude_isa.py``). Register names are
those of the reference's state (``QG``, ``QA``, ``LP`` ...); values that live across sections
have registers of the routine's own (``F_`` names), short-lived ones come from the assembler's
scratch pool (``asm.scratch``).

Cost: ``python -m mpu9250_ahrs report`` (``cycles_per_update.flagship``).
"""

from ..attitude_isa import DOUBLED, Q14, Q30, Cond, Flag
from .shared import magnetometer_in, matrix_angles, step_n


__all__ = ["CONFIG_REGISTERS", "REGISTERS", "FLAGSHIP_REGISTERS", "flagship_names",
           "flagship_routine", "emit"]

# Run-time registers (host-visible, from 0x70): ``FlagshipFixedConfig.registers()`` names.
FLAGSHIP_REGISTERS = ("K_RAD", "A_DET", "A_REST", "A_ACC", "A_MAG", "A_MAG_FAST", "REST_GYRO2",
                      "REST_ACC2", "GATE_NORM", "GATE_DIP", "K_REST", "K_REF", "K_FAST",
                      "K_NEW", "A_REF", "REST_BIAS2")

_VEC3 = ("G16", "A16", "U", "DG", "DA", "V", "AI", "E", "LP", "GLP", "ALP", "BAND")
_QUAT = ("QG", "QA", "QAG", "QT")
_STATE = ("DELTA", "DELTA_OK", "REST_LEFT", "FAST_LEFT", "REF_LEFT", "CAND_LEFT", "REF_OK",
          "REF_SEEN", "REF_NORM", "REF_DIP", "CAND_NORM", "CAND_DIP")
# CORDIC results come in pairs (d, d + 1): each pair is listed together
_PAIRS = ("F_PHI", "F_SK", "F_TH", "F_THK", "F_CPHI", "F_SPHI", "F_CH", "F_SH", "F_PSI", "F_HK",
          "F_DIP", "F_NK", "F_CD", "F_SD", "F_YAW", "F_YAWK")
_WORK = ("F_SG", "F_SA", "F_V2", "F_C", "F_S", "F_N2", "F_F", "F_SXY",
         "F_CX", "F_CY", "F_HORIZ", "F_MN", "F_LIM", "F_HD", "F_GAIN")


def flagship_names():
    """The routine's registers, in allocation order (pairs adjacent)."""
    names = [f"{v}{i}" for v in _VEC3 for i in range(3)]
    names += [f"{q}{i}" for q in _QUAT for i in range(4)]
    names += [f"{m}{i}" for m in ("RM", "RAG") for i in range(9)]
    return names + list(_STATE) + list(_PAIRS) + list(_WORK)


def _aliases(r):
    """Registers that only live within one sample share words with others that are dead by
    then: the field takes the rotation vector's words (the gyro's live until the rest
    detection, at the end), the transformed field the rotated accelerometer's, R(q_g) and
    R(q_a) one matrix, the rotation vector's quaternion the vector itself."""
    r = dict(r)
    for i in range(3):
        r[f"M16{i}"], r[f"ME{i}"] = r[f"V{i}"], r[f"AI{i}"]
    for i in range(9):
        r[f"RG{i}"] = r[f"RA{i}"] = r[f"RM{i}"]
    r["QV0"] = r["F_C"]
    # the rest test's third sum: the deviations' words are free once their sum is formed
    r["F_SB"] = r["DG0"]
    for i in range(3):
        r[f"QV{i + 1}"] = r[f"V{i}"]
    return r


def _qmul(asm, r, out, p, q):
    """out = p ⊗ q (names of four-word quaternions; ``out`` must not be ``p`` or ``q``)."""
    (pw, px, py, pz), (qw, qx, qy, qz) = ([r[f"{x}{i}"] for i in range(4)] for x in (p, q))
    o = [r[f"{out}{i}"] for i in range(4)]
    asm.mac(o[0], [(pw, qw), (px, qx, -1), (py, qy, -1), (pz, qz, -1)], Q30)
    asm.mac(o[1], [(pw, qx), (px, qw), (py, qz), (pz, qy, -1)], Q30)
    asm.mac(o[2], [(pw, qy), (px, qz, -1), (py, qw), (pz, qx)], Q30)
    asm.mac(o[3], [(pw, qz), (px, qy), (py, qx, -1), (pz, qw)], Q30)


def _normalise(asm, r, dst, src):
    """dst = src · (3/2 − |src|²/2): one Newton step (``dst`` may be ``src``)."""
    s = [r[f"{src}{i}"] for i in range(4)]
    asm.mac(r["F_N2"], [(c, c) for c in s], Q30)
    with asm.scratch(1) as (half,):
        asm.mul(half, r["F_N2"], r["HALF"], Q30)
        asm.sub(r["F_F"], r["THREE_HALVES"], half)
    for i in range(4):
        asm.mul(r[f"{dst}{i}"], s[i], r["F_F"], Q30)


def _matrix(asm, r, out, q):
    """out = R(q), row-major, Q2.30; the doubled products 2·a·b as MULs with shift 29."""
    w, x, y, z = (r[f"{q}{i}"] for i in range(4))
    o = [r[f"{out}{i}"] for i in range(9)]
    with asm.scratch(9) as (xx, yy, zz, xy, xz, yz, wx, wy, wz):
        for d, a, b in ((xx, x, x), (yy, y, y), (zz, z, z), (xy, x, y), (xz, x, z), (yz, y, z),
                        (wx, w, x), (wy, w, y), (wz, w, z)):
            asm.mul(d, a, b, DOUBLED)
        asm.sub(o[0], r["ONE"], yy)
        asm.sub(o[4], r["ONE"], xx)
        asm.sub(o[8], r["ONE"], xx)
        asm.sub(o[0], o[0], zz)
        asm.sub(o[4], o[4], zz)
        asm.sub(o[8], o[8], yy)
        asm.sub(o[1], xy, wz)
        asm.add(o[2], xz, wy)
        asm.add(o[3], xy, wz)
        asm.sub(o[5], yz, wx)
        asm.sub(o[6], xz, wy)
        asm.add(o[7], yz, wx)


def _rotate(asm, r, out, m, v):
    for i in range(3):
        asm.mac(r[f"{out}{i}"], [(r[f"{m}{3 * i + j}"], r[f"{v}{j}"]) for j in range(3)], Q30)


def _abs(asm, r, x, label):
    asm.br(label, Cond.A_NEG, a=x, inv=True)
    asm.sub(x, r["ZERO"], x)
    asm.label(label)


def _low_pass(asm, r, states, inputs, gain):
    """state += mul(gain, input − state, 30) for each pair: the SUBs, then the MULs back to
    back (``_low_pass_steps``' two halves)."""
    with asm.scratch(len(states)) as temps:
        for step in _low_pass_steps(asm, r, temps, states, inputs, gain):
            step()


def _low_pass_steps(asm, r, temps, states, inputs, gain):
    """``_low_pass`` in two steps (callables) over the scratch registers ``temps``: the
    products (the SUBs, then the MULs back to back), then the sums (the ADDs)."""
    def products():
        for t, s, x in zip(temps, states, inputs):
            asm.sub(t, x, s)
        for t in temps:
            asm.mul(t, r[gain], t, Q30)

    def sums():
        for t, s in zip(temps, states):
            asm.add(s, s, t)
    return products, sums


def _butterworth_low(asm, r, low, band, gain):
    """The second-order low-pass (state-variable form, ``reference.flagship_fixed``), its first
    half, each axis: low += mul(gain, band, 30). MULs back to back."""
    with asm.scratch(len(low)) as t:
        for ti, b in zip(t, band):
            asm.mul(ti, r[gain], b, Q30)
        for ti, lo in zip(t, low):
            asm.add(lo, lo, ti)


def _butterworth_band(asm, r, low, band, inputs, gain):
    """Its second half, from the new ``low``: band += mul(gain, input − low − mul(band, √2,
    30), 30). MULs back to back where they can be."""
    with asm.scratch(len(low)) as t, asm.scratch(len(low)) as u:
        for ti, b in zip(t, band):
            asm.mul(ti, b, r["SQRT2"], Q30)
        for ui, x, lo, ti in zip(u, inputs, low, t):
            asm.sub(ui, x, lo)
            asm.sub(ui, ui, ti)
        for ui in u:
            asm.mul(ui, r[gain], ui, Q30)
        for ui, b in zip(u, band):
            asm.add(b, b, ui)


def _rest_steps(asm, r, temps):
    """The flagship's rest detection, its straight-line part (the input low-passes, the
    deviations from them, the low-passed rate, and their sums of squares against the
    thresholds), as four steps
    (callables) for the output's CORDIC waits (``_output``); ``temps``: six scratch
    registers, held across them (the first three hold the low-passed rate once the
    low-pass state is summed)."""
    v = lambda name: [r[f"{name}{i}"] for i in range(3)]
    low_pass_products, low_pass_state = _low_pass_steps(
        asm, r, temps, v("GLP") + v("ALP"), v("G16") + v("A16"), "A_DET")

    def low_pass_sums():
        low_pass_state()
        for i in range(3):
            asm.sub(r[f"DG{i}"], r[f"G16{i}"], r[f"GLP{i}"])
        for i in range(3):
            asm.sub(r[f"DA{i}"], r[f"A16{i}"], r[f"ALP{i}"])

    # the low-passed rate in Q.6 counts (against REST_BIAS2): in the scratch registers, free
    # once the low-pass state is summed
    slow = temps[:3]

    def deviations():
        for i in range(3):
            asm.mul(r[f"DG{i}"], r[f"DG{i}"], r["SHR10"], Q30)      # Q.6 counts
        for i in range(3):
            asm.mul(r[f"DA{i}"], r[f"DA{i}"], r["SHR10"], Q30)
        for t, i in zip(slow, range(3)):
            asm.mul(t, r[f"GLP{i}"], r["SHR10"], Q30)

    def sums():
        asm.mac(r["F_SG"], [(d, d) for d in v("DG")], Q14)
        asm.mac(r["F_SA"], [(d, d) for d in v("DA")], Q14)
        asm.mac(r["F_SB"], [(t, t) for t in slow], Q14)
        asm.sub(r["F_SG"], r["F_SG"], r["REST_GYRO2"])
        asm.sub(r["F_SA"], r["F_SA"], r["REST_ACC2"])
        asm.sub(r["F_SB"], r["F_SB"], r["REST_BIAS2"])
    return low_pass_products, low_pass_sums, deviations, sums


def _rate_error(asm, r):
    """U = ω − b, Q16.16, with the bias of the previous sample: the strapdown's."""
    for i in range(3):
        asm.sub(r[f"U{i}"], r[f"G16{i}"], r[f"BIAS{i}"])


def _rest_and_bias(asm, r):
    """The flagship's rest decision on ``_rest_steps``' sums, and the bias at rest."""
    v = lambda name: [r[f"{name}{i}"] for i in range(3)]
    ZERO, INT1 = r["ZERO"], r["INT1"]
    asm.br("f_moving", Cond.A_NEG, a=r["F_SG"], inv=True)
    asm.br("f_moving", Cond.A_NEG, a=r["F_SA"], inv=True)
    asm.br("f_moving", Cond.A_NEG, a=r["F_SB"], inv=True)
    asm.br("f_rest_checked", Cond.A_ZERO, a=r["REST_LEFT"])
    asm.sub(r["REST_LEFT"], r["REST_LEFT"], INT1)
    asm.br("f_rest_checked")
    asm.label("f_moving")
    asm.add(r["REST_LEFT"], r["K_REST"], ZERO)
    asm.label("f_rest_checked")
    asm.br("f_not_at_rest", Cond.A_ZERO, a=r["REST_LEFT"], inv=True)
    asm.setf(Flag.AT_REST)
    asm.setf(Flag.BIAS_UPDATED)
    _low_pass(asm, r, v("BIAS"), v("GLP"), "A_REST")
    asm.label("f_not_at_rest")


def _strapdown(asm, r):
    """The flagship's strapdown: q_g ⊗ exp(v), v = (ω − b)·T (``flagship_routine``'s part)."""
    v = lambda name: [r[f"{name}{i}"] for i in range(3)]
    ONE = r["ONE"]
    for i in range(3):
        asm.mul(r[f"V{i}"], r[f"U{i}"], r["STEP_N"], Q30)    # STEP_N = K_RAD · NPER
    asm.mac(r["F_V2"], [(x, x) for x in v("V")], Q30)
    with asm.scratch(2) as (t0, t1):
        asm.mul(t0, r["F_V2"], r["EIGHTH"], Q30)
        asm.mul(t1, r["F_V2"], r["ONE_48"], Q30)
        asm.sub(r["QV0"], ONE, t0)                           # cos(|v|/2)
        asm.sub(r["F_S"], r["HALF"], t1)                     # sin(|v|/2)/|v|
    for i in range(3):
        asm.mul(r[f"QV{i + 1}"], r[f"V{i}"], r["F_S"], Q30)        # in place: V is dead now
    _qmul(asm, r, "QT", "QG", "QV")
    _normalise(asm, r, "QG", "QT")


def _inclination(asm, r):
    """The flagship's inclination (``flagship_routine``'s part)."""
    v = lambda name: [r[f"{name}{i}"] for i in range(3)]
    ZERO = r["ZERO"]
    asm.br("f_no_acc", Cond.A_ZERO, a=r["ACC_OK"])
    _matrix(asm, r, "RG", "QG")
    _rotate(asm, r, "AI", "RG", "A16")
    _butterworth_low(asm, r, v("LP"), v("BAND"), "A_ACC")
    _matrix(asm, r, "RA", "QA")
    _rotate(asm, r, "E", "RA", "LP")
    # E needs the low-pass's new state only: its band is updated while the CORDIC vectors E
    # in the background (``attitude_isa``), and SXY is scaled while it rotates by φ
    asm.vec(r["F_PHI"], r["E0"], r["E1"], go_on=True)        # φ, s·K
    _butterworth_band(asm, r, v("LP"), v("BAND"), v("AI"), "A_ACC")
    asm.collect()
    asm.br("f_no_acc", Cond.A_ZERO, a=r["F_SK"])
    asm.rot(r["F_CPHI"], r["F_PHI"], go_on=True)
    asm.setf(Flag.ACC_USED)
    asm.mul(r["F_SXY"], r["F_SK"], r["INV_GAIN"], Q30)
    asm.collect()
    asm.vec(r["F_TH"], r["E2"], r["F_SXY"])                  # θ from up
    with asm.scratch(1) as (t0,):
        asm.mul(t0, r["F_TH"], r["HALF"], Q30)
        asm.rot(r["F_CH"], t0)
        asm.mul(r["F_CX"], r["F_SPHI"], r["F_SH"], Q30)
        asm.mul(t0, r["F_CPHI"], r["F_SH"], Q30)
        asm.sub(r["F_CY"], ZERO, t0)
    ch, cx, cy = r["F_CH"], r["F_CX"], r["F_CY"]
    qw, qx, qy, qz = (r[f"QA{i}"] for i in range(4))
    qt = [r[f"QT{i}"] for i in range(4)]
    asm.mac(qt[0], [(ch, qw), (cx, qx, -1), (cy, qy, -1)], Q30)
    asm.mac(qt[1], [(ch, qx), (cx, qw), (cy, qz)], Q30)
    asm.mac(qt[2], [(ch, qy), (cx, qz, -1), (cy, qw)], Q30)
    asm.mac(qt[3], [(ch, qz), (cx, qy), (cy, qx, -1)], Q30)
    _normalise(asm, r, "QA", "QT")
    asm.label("f_no_acc")
    _qmul(asm, r, "QAG", "QA", "QG")
    _matrix(asm, r, "RAG", "QAG")


def _heading(asm, r):
    """The flagship's heading (``flagship_routine``'s part)."""
    ONE, ZERO, INT1 = r["ONE"], r["ZERO"], r["INT1"]
    asm.br("f_no_mag", Cond.A_ZERO, a=r["MAG_OK"])
    for i in range(3):
        asm.mul(r[f"M16{i}"], r[f"M{i}"], ONE, Q14)
    _rotate(asm, r, "ME", "RAG", "M16")
    asm.vec(r["F_PSI"], r["ME1"], r["ME0"])                  # ψ = atan2(mE_x, mE_y), h·K
    asm.mul(r["F_HORIZ"], r["F_HK"], r["INV_GAIN"], Q30)
    asm.br("f_no_mag", Cond.A_ZERO, a=r["F_HORIZ"])
    with asm.scratch(2) as (t0, t1):
        asm.sub(t0, ZERO, r["ME2"])
        asm.vec(r["F_DIP"], r["F_HORIZ"], t0)
        asm.mul(r["F_MN"], r["F_NK"], r["INV_GAIN"], Q30)
        mn, dip = r["F_MN"], r["F_DIP"]
        # the gate: learning the reference (a low-pass from the first field) ...
        asm.br("f_learnt", Cond.A_ZERO, a=r["REF_OK"], inv=True)
        asm.br("f_ref_first", Cond.A_ZERO, a=r["REF_SEEN"])
        asm.sub(t0, mn, r["REF_NORM"])                      # ref += A_REF · (x − ref)
        asm.sub(t1, dip, r["REF_DIP"])
        asm.mul(t0, t0, r["A_REF"], Q30)
        asm.mul(t1, t1, r["A_REF"], Q30)
        asm.add(r["REF_NORM"], r["REF_NORM"], t0)
        asm.add(r["REF_DIP"], r["REF_DIP"], t1)
        asm.label("f_ref_learnt")
        asm.br("f_good", Cond.A_ZERO, a=r["REF_LEFT"], inv=True)
        asm.add(r["REF_OK"], INT1, ZERO)
        asm.setf(Flag.MAG_NEW_REF)
        asm.br("f_good")
        asm.label("f_ref_first")                            # the first field: taken as it is
        asm.add(r["REF_NORM"], mn, ZERO)
        asm.add(r["REF_DIP"], dip, ZERO)
        asm.add(r["REF_SEEN"], INT1, ZERO)
        asm.br("f_ref_learnt")
        # ... or testing the field against it
        asm.label("f_learnt")
        asm.mul(r["F_LIM"], r["REF_NORM"], r["GATE_NORM"], Q30)
        asm.sub(t0, mn, r["REF_NORM"])
        _abs(asm, r, t0, "f_abs_norm")
        asm.sub(t0, t0, r["F_LIM"])
        asm.br("f_bad", Cond.A_NEG, a=t0, inv=True)
        asm.sub(t0, dip, r["REF_DIP"], wrap=True)
        _abs(asm, r, t0, "f_abs_dip")
        asm.sub(t0, t0, r["GATE_DIP"])
        asm.br("f_bad", Cond.A_NEG, a=t0, inv=True)
        asm.add(r["CAND_NORM"], ZERO, ZERO)
        asm.br("f_good")
        asm.label("f_bad")
        asm.setf(Flag.MAG_DISTURBED)
        asm.mul(r["F_HD"], r["GATE_DIP"], r["HALF"], Q30)
        asm.br("f_moved", Cond.A_ZERO, a=r["CAND_NORM"])
        asm.mul(t1, r["CAND_NORM"], r["GATE_NORM"], Q30)       # steady: within the gate
        asm.sub(t0, mn, r["CAND_NORM"])
        _abs(asm, r, t0, "f_abs_cnorm")
        asm.sub(t0, t1, t0)
        asm.br("f_moved", Cond.A_NEG, a=t0)
        asm.sub(t0, dip, r["CAND_DIP"], wrap=True)
        _abs(asm, r, t0, "f_abs_cdip")
        asm.sub(t0, r["F_HD"], t0)
        asm.br("f_moved", Cond.A_NEG, a=t0)
        asm.br("f_no_mag", Cond.A_ZERO, a=r["CAND_LEFT"], inv=True)
        asm.add(r["REF_NORM"], r["CAND_NORM"], ZERO)             # a steady new field: adopt it
        asm.add(r["REF_DIP"], r["CAND_DIP"], ZERO)
        asm.add(r["CAND_NORM"], ZERO, ZERO)
        asm.setf(Flag.MAG_NEW_REF)
        asm.br("f_no_mag")
        asm.label("f_moved")
        asm.add(r["CAND_NORM"], mn, ZERO)
        asm.add(r["CAND_DIP"], dip, ZERO)
        asm.add(r["CAND_LEFT"], r["K_NEW"], ZERO)
        asm.br("f_no_mag")
        # the heading follows the field
        asm.label("f_good")
        asm.setf(Flag.MAG_USED)
        asm.br("f_delta_ok", Cond.A_ZERO, a=r["DELTA_OK"], inv=True)
        asm.add(r["DELTA"], r["F_PSI"], ZERO)
        asm.add(r["DELTA_OK"], INT1, ZERO)
        asm.br("f_no_mag")
        asm.label("f_delta_ok")
        asm.sub(t0, r["F_PSI"], r["DELTA"], wrap=True)
        asm.add(r["F_GAIN"], r["A_MAG"], ZERO)
        asm.br("f_slow", Cond.A_ZERO, a=r["FAST_LEFT"])
        asm.add(r["F_GAIN"], r["A_MAG_FAST"], ZERO)
        asm.label("f_slow")
        asm.mul(t0, t0, r["F_GAIN"], Q30)
        asm.add(r["DELTA"], r["DELTA"], t0, wrap=True)
    asm.label("f_no_mag")


def _output(asm, r):
    """The flagship's output: q = (cos δ/2, 0, 0, sin δ/2) ⊗ q_a ⊗ q_g, and its angles
    (``flagship_routine``'s part)."""
    cd, sd = r["F_CD"], r["F_SD"]
    w, x, y, z = (r[f"QAG{i}"] for i in range(4))

    def half_delta(t):
        asm.mul(t, r["DELTA"], r["HALF"], Q30)

    def quaternion():
        asm.mac(r["QOUT0"], [(cd, w), (sd, z, -1)], Q30)
        asm.mac(r["QOUT1"], [(cd, x), (sd, y, -1)], Q30)
        asm.mac(r["QOUT2"], [(cd, y), (sd, x)], Q30)
        asm.mac(r["QOUT3"], [(cd, z), (sd, w)], Q30)
    # the rotation by δ/2, the quaternion and the rest detection's sums beside the angles'
    # VECs, in the CORDIC's background (``matrix_angles``); then the rest decision
    with asm.scratch(6) as temps:
        matrix_angles(asm, r, [r[f"RAG{i}"] for i in range(9)], r["F_YAW"], r["DELTA"],
                      rotation=(cd, half_delta, quaternion), beside=_rest_steps(asm, r, temps))
    _rest_and_bias(asm, r)
    asm.end()


def _start_up(asm, r):
    """The flagship's start-up: the first sample after a reset or a filter switch; the bias is
    kept (``flagship_routine``'s part, after its END: reached by the branch to ``f_start``)."""
    ONE, ZERO = r["ONE"], r["ZERO"]
    asm.label("f_start")
    for q in ("QG", "QA"):
        asm.add(r[f"{q}0"], ONE, ZERO)
        for i in range(1, 4):
            asm.add(r[f"{q}{i}"], ZERO, ZERO)
    for i in range(3):
        asm.add(r[f"LP{i}"], r[f"A16{i}"], ZERO)
        asm.add(r[f"BAND{i}"], ZERO, ZERO)
        asm.add(r[f"ALP{i}"], r[f"A16{i}"], ZERO)
        asm.add(r[f"GLP{i}"], r[f"G16{i}"], ZERO)
    for name, value in (("REST_LEFT", "K_REST"), ("FAST_LEFT", "K_FAST"),
                        ("REF_LEFT", "K_REF")):
        asm.add(r[name], r[value], ZERO)
    for name in ("DELTA", "DELTA_OK", "CAND_LEFT", "REF_OK", "REF_SEEN", "REF_NORM", "REF_DIP",
                 "CAND_NORM", "CAND_DIP"):
        asm.add(r[name], ZERO, ZERO)
    asm.br("f_started")


def flagship_routine(asm, r):
    """The flagship, from the calibrated sample (G, A, M, ACC_OK, MAG_OK) to QOUT, THETA and
    BIAS; ends with END. Working registers beyond its own come from ``asm.scratch``."""
    r = _aliases(r)
    ONE, INT1 = r["ONE"], r["INT1"]
    for i in range(3):
        asm.mul(r[f"G16{i}"], r[f"G{i}"], ONE, Q14)          # << 16
    for i in range(3):
        asm.mul(r[f"A16{i}"], r[f"A{i}"], ONE, Q14)
    asm.br("f_start", Cond.FIRST)
    asm.label("f_started")
    for t in ("FAST_LEFT", "REF_LEFT", "CAND_LEFT"):         # countdowns, stopping at 0
        asm.br(f"f_{t}_0", Cond.A_ZERO, a=r[t])
        asm.sub(r[t], r[t], INT1)
        asm.label(f"f_{t}_0")
    _rate_error(asm, r)
    _strapdown(asm, r)
    _inclination(asm, r)
    magnetometer_in(asm, "flagship")      # the field from here on (the early start)
    _heading(asm, r)
    _output(asm, r)
    _start_up(asm, r)


def emit(asm, r):
    """The filter's entry: the per-period rotation (its strapdown step uses STEP_N), then the
    routine."""
    step_n(asm, r, "K_RAD")
    flagship_routine(asm, r)


# the registry's view (``hdl/engine/filters/__init__.py``): run-time registers from 0x70, and the
# routine's own registers
CONFIG_REGISTERS = FLAGSHIP_REGISTERS
REGISTERS = tuple(flagship_names())
