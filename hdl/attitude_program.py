"""Register map and microcode of the attitude engine: calibration, the flagship quaternion
filter (``hdl/flagship_microcode.py``), the per-axis Kalman filter, the complementary filter,
and the result quaternion (or angles) each of them reports.

The microcode computes exactly ``reference.engine_model.EngineModel`` (formats in
``reference/FIXED_POINT.md``); it is written from those formulas, step by step, and the tests
compare the gateware with the reference sample by sample.

Register map (32-bit words; the host writes the run-time registers through the engine's
``cfg`` port at these addresses, any time the engine is idle)

=======  ==============  =========================================================  ===========
address  name            meaning, format                                            reset value
=======  ==============  =========================================================  ===========
0x00     ZERO            constant 0 (read-only to the host)                         0
0x01     RATE            BAM per gyro count per period, Q14 (see FIXED_POINT.md)    from dt
0x02     T               sample period, Q0.24 s                                     from dt
0x03     Q_ANGLE         Kalman Q angle, Q8.24 deg²                                 0.2
0x04     Q_BIAS          Kalman Q bias, Q8.24 (°/s)²                                0.1
0x05     R               Kalman R, Q8.24 deg² (> 0)                                 2.0
0x06     P0              initial covariance diagonal, Q8.24                         1.0
0x07     BIAS_SCALE      360·LSB_per_dps/2¹⁶, Q8.24                                 from LSB
0x08     ONE_MINUS_A     complementary filter 1 − a, Q0.24                          0.02
0x09     INV_GAIN        1/K of the CORDIC, Q1.30 (read-only to the host)           0.607…
0x0A-0C  GYRO_OFF x,y,z  gyro offset, counts                                        0
0x0D-0F  ACC_OFF x,y,z   accelerometer offset, counts                               0
0x10-12  ACC_SCALE       accelerometer scale, Q2.14                                 1.0
0x13-15  HARD x,y,z      hard-iron offset, counts, body axes, after ASA             0
0x16-1E  SOFT            soft-iron matrix, row-major, Q2.14                         identity
0x1F     SHL8            2²²: a MUL by it with shift 14 is a left shift by 8        2²²
                         (read-only to the host)
0x70     K_RAD           flagship: T / LSB_per_rad · 2⁴⁴ (v = (ω−b)·K_RAD >> 30)    from dt
0x71-75  A_DET, A_REST,  flagship low-pass gains 1 − exp(−T/τ), Q0.30 (τ = 0.5 s,   from dt
         A_ACC, A_MAG,   tau_rest, tau_mag, min(tau_mag, 0.2 s)); A_MAG,            (A_MAG*:
         A_MAG_FAST      A_MAG_FAST with T the magnetometer's period (a new field   from the
                         every 10 ms: ``numeric_contract.mag_period``); A_ACC: the  field's)
                         inclination's second-order low-pass, 2·sin(π·f_c·T), f_c =
                         √2/(2π·tau_acc), Q0.30
0x76-77  REST_GYRO2,     flagship rest thresholds, counts² / 4                      from LSB
         REST_ACC2
0x78     GATE_NORM       flagship field-norm gate, relative, Q0.30; a rejected      0.05
                         field is steady (a new reference) while its norm stays
                         within it of the first one's
0x79     GATE_DIP        flagship dip gate, BAM32                                   10°
0x7A-7D  K_REST, K_REF,  flagship times in samples (rest, reference learning, fast  from dt
         K_FAST, K_NEW   heading, new reference)
0x7E     A_REF           flagship gain of the reference's low-pass while learnt,    from the
                         Q0.30 (tau_ref; T the magnetometer's period)               field's
0x7F     EULER_RATES     per-axis filters: 0 = body rates (the published form),    0
                         else Euler-angle rates (reference.fixed_point.
                         euler_rates_fixed; right at any attitude but ±90° pitch)
0xFE     TELEMETRY_DIV   (read by ``AHRSCore``, not the engine) frame every n-th     from baud
                         result (1..65535; 0 is taken as 1)
0xFF     CONTROL         (not a register-file word) bits 1:0 filter: 0 = per-axis
                         Kalman, 1 = complementary, 2 = flagship (the reset
                         default); bit 2: write 1 to reset the filter state
                         (angles 0, bias 0, P = P0·I, flagship afresh); bit 3: keep
                         the filter (bits 1:0 ignored: a reset alone). Selecting
                         another filter makes the next sample a first one. A word
                         with a reserved bit (31:4) set, or without keep a code
                         that names no filter (3), is refused and counted
                         (``numeric_contract.control_fields``).
=======  ==============  =========================================================  ===========

From 0x20 (``REGS``): the loader's inputs, the filters' state, working registers and more
constants (``SHL12``, ``SHL15``, ``ONE``, ``HALF`` ...: reset values that no program writes); the
host need not know them. Reading back works for every word; writing works for the run-time
registers above and CONTROL only (``HOST_WRITABLE``): a write anywhere else is refused and
counted (the engine's ``cfg_refused``, carried in attitude frames).
"""

