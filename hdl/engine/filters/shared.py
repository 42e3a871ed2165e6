"""Microcode every filter shares: the reset program, the calibration of a sample, the zero
tests, the tilt and heading measurements, the per-period rotation, Euler-angle rates and the
result quaternion of the per-axis filters (``angles_out``). Each writes into an ``Assembler``
(``hdl/engine/attitude_isa.py``) with the register map ``r`` (``hdl/engine/register_map.py``'s
``REGS``)."""

from ..attitude_isa import Q14, Q24, Q30, Cond


__all__ = ["init", "calibrate", "magnetometer", "magnetometer_in", "zero_tests",
           "background_divisions", "tilt", "heading",
           "step_n", "euler_rates", "matrix_angles", "euler_quat", "angles_out"]


def init(asm, r):
    for i in range(3):
        asm.add(r[f"THETA{i}"], r["ZERO"], r["ZERO"])
        asm.add(r[f"BIAS{i}"], r["ZERO"], r["ZERO"])
        asm.add(r[f"P{i}_00"], r["P0"], r["ZERO"])
        asm.add(r[f"P{i}_01"], r["ZERO"], r["ZERO"])
        asm.add(r[f"P{i}_10"], r["ZERO"], r["ZERO"])
        asm.add(r[f"P{i}_11"], r["P0"], r["ZERO"])
    asm.end()



def calibrate(asm, r):
    """The gyro and accelerometer of the sample, calibrated (G, A), and NPER << 14: what the
    filters use before the magnetometer (``magnetometer`` calibrates its field after SYNC)."""
    with asm.scratch(3) as T:
        for i in range(3):
            asm.sub(r[f"G{i}"], r[f"GRAW{i}"], r[f"GYRO_OFF{i}"], sat16=True)
        # the multiplier does not saturate to 16 bits: products go to temporaries, then an ADD
        # saturates them (sat16 of sat32 is sat16, so the result is the same)
        for i in range(3):
            asm.sub(T[i], r[f"ARAW{i}"], r[f"ACC_OFF{i}"])
        for i in range(3):
            asm.mul(T[i], T[i], r[f"ACC_SCALE{i}"], Q14)
        # NPER << 14 in place (exact: NPER ≤ 16), for ``step_n``
        asm.mul(r["NPER"], r["NPER"], r["SHL14"], Q14)
        for i in range(3):
            asm.add(r[f"A{i}"], T[i], r["ZERO"], sat16=True)


def magnetometer(asm, r):
    """SYNC (the early start, ``attitude_isa``: the loader writes MRAW, the engine takes the
    sample's ``mag_valid``), then the field calibrated (M) and MAG_OK (``zero_tests``). The
    working values go in place, into MRAW and M (no scratch register: the filters reach this
    from the middle of their routines, scratch registers held)."""
    asm.sync()
    for j in range(3):                                   # ASA: h·(ASA + 128)/256, AK axes
        asm.mul(r[f"MRAW{j}"], r[f"MRAW{j}"], r[f"ASA{j}"], Q14)   # ASA holds (ASA + 128)·2⁶
    # AK8963 -> body axes (x = y_ak, y = x_ak, z = −z_ak), minus the hard-iron offset, into M
    d = [r[f"M{i}"] for i in range(3)]
    asm.sub(d[0], r["MRAW1"], r["HARD0"])
    asm.sub(d[1], r["MRAW0"], r["HARD1"])
    asm.sub(d[2], r["ZERO"], r["MRAW2"])
    asm.sub(d[2], d[2], r["HARD2"])
    for i in range(3):
        asm.mac(r[f"MRAW{i}"], [(r[f"SOFT{i}{j}"], d[j]) for j in range(3)], Q14)
    for i in range(3):
        asm.add(r[f"M{i}"], r[f"MRAW{i}"], r["ZERO"], sat16=True)
    zero_tests(asm, r, "s", ("MAG_OK",))


def magnetometer_in(asm, name):
    """A filter's way to its field: a branch to the shared ``magnetometer`` part (SYNC and the
    field's calibration; ``attitude_program``), which returns to the label ``{name}_mag``
    here by a dispatch on the filter. On every path of the routine before its first read
    of M or MAG_OK, and only once."""
    asm.br("magnetometer")
    asm.label(f"{name}_mag")


def zero_tests(asm, r, name, tests=("ACC_OK", "MAG_OK")):
    """ACC_OK = 0 when the calibrated accelerometer vector is zero, else not (its first axis
    that is not 0); MAG_OK likewise for the field, or 0 when the sample's magnetometer is
    invalid. Copies and register tests (the ALU has no OR): an axis that is not 0 ends the
    test, so a usual one costs a copy and a taken branch."""
    for ok, v in ((ok, v) for ok, v in (("ACC_OK", "A"), ("MAG_OK", "M")) if ok in tests):
        done = f"{name}_{ok.lower()}_tested"
        if ok == "MAG_OK":
            asm.add(r[ok], r["ZERO"], r["ZERO"])
            asm.br(done, Cond.MAG_INVALID)
        for i in range(3):
            asm.add(r[ok], r[f"{v}{i}"], r["ZERO"])
            if i < 2:
                asm.br(done, Cond.A_ZERO, a=r[ok], inv=True)
        asm.label(done)


