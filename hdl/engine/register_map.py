"""The attitude engine's register map: the run-time registers the host writes, CONTROL, the
loader's inputs, the filters' state and the constants (``REGS``), and the reset values.

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
0x76-77  REST_GYRO2,     flagship rest thresholds, counts² / 4: the gyro's and the    from LSB
         REST_ACC2       accelerometer's deviations from their low-passes
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
0x80     REST_BIAS2      flagship rest: the low-passed gyro's bound (the largest     10 °/s,
                         bias learnt at rest), counts² / 4                          from LSB
0x81     BETA_K          Madgwick's gradient step β·T·K²·2³⁰ (K: the CORDIC's      β = 0.1,
                         gain; ``numeric_contract.MadgwickFixedConfig``)            from dt
0xFE     TELEMETRY_DIV   (read by ``AHRSCore``, not the engine) frame every n-th     from baud
                         result (1..65535; 0 is taken as 1)
0xFF     CONTROL         (not a register-file word) bits 1:0 filter: 0 = per-axis
                         Kalman, 1 = complementary, 2 = flagship (the reset
                         default), 3 = Madgwick (``filter_registry``); bit 2:
                         write 1 to reset the filter state (angles 0, bias 0,
                         P = P0·I, flagship afresh); bit 3: keep the filter (bits
                         1:0 ignored: a reset alone). Selecting another filter
                         makes the next sample a first one. A word with a
                         reserved bit (31:4) set, or without keep a code that
                         names no filter (none, with four), is refused and
                         counted (``numeric_contract.control_fields``).
=======  ==============  =========================================================  ===========

From 0x20 (``REGS``): the loader's inputs, the filters' state, working registers and more
constants (``SHL12``, ``SHL15``, ``ONE``, ``HALF`` ...: reset values that no program writes); the
host need not know them. Reading back works for every word; writing works for the run-time
registers above and CONTROL only (``HOST_WRITABLE``): a write anywhere else is refused and
counted (the engine's ``cfg_refused``, carried in attitude frames).
"""

import math

from .attitude_isa import REG_COUNT
from ..contract.filter_registry import FILTER_CODES
from .filters import config_registers, state_registers
# the CONTROL word's bits are part of the numeric contract (the reference decodes them too)
from ..contract.numeric_contract import CONTROL_KEEP, CONTROL_RESET, MADGWICK_UNIT_BOUNDS


__all__ = ["CONFIG_REGS", "CONTROL_ADDR", "CONTROL_RESET", "CONTROL_KEEP", "TELEMETRY_DIV_ADDR",
           "HOST_WRITABLE", "HOST_READ_ONLY", "REGS", "LOAD_BASE", "LOAD_ORDER",
           "LOAD_EARLY", "TEMPS",
           "CONSTANTS", "config_init", "load_words", "control_word"]

CONTROL_ADDR = REG_COUNT - 1


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
    # the filters' run-time registers from 0x70 in the registry's order, around EULER_RATES
    **dict(zip(config_registers(), (a for a in range(0x70, 0xFE) if a != 0x7F))),
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
    # inputs, written by the engine's loader: raw gyro, accel, (ASA + 128)·2⁶, the sample
    # periods since the previous sample (1 + Sample.skipped; the calibration shifts it left by
    # 14 in place), then the AK8963's (AK axes), last: the loader writes them at the program's
    # SYNC (the early start, ``attitude_isa``), the others before the program starts; first,
    # at 0x20, so that the loader's address is its counter with 0b010 above it
    names += [f"GRAW{i}" for i in range(3)] + [f"ARAW{i}" for i in range(3)]
    names += [f"ASA{i}" for i in range(3)] + ["NPER"] + [f"MRAW{i}" for i in range(3)]
    # STEP_N: the filter's per-period rotation coefficient (RATE or K_RAD) times NPER
    names += ["STEP_N", "ACC_OK", "MAG_OK"]
    # the result's words (``PEEKED``, the framer reads them by index), from 0x30: a word's
    # address is its index with 0b0011 above it (no table of addresses in the engine)
    names += ["QOUT0", "QOUT1", "QOUT2", "QOUT3"]           # the result quaternion
    names += [f"THETA{i}" for i in range(3)] + [f"BIAS{i}" for i in range(3)]
    names += [f"P{i}_{e}" for i in range(3) for e in ("00", "01", "10", "11")]
    names += [f"PREV{i}" for i in range(3)]
    # calibrated body-axis sensor values
    names += [f"G{i}" for i in range(3)] + [f"A{i}" for i in range(3)] + [f"M{i}" for i in range(3)]
    # MEAS3 takes the magnitude the heading's vectoring CORDIC writes beside MEAS2
    names += [f"PRED{i}" for i in range(3)] + [f"MEAS{i}" for i in range(4)]
    names += ["CR", "SR", "CP", "SP", "CY", "SY"]             # CORDIC result pairs (d, d+1)
    # constants (reset values; no program writes them): MUL by them with shift 14 shifts left
    names += [f"T{i}" for i in range(12)]
    names += list(CONSTANTS)
    names += state_registers()
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
# by 2¹⁰ (rounded); UNIT_LO/HI: Madgwick's bounds of a quick normalisation
# (``numeric_contract.MADGWICK_UNIT_BOUNDS``); the rest are operands of the flagship
# (``reference.flagship_fixed``).
CONSTANTS = {"SHL12": 1 << 26, "SHL15": 1 << 29, "ONE": 1 << 30, "HALF": 1 << 29,
             "EIGHTH": 1 << 27, "ONE_48": (1 << 30) // 48, "THREE_HALVES": 3 << 29,
             "SHR10": 1 << 20, "INT1": 1, "SHL14": 1 << 28, "COS_PITCH_MIN": 1 << 23,
             "SQRT2": round(math.sqrt(2) * (1 << 30)),
             **dict(zip(("UNIT_LO", "UNIT_HI"), MADGWICK_UNIT_BOUNDS))}


REGS = _allocate()
# Loader order: the sample's fields are written to these registers before the program runs.
TEMPS = [REGS[f"T{i}"] for i in range(12)]
LOAD_ORDER = ([f"GRAW{i}" for i in range(3)] + [f"ARAW{i}" for i in range(3)]
              + [f"ASA{i}" for i in range(3)] + ["NPER"] + [f"MRAW{i}" for i in range(3)])
LOAD_BASE = 0x20
assert [REGS[n] for n in LOAD_ORDER] == list(range(LOAD_BASE, LOAD_BASE + len(LOAD_ORDER)))
# the words the loader writes before the program starts; the rest (the AK8963's) at its SYNC
LOAD_EARLY = LOAD_ORDER.index("MRAW0")


def load_words(gyro, accel, mag_ak, asa, skipped=0):
    """The words the loader writes, in ``LOAD_ORDER``, from a sample's fields and the ASA
    bytes: the fields as they are, (ASA + 128)·2⁶, so that the ASA product h·(ASA + 128)/2⁸
    rounds with a MUL_SHIFTS shift (14), and the periods since the previous sample, 1 +
    ``skipped``. Every word fits 16 bits, so the engine multiplexes 16 bits and sign-extends.
    Works on integers (the models) and on Amaranth values (the engine: an unsigned 8-bit ASA
    plus 128 is wiring, no adder)."""
    return [*gyro, *accel, *((a + 128) << 6 for a in asa), skipped + 1, *mag_ak]


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