import math
from dataclasses import dataclass
from typing import Callable

from .attitude_isa import Q14, Q24, Q30, REG_COUNT, Assembler, Cond, Flag
from .flagship_microcode import FLAGSHIP_REGISTERS, flagship_names, flagship_routine
# the CONTROL word's bits are part of the numeric contract (the reference decodes them too)
from .numeric_contract import CONTROL_KEEP, CONTROL_RESET


__all__ = ["CONFIG_REGS", "CONTROL_ADDR", "CONTROL_RESET", "CONTROL_KEEP", "TELEMETRY_DIV_ADDR", "HOST_WRITABLE", "HOST_READ_ONLY", "REGS", "FILTERS",
           "FILTER_CODES", "FilterRoutine",
           "LOAD_BASE", "LOAD_ORDER", "TEMPS", "CONSTANTS", "build_program", "config_init",
           "load_words", "control_word"]

CONTROL_ADDR = REG_COUNT - 1


@dataclass(frozen=True)
class FilterRoutine:
    """One filter of the engine: its ``name`` (``reference.engine_model.EngineModel`` steps the
    filter of the same name), its ``code`` (CONTROL bits 1:0 and ``AttitudeFlags.filter``) and
    ``emit(asm, regs)``, which writes its microcode from the calibrated sample (G, A, M, the
    zero tests ACC_OK and MAG_OK) to QOUT, THETA and BIAS, ending in END or a branch to the
    ``angles_out`` tail."""
    name: str
    code: int
    emit: Callable


def control_word(filter="flagship", reset=False):
    """The CONTROL register value selecting ``filter`` (a name), with a filter reset."""
    return FILTER_CODES[filter] | (CONTROL_RESET if reset else 0)


CONFIG_REGS = {
    "ZERO": 0x00, "RATE": 0x01, "T": 0x02, "Q_ANGLE": 0x03, "Q_BIAS": 0x04, "R": 0x05,
    "P0": 0x06, "BIAS_SCALE": 0x07, "ONE_MINUS_A": 0x08, "INV_GAIN": 0x09, "SHL8": 0x1F,
    **{f"GYRO_OFF{i}": 0x0A + i for i in range(3)},
    **{f"ACC_OFF{i}": 0x0D + i for i in range(3)},
    **{f"ACC_SCALE{i}": 0x10 + i for i in range(3)},
    **{f"HARD{i}": 0x13 + i for i in range(3)},
    **{f"SOFT{i}{j}": 0x16 + 3 * i + j for i in range(3) for j in range(3)},
    **{name: 0x70 + k for k, name in enumerate(FLAGSHIP_REGISTERS)},
    "EULER_RATES": 0x7F,
    "TELEMETRY_DIV": 0xFE,
}
TELEMETRY_DIV_ADDR = CONFIG_REGS["TELEMETRY_DIV"]
# What the host may write: the run-time registers and CONTROL. The constants in the map (ZERO,
# INV_GAIN, SHL8) and everything from 0x20 (inputs, filter state, working registers, more
# constants) are read-only to the host: a write there would silently break the arithmetic.
HOST_READ_ONLY = ("ZERO", "INV_GAIN", "SHL8")
HOST_WRITABLE = frozenset({a for name, a in CONFIG_REGS.items() if name not in HOST_READ_ONLY} |
                          {CONTROL_ADDR})