def background_divisions(asm, divisions):
    """The start and the collect (callables) of each division (d, a, b) made in the
    background (``attitude_isa``), two at most: ``tilt``'s and ``heading``'s ``divisions``
    (where there are fewer, of nothing)."""
    steps = []
    for d, a, b in divisions:
        steps.append((lambda d=d, a=a, b=b: asm.div(d, a, b, go_on=True),
                      lambda: asm.collect("divider")))
    if len(steps) > 2:
        raise ValueError(f"{len(steps)} divisions asked for, two fit")
    return steps + [(lambda: None, lambda: None)] * (2 - len(steps))


def tilt(asm, r, roll, divisions=()):
    """roll = atan2(ay, az) into ``roll``, pitch = atan2(−ax, √(ay² + az²)) into ``roll`` + 1,
    inputs scaled by 2⁸. Clobbers ``roll`` + 2 (the vectoring CORDIC writes its magnitude
    beside the angle; the first one's is used for the pitch). ``divisions``: up to two
    (d, a, b) the caller wants made in the background meanwhile (``attitude_isa``: their
    operands written before, nothing here touches their d), each beside one of the VECs."""
    (start0, collect0), (start1, collect1) = background_divisions(asm, divisions)
    with asm.scratch(4) as T:
        # a << 8 (exact); −ax << 8 by a MUL that subtracts its product (exact too, and no
        # ADD after it: a MUL followed by one takes three cycles, by a MUL one)
        start0()
        asm.mul(T[0], r["A0"], r["SHL8"], Q14, neg=True)
        for i in (1, 2):
            asm.mul(T[i], r[f"A{i}"], r["SHL8"], Q14)
        asm.vec(roll, T[2], T[1])
        collect0()
        start1()
        asm.mul(T[3], roll + 1, r["INV_GAIN"], Q30)
        asm.vec(roll + 1, T[3], T[0])
        collect1()


def heading(asm, r, roll, pitch, out, divisions=()):
    """Tilt-compensated heading into ``out``; clobbers ``out`` + 1. ``divisions``: as
    ``tilt``'s (the first beside the two rotations, the second beside the rest)."""
    (start0, collect0), (start1, collect1) = background_divisions(asm, divisions)
    with asm.scratch(7) as T:
        start0()
        # (sine · m) >> 18 as (sine · (m << 12)) >> 30: the same bits, one rounding shift
        # fewer; m << 12 while the CORDIC turns by the roll (in the background)
        ms = T[4:7]
        asm.rot(r["CR"], roll, go_on=True)
        for i in range(3):
            asm.mul(ms[i], r[f"M{i}"], r["SHL12"], Q14)
        asm.collect()
        asm.rot(r["CP"], pitch)
        collect0()
        start1()
        asm.mul(T[0], r["SP"], r["SR"], Q30)
        asm.mul(T[1], r["SP"], r["CR"], Q30)
        asm.mac(T[2], [(r["CP"], ms[0]), (T[0], ms[1]), (T[1], ms[2])], Q30)      # hx
        asm.mac(T[3], [(r["CR"], ms[1]), (r["SR"], ms[2], -1)], Q30)              # hy
        asm.vec(out, T[3], T[2])
        collect1()



def step_n(asm, r, coefficient, dst="STEP_N"):
    """``dst`` (STEP_N) = ``coefficient`` · NPER: the rotation of this update covers every
    period since the previous sample (a sample the sensor made but nobody read is integrated,
    not lost). Exact: ``calibrate`` has shifted NPER left by 14 (a MUL with SHL14, in the run
    of its products: one cycle, where a MUL of its own before this one cost three), so this is
    one MUL with shift 14; saturates (and flags) only for a coefficient times 16 beyond 32
    bits."""
    asm.mul(r[dst], r[coefficient], r["NPER"], Q14)