def _allocate():
    names = []
    # inputs, written by the engine's loader: raw gyro, accel, AK8963 (AK axes), (ASA + 128)·2⁶;
    # first, at 0x20, so that the loader's address is its counter with 0b010 above it
    names += [f"GRAW{i}" for i in range(3)] + [f"ARAW{i}" for i in range(3)]
    names += [f"MRAW{i}" for i in range(3)] + [f"ASA{i}" for i in range(3)]
    # sample periods since the previous sample (1 + Sample.skipped), and STEP_N: the filter's
    # per-period rotation coefficient (RATE or K_RAD) times that
    names += ["NPER"]
    names += [f"THETA{i}" for i in range(3)] + [f"BIAS{i}" for i in range(3)]
    names += ["STEP_N"]
    names += [f"P{i}_{e}" for i in range(3) for e in ("00", "01", "10", "11")]
    names += [f"PREV{i}" for i in range(3)]
    # calibrated body-axis sensor values
    names += [f"G{i}" for i in range(3)] + [f"A{i}" for i in range(3)] + [f"M{i}" for i in range(3)]
    # MEAS3 takes the magnitude the heading's vectoring CORDIC writes beside MEAS2
    names += [f"PRED{i}" for i in range(3)] + [f"MEAS{i}" for i in range(4)]
    names += ["ACC_OK", "MAG_OK"]
    names += ["CR", "SR", "CP", "SP", "CY", "SY"]             # CORDIC result pairs (d, d+1)
    # constants (reset values; no program writes them): MUL by them with shift 14 shifts left
    names += [f"T{i}" for i in range(12)]
    names += ["QOUT0", "QOUT1", "QOUT2", "QOUT3"]           # the result quaternion
    names += list(CONSTANTS)
    names += flagship_names()
    regs = dict(CONFIG_REGS)
    free = (a for a in range(0x20, CONTROL_ADDR) if a not in CONFIG_REGS.values())
    for name in names:
        if name in regs:
            raise ValueError(f"register {name} allocated twice")
        regs[name] = next(free, None)
        if regs[name] is None:
            raise ValueError(f"the register file ({REG_COUNT} words) is full at {name}")
    return regs


# Constants (register-file reset values that no program writes): a MUL by SHL12/SHL15/ONE with
# shift 14 shifts left by 12/15/16; by HALF/EIGHTH/SHR10 with shift 30 halves, divides by 8 and
# by 2¹⁰ (rounded); the rest are operands of the flagship (``reference.flagship_fixed``).
CONSTANTS = {"SHL12": 1 << 26, "SHL15": 1 << 29, "ONE": 1 << 30, "HALF": 1 << 29,
             "EIGHTH": 1 << 27, "ONE_48": (1 << 30) // 48, "THREE_HALVES": 3 << 29,
             "SHR10": 1 << 20, "INT1": 1, "SHL14": 1 << 28, "COS_PITCH_MIN": 1 << 23,
             "SQRT2": round(math.sqrt(2) * (1 << 30))}


REGS = _allocate()
# Loader order: the sample's fields are written to these registers before the program runs.
TEMPS = [REGS[f"T{i}"] for i in range(12)]
LOAD_ORDER = ([f"GRAW{i}" for i in range(3)] + [f"ARAW{i}" for i in range(3)]
              + [f"MRAW{i}" for i in range(3)] + [f"ASA{i}" for i in range(3)] + ["NPER"])
LOAD_BASE = 0x20
assert [REGS[n] for n in LOAD_ORDER] == list(range(LOAD_BASE, LOAD_BASE + len(LOAD_ORDER)))


def load_words(gyro, accel, mag_ak, asa, skipped=0):
    """The words the loader writes, in ``LOAD_ORDER``, from a sample's fields and the ASA
    bytes: the fields as they are, (ASA + 128)·2⁶, so that the ASA product h·(ASA + 128)/2⁸
    rounds with a MUL_SHIFTS shift (14), and the periods since the previous sample, 1 +
    ``skipped``. Every word fits 16 bits, so the engine multiplexes 16 bits and sign-extends.
    Works on integers (the models) and on Amaranth values (the engine: an unsigned 8-bit ASA
    plus 128 is wiring, no adder)."""
    return [*gyro, *accel, *mag_ak, *((a + 128) << 6 for a in asa), skipped + 1]


def _euler_rates(asm, r, U, name):
    """``U`` (three registers, body rates in any one format) -> Euler-angle rates of THETA, in
    place (``reference.fixed_point.euler_rates_fixed``)."""
    asm.rot(r["CR"], r["THETA0"])                       # CR, SR = cos, sin of roll
    asm.rot(r["CP"], r["THETA1"])                       # CP, SP = cos, sin of pitch
    with asm.scratch(4) as (t, tp, sec, w):
        asm.sub(t, r["CP"], r["COS_PITCH_MIN"])
        asm.br(f"{name}_cp_ok", Cond.A_NEG, a=t, inv=True)
        asm.add(r["CP"], r["COS_PITCH_MIN"], r["ZERO"])
        asm.label(f"{name}_cp_ok")
        asm.div(tp, r["SP"], r["CP"])                   # tan θ, Q8.24
        asm.div(sec, r["ONE"], r["CP"])                 # 1 / cos θ, Q8.24
        asm.mac(w, [(r["SR"], U[1]), (r["CR"], U[2])], Q30)
        asm.mac(t, [(r["CR"], U[1]), (r["SR"], U[2], -1)], Q30)
        asm.mul(U[2], w, sec, Q24)
        asm.mul(w, w, tp, Q24)
        asm.add(U[1], t, r["ZERO"])
        asm.add(U[0], U[0], w)


def _step_n(asm, r, coefficient):
    """STEP_N = ``coefficient`` · NPER: the rotation of this update covers every period since
    the previous sample (a sample the sensor made but nobody read is integrated, not lost).
    Exact: NPER << 14 by a MUL with SHL14, then a MUL with shift 14; saturates (and flags)
    only for a coefficient times 16 beyond 32 bits."""
    asm.mul(r["STEP_N"], r["NPER"], r["SHL14"], Q14)
    asm.mul(r["STEP_N"], r[coefficient], r["STEP_N"], Q14)


def config_init(registers, inv_gain_q30):
    """Reset values of the register file: a list of REG_COUNT integers from ``registers``
    (values by name: the filters' coefficients and the calibration) and the constants."""
    init = [0] * REG_COUNT
    for name, value in registers.items():
        init[CONFIG_REGS[name]] = value
    init[CONFIG_REGS["INV_GAIN"]] = inv_gain_q30
    init[CONFIG_REGS["SHL8"]] = 1 << 22
    for name, value in CONSTANTS.items():
        init[REGS[name]] = value
    # the initial filter state is written by the INIT program, not here
    return init


def _init(asm, r):
    for i in range(3):
        asm.add(r[f"THETA{i}"], r["ZERO"], r["ZERO"])
        asm.add(r[f"BIAS{i}"], r["ZERO"], r["ZERO"])
        asm.add(r[f"P{i}_00"], r["P0"], r["ZERO"])
        asm.add(r[f"P{i}_01"], r["ZERO"], r["ZERO"])
        asm.add(r[f"P{i}_10"], r["ZERO"], r["ZERO"])
        asm.add(r[f"P{i}_11"], r["P0"], r["ZERO"])
    asm.end()