def euler_rates(asm, r, U, name):
    """``U`` (three registers, body rates in any one format) -> Euler-angle rates of THETA, in
    place (``reference.fixed_point.euler_rates_fixed``)."""
    asm.rot(r["CR"], r["THETA0"])                       # CR, SR = cos, sin of roll
    asm.rot(r["CP"], r["THETA1"])                       # CP, SP = cos, sin of pitch
    with asm.scratch(4) as (t, tp, sec, w):
        asm.sub(t, r["CP"], r["COS_PITCH_MIN"])
        asm.br(f"{name}_cp_ok", Cond.A_NEG, a=t, inv=True)
        asm.add(r["CP"], r["COS_PITCH_MIN"], r["ZERO"])
        asm.label(f"{name}_cp_ok")
        # the products first: a division that read CP as b just after its clamp would need
        # a NOP before it (``attitude_isa``), a ROM word
        asm.mac(w, [(r["SR"], U[1]), (r["CR"], U[2])], Q30)
        asm.mac(t, [(r["CR"], U[1]), (r["SR"], U[2], -1)], Q30)
        asm.div(tp, r["SP"], r["CP"])                   # tan θ, Q8.24
        asm.div(sec, r["ONE"], r["CP"])                 # 1 / cos θ, Q8.24
        asm.mul(U[2], w, sec, Q24)
        asm.mul(w, w, tp, Q24)
        asm.add(U[1], t, r["ZERO"])
        asm.add(U[0], U[0], w)


def matrix_angles(asm, r, m, yaw, delta, rotation=None, beside=()):
    """THETA = the ZYX angles of Rz(δ)·R (``quat_angles_fixed``), R the nine registers ``m``
    (Q2.30): roll and pitch from R's bottom row, yaw = δ (register ``delta``) + atan2(R10,
    R00), vectored into the CORDIC pair ``yaw`` (the VECs write magnitudes beside angles).

    ``rotation`` (the flagship's output): (``dst``, ``prepare``, ``use``), a rotation the caller
    wants beside the angles, made in the CORDIC's turn between the roll and the pitch:
    ``prepare(t)`` writes its angle into the scratch register ``t`` while the roll's VEC runs
    in the background, and ``use()`` reads its cos and sin (``dst``, ``dst`` + 1) while the
    pitch's does. ``beside``: more of the caller's work (routines) for the CORDIC's waits, in
    order: the roll's, the rotation's (without a rotation, between the roll and the pitch),
    the pitch's and the yaw's. None of them may branch or use the CORDIC (``attitude_isa``'s
    background rules)."""
    work = list(beside) + [lambda: None] * (4 - len(beside))
    with asm.scratch(3) as (t0, t1, t2):
        asm.vec(r["THETA0"], m[8], m[7], go_on=True)
        asm.sub(t1, r["ZERO"], m[6])
        if rotation is not None:
            dst, prepare, use = rotation
            prepare(t2)
        work[0]()
        asm.collect()
        if rotation is not None:
            asm.rot(dst, t2, go_on=True)
            asm.mul(t0, r["THETA1"], r["INV_GAIN"], Q30)
            work[1]()
            asm.collect()
            asm.vec(r["THETA1"], t0, t1, go_on=True)
            use()
        else:
            asm.mul(t0, r["THETA1"], r["INV_GAIN"], Q30)
            work[1]()
            asm.vec(r["THETA1"], t0, t1, go_on=True)
        work[2]()
        asm.collect()
    asm.vec(yaw, m[0], m[3], go_on=True)
    work[3]()
    asm.collect()
    asm.add(r["THETA2"], delta, yaw, wrap=True)


def euler_quat(asm, r, angles):
    """QOUT = the quaternion of the ZYX angles in the three registers ``angles`` (roll,
    pitch, yaw; ``euler_quat_fixed``); clobbers CR .. SY."""
    with asm.scratch(4) as T:
        cr, sr, cp, sp, cy, sy = (r[n] for n in ("CR", "SR", "CP", "SP", "CY", "SY"))
        cc, ss, cs, sc = T[0:4]
        # the half angles of roll and pitch while the CORDIC turns by the yaw's, the yaw's and
        # pitch's products while it turns by the roll's (in the background); the CORDIC
        # takes its angle as it starts, so T0 is free again then
        asm.mul(T[2], angles[2], r["HALF"], Q30)
        asm.rot(cy, T[2], go_on=True)
        for i in range(2):
            asm.mul(T[i], angles[i], r["HALF"], Q30)
        asm.collect()
        asm.rot(cp, T[1])
        asm.rot(cr, T[0], go_on=True)
        asm.mul(cc, cy, cp, Q30)
        asm.mul(ss, sy, sp, Q30)
        asm.mul(cs, cy, sp, Q30)
        asm.mul(sc, sy, cp, Q30)
        asm.collect()
        asm.mac(r["QOUT0"], [(cr, cc), (sr, ss)], Q30)
        asm.mac(r["QOUT1"], [(sr, cc), (cr, ss, -1)], Q30)
        asm.mac(r["QOUT2"], [(cr, cs), (sr, sc)], Q30)
        asm.mac(r["QOUT3"], [(cr, sc), (sr, cs, -1)], Q30)


def angles_out(asm, r):
    """The result quaternion of the per-axis filters' angles (``euler_quat_fixed``), then END."""
    euler_quat(asm, r, [r[f"THETA{i}"] for i in range(3)])
    asm.end()