def _calibrate(asm, r):
    with asm.scratch(12) as T:
        for i in range(3):
            asm.sub(r[f"G{i}"], r[f"GRAW{i}"], r[f"GYRO_OFF{i}"], sat16=True)
        # the multiplier does not saturate to 16 bits: products go to temporaries, then an ADD
        # saturates them (sat16 of sat32 is sat16, so the result is the same)
        for i in range(3):
            asm.sub(T[i], r[f"ARAW{i}"], r[f"ACC_OFF{i}"])
        for i in range(3):
            asm.mul(T[i], T[i], r[f"ACC_SCALE{i}"], Q14)
        for j in range(3):                               # ASA: h·(ASA + 128)/256, AK axes
            asm.mul(T[3 + j], r[f"MRAW{j}"], r[f"ASA{j}"], Q14)       # ASA holds (ASA + 128)·2⁶
        for i in range(3):
            asm.add(r[f"A{i}"], T[i], r["ZERO"], sat16=True)
        # AK8963 -> body axes (x = y_ak, y = x_ak, z = −z_ak), minus the hard-iron offset
        d = T[9:12]
        asm.sub(d[0], T[4], r["HARD0"])
        asm.sub(d[1], T[3], r["HARD1"])
        asm.sub(d[2], r["ZERO"], T[5])
        asm.sub(d[2], d[2], r["HARD2"])
        for i in range(3):
            asm.mac(T[6 + i], [(r[f"SOFT{i}{j}"], d[j]) for j in range(3)], Q14)
        for i in range(3):
            asm.add(r[f"M{i}"], T[6 + i], r["ZERO"], sat16=True)


def _tilt(asm, r, roll):
    """roll = atan2(ay, az) into ``roll``, pitch = atan2(−ax, √(ay² + az²)) into ``roll`` + 1,
    inputs scaled by 2⁸. Clobbers ``roll`` + 2 (the vectoring CORDIC writes its magnitude
    beside the angle; the first one's is used for the pitch)."""
    with asm.scratch(4) as T:
        for i in range(3):
            asm.mul(T[i], r[f"A{i}"], r["SHL8"], Q14)           # a << 8
        asm.vec(roll, T[2], T[1])
        asm.mul(T[3], roll + 1, r["INV_GAIN"], Q30)
        asm.sub(T[0], r["ZERO"], T[0])
        asm.vec(roll + 1, T[3], T[0])


def _heading(asm, r, roll, pitch, out):
    """Tilt-compensated heading into ``out``; clobbers ``out`` + 1."""
    with asm.scratch(7) as T:
        asm.rot(r["CR"], roll)
        asm.rot(r["CP"], pitch)
        # (sine · m) >> 18 as (sine · (m << 12)) >> 30: the same bits, one rounding shift fewer
        ms = T[4:7]
        for i in range(3):
            asm.mul(ms[i], r[f"M{i}"], r["SHL12"], Q14)
        asm.mul(T[0], r["SP"], r["SR"], Q30)
        asm.mul(T[1], r["SP"], r["CR"], Q30)
        asm.mac(T[2], [(r["CP"], ms[0]), (T[0], ms[1]), (T[1], ms[2])], Q30)      # hx
        asm.mac(T[3], [(r["CR"], ms[1]), (r["SR"], ms[2], -1)], Q30)              # hy
        asm.vec(out, T[3], T[2])


def _zero_tests(asm, r, name):
    """ACC_OK = ax|ay|az; MAG_OK = mx|my|mz, or 0 when the sample's magnetometer is invalid."""
    asm.or_(r["ACC_OK"], r["A0"], r["A1"])
    asm.or_(r["ACC_OK"], r["ACC_OK"], r["A2"])
    asm.add(r["MAG_OK"], r["ZERO"], r["ZERO"])
    asm.br(f"{name}_mag_checked", Cond.MAG_INVALID)
    asm.or_(r["MAG_OK"], r["M0"], r["M1"])
    asm.or_(r["MAG_OK"], r["MAG_OK"], r["M2"])
    asm.label(f"{name}_mag_checked")


def _kalman_update(asm, r, i, z):
    with asm.scratch(12) as T:
        th, b = r[f"THETA{i}"], r[f"BIAS{i}"]
        p00, p01, p10, p11 = (r[f"P{i}_{e}"] for e in ("00", "01", "10", "11"))
        asm.add(T[4], p00, r["R"])                           # s
        asm.div(T[5], p00, T[4])                             # k0, Q0.24
        asm.div(T[6], p10, T[4])                             # k1, Q8.24
        asm.sub(T[7], z, th, wrap=True)                      # innovation y
        asm.mul(T[8], T[5], T[7], Q24)
        asm.mul(T[9], T[6], T[7], Q24)                        # k1·y, BAM/s
        asm.add(th, th, T[8], wrap=True)
        asm.mul(T[9], T[9], r["BIAS_SCALE"], Q24)
        asm.add(b, b, T[9])
        asm.mul(T[8], T[5], p00, Q24)
        asm.mul(T[9], T[5], p01, Q24)
        asm.mul(T[10], T[6], p00, Q24)
        asm.mul(T[11], T[6], p01, Q24)
        asm.sub(p00, p00, T[8])
        asm.sub(p01, p01, T[9])
        asm.sub(p10, p10, T[10])
        asm.sub(p11, p11, T[11])


def _kalman(asm, r):
    # the first sample after a reset takes ω₍ₖ₋₁₎ = ωₖ: out of line, so that every other
    # sample falls through (a taken branch costs two bubbles)
    asm.br("k_first", Cond.FIRST)
    asm.label("k_predict")
    _step_n(asm, r, "RATE")
    # the three axes interleaved, so that products follow products: a MUL followed by a MUL
    # that does not read its result takes one cycle instead of two
    P = [[r[f"P{i}_{e}"] for e in ("00", "01", "10", "11")] for i in range(3)]
    # U first: the Euler-rate transform takes four more scratch registers before TP and D live
    with asm.scratch(3) as U:
        for i in range(3):
            asm.add(U[i], r[f"PREV{i}"], r[f"G{i}"])
        for i in range(3):
            asm.mul(U[i], U[i], r["SHL15"], Q14)              # << 15 (exact: |ω| < 2¹⁶)
        asm.br("k_body_rates", Cond.A_ZERO, a=r["EULER_RATES"])
        _euler_rates(asm, r, U, "k")
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
    _zero_tests(asm, r, "k")
    asm.br("k_no_tilt", Cond.A_ZERO, a=r["ACC_OK"])
    _tilt(asm, r, r["MEAS0"])
    asm.label("k_no_tilt")
    asm.br("k_no_heading", Cond.A_ZERO, a=r["MAG_OK"])
    _heading(asm, r, r["THETA0"], r["THETA1"], r["MEAS2"])    # with the predicted tilt
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


def _complementary(asm, r):
    _step_n(asm, r, "RATE")
    asm.br("c_euler", Cond.A_ZERO, a=r["EULER_RATES"], inv=True)
    with asm.scratch(1) as T:
        for i in range(3):
            asm.mul(T[0], r[f"G{i}"], r["STEP_N"], Q14)                 # ω·RATE·n >> 14
            asm.add(r[f"PRED{i}"], r[f"THETA{i}"], T[0], wrap=True)
            asm.add(r[f"PREV{i}"], r[f"G{i}"], r["ZERO"])
        asm.label("c_predicted")
        _zero_tests(asm, r, "c")
        asm.add(r["MEAS0"], r["PRED0"], r["ZERO"])
        asm.add(r["MEAS1"], r["PRED1"], r["ZERO"])
        asm.br("c_no_tilt", Cond.A_ZERO, a=r["ACC_OK"])
        _tilt(asm, r, r["MEAS0"])
        asm.setf(Flag.ACC_USED)
        asm.label("c_no_tilt")
        asm.add(r["MEAS2"], r["PRED2"], r["ZERO"])
        asm.br("c_blend", Cond.A_ZERO, a=r["MAG_OK"])
        _heading(asm, r, r["PRED0"], r["PRED1"], r["MEAS2"])
        asm.setf(Flag.MAG_USED)
        asm.label("c_blend")
        for i in range(3):
            asm.sub(T[0], r[f"MEAS{i}"], r[f"PRED{i}"], wrap=True)
            asm.mul(T[0], r["ONE_MINUS_A"], T[0], Q24)
            asm.add(r[f"THETA{i}"], r[f"PRED{i}"], T[0], wrap=True)
        asm.br("angles_out")
    # out of line: the prediction with Euler-angle rates, in Q16 counts
    asm.label("c_euler")
    with asm.scratch(3) as U:
        for i in range(3):
            asm.mul(U[i], r[f"G{i}"], r["ONE"], Q14)                    # << 16
        _euler_rates(asm, r, U, "c")
        for i in range(3):
            asm.mul(U[i], U[i], r["STEP_N"], Q30)
            asm.add(r[f"PRED{i}"], r[f"THETA{i}"], U[i], wrap=True)
            asm.add(r[f"PREV{i}"], r[f"G{i}"], r["ZERO"])
    asm.br("c_predicted")


def _angles_out(asm, r):
    """The result quaternion of the per-axis filters' angles (``euler_quat_fixed``), then END."""
    with asm.scratch(4) as T:
        for i in range(3):
            asm.mul(T[i], r[f"THETA{i}"], r["HALF"], Q30)
        for i, pair in enumerate(("CR", "CP", "CY")):
            asm.rot(r[pair], T[i])
        cr, sr, cp, sp, cy, sy = (r[n] for n in ("CR", "SR", "CP", "SP", "CY", "SY"))
        cc, ss, cs, sc = T[0:4]
        asm.mul(cc, cy, cp, Q30)
        asm.mul(ss, sy, sp, Q30)
        asm.mul(cs, cy, sp, Q30)
        asm.mul(sc, sy, cp, Q30)
        asm.mac(r["QOUT0"], [(cr, cc), (sr, ss)], Q30)
        asm.mac(r["QOUT1"], [(sr, cc), (cr, ss, -1)], Q30)
        asm.mac(r["QOUT2"], [(cr, cs), (sr, sc)], Q30)
        asm.mac(r["QOUT3"], [(cr, sc), (sr, cs, -1)], Q30)
        asm.end()


def _flagship(asm, r):
    _zero_tests(asm, r, "f")
    _step_n(asm, r, "K_RAD")                # the routine's strapdown step uses STEP_N
    flagship_routine(asm, r)


# The filters, in ROM order: the first one is reached by falling through the dispatch. A new
# filter is one entry here, its routine, its run-time registers in CONFIG_REGS and its step in
# ``reference.engine_model.EngineModel``.
FILTERS = (FilterRoutine("kalman", 0, _kalman),
           FilterRoutine("complementary", 1, _complementary),
           FilterRoutine("flagship", 2, _flagship))
FILTER_CODES = {f.name: f.code for f in FILTERS}


def build_program():
    """(instructions, entry points {"init", "sample"})."""
    asm, r = Assembler(scratch_pool=tuple(TEMPS)), REGS
    asm.label("init")
    _init(asm, r)
    asm.label("sample")
    _calibrate(asm, r)
    for f in FILTERS[1:]:
        asm.br(f.name, Cond.FILTER, code=f.code)
    for f in FILTERS:
        asm.label(f.name)
        f.emit(asm, r)
    asm.label("angles_out")
    _angles_out(asm, r)
    return asm.resolve(), {"init": asm.labels["init"], "sample": asm.labels["sample"]}
