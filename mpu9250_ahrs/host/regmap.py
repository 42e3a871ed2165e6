"""The register map by name, with formats and units: the host converts physical values to
register words and back (``config get`` / ``config set``).

Names are those of ``hdl/engine/register_map.py`` (engine, space 0x00), ``BOARD_REGS`` (space
0x01), ``PWM_REGS`` (space 0x02) and ``BALANCE_REGS`` (space 0x03, a build with the balance
controller: others answer bad_address); ``hdl/FRAMES.md`` lists them.
"""

import math
from dataclasses import dataclass

from ..hdl.engine.register_map import CONFIG_REGS, CONTROL_ADDR, HOST_WRITABLE
from ..hdl.contract.commands import BOARD_REGS
from ..hdl.contract.pwm_regs import PWM_REGS
from ..hdl.contract.balance_regs import BALANCE_REGS, BALANCE_WIDTHS


__all__ = ["Register", "REGISTERS", "lookup", "to_word", "from_word", "value_range"]


@dataclass(frozen=True)
class Register:
    name: str
    space: str             # "engine", "board", "pwm", "control"
    addr: int
    format: str            # "int", "Q8.24", "Q0.24", "Q2.14", "Q0.30", "BAM32"
    unit: str
    writable: bool


# The fraction bits of each format; BAM32: 2³² = 360°.
_FRACTION = {"Q8.24": 24, "Q0.24": 24, "Q2.14": 14, "Q0.30": 30}

_ENGINE_FORMATS = {
    "T": ("Q0.24", "s"), "Q_ANGLE": ("Q8.24", "deg²"), "Q_BIAS": ("Q8.24", "(°/s)²"),
    "R": ("Q8.24", "deg²"), "P0": ("Q8.24", ""), "BIAS_SCALE": ("Q8.24", ""),
    "ONE_MINUS_A": ("Q0.24", ""), "INV_GAIN": ("Q0.30", ""), "GATE_NORM": ("Q0.30", ""),
    "GATE_DIP": ("BAM32", "°"), "A_REF": ("Q0.30", ""), "BETA_K": ("Q0.30", "β·T·K²"),
    **{f"ACC_SCALE{i}": ("Q2.14", "") for i in range(3)},
    **{f"SOFT{i}{j}": ("Q2.14", "") for i in range(3) for j in range(3)},
    **{f"{n}{i}": ("int", "counts") for n in ("GYRO_OFF", "ACC_OFF", "HARD") for i in range(3)},
    **{n: ("Q0.30", "") for n in ("A_DET", "A_REST", "A_ACC", "A_MAG", "A_MAG_FAST")},
    **{n: ("int", "samples") for n in ("K_REST", "K_REF", "K_FAST", "K_NEW")},
    "REST_GYRO2": ("int", "counts²/4"), "REST_ACC2": ("int", "counts²/4"),
    "REST_BIAS2": ("int", "counts²/4"),
    "TELEMETRY_DIV": ("int", "results"),
}


def _registers():
    regs = {}
    for name, addr in CONFIG_REGS.items():
        fmt, unit = _ENGINE_FORMATS.get(name, ("int", ""))
        regs[name] = Register(name, "engine", addr, fmt, unit, addr in HOST_WRITABLE)
    regs["CONTROL"] = Register("CONTROL", "engine", CONTROL_ADDR, "int", "", True)
    for name, addr in BOARD_REGS.items():
        regs[name] = Register(name, "board", addr, "int", "", name == "RAW_MODE")
    for name, addr in PWM_REGS.items():
        unit = {"PWM_WATCHDOG_MS": "ms", "PWM_SERVO_PERIOD": "µs",
                "PWM_MOTOR_PERIOD": "cycles"}.get(name, "µs (servo) or cycles (motor)"
                                                   if name.startswith("PWM_HIGH") else "")
        regs[name] = Register(name, "pwm", addr, "int", unit, name != "PWM_STATUS")
    for name, addr in BALANCE_REGS.items():
        regs[name] = Register(name, "control", addr, "int", "", name in BALANCE_WIDTHS)
    return regs


REGISTERS = _registers()


def lookup(name):
    try:
        return REGISTERS[name.upper()]
    except KeyError:
        raise ValueError(f"no register {name!r}; known: {', '.join(sorted(REGISTERS))}") from None


# Physical ranges of the engine registers whose meaning bounds them (inclusive), beyond their
# format: a value outside is refused before anything is sent (a sample period of 200 s would
# wrap to -56 s in Q0.24's signed word).
_RANGES = {
    "T": (1 / 32_000, 1.0), "TELEMETRY_DIV": (1, 65_535), "EULER_RATES": (0, 1),
    "CONTROL": (0, 15),
    **{n: (0.0, None) for n in ("Q_ANGLE", "Q_BIAS", "R", "P0")},
    **{n: (0.0, 1.0) for n in ("ONE_MINUS_A", "A_DET", "A_REST", "A_ACC", "A_MAG",
                               "A_MAG_FAST", "A_REF")},
    **{n: (0, None) for n in ("K_REST", "K_REF", "K_FAST", "K_NEW", "REST_GYRO2",
                              "REST_ACC2", "REST_BIAS2")},
    # the calibration's offsets are counts of the 16-bit readings (as build --calibration's)
    **{f"{n}{i}": (-2 ** 15, 2 ** 15 - 1) for n in ("GYRO_OFF", "ACC_OFF", "HARD")
       for i in range(3)},
}


def value_range(reg):
    """(lowest, highest) physical value ``reg`` takes (None: no bound but its format's)."""
    if reg.space == "control" and reg.name in BALANCE_WIDTHS:
        return BALANCE_WIDTHS[reg.name][2:]                 # the controller's own ranges
    if reg.space != "engine":
        return 0, 2 ** 32 - 1
    if reg.format == "int":
        lo, hi = -2 ** 31, 2 ** 31 - 1                      # the engine's words are signed 32
    elif reg.format == "BAM32":
        lo, hi = -180.0, 180.0 - 360 / 2 ** 32           # 180° is -180°
    else:
        # Qm.f: m integer bits with the sign (signed, [-2^(m-1), 2^(m-1))), or with m = 0 an
        # unsigned fraction [0, 1)
        whole = int(reg.format[1:].split(".")[0])
        ulp = 2.0 ** -_FRACTION[reg.format]
        lo, hi = (-2.0 ** (whole - 1), 2.0 ** (whole - 1) - ulp) if whole else (0.0, 1 - ulp)
    own_lo, own_hi = _RANGES.get(reg.name, (None, None))
    return (lo if own_lo is None else max(lo, own_lo)), (hi if own_hi is None else min(hi, own_hi))


def to_word(reg, value):
    """A physical value (a number, or an int with ``0x``) -> the 32-bit register word; a value
    out of the register's range (``value_range``) is refused with the range."""
    if isinstance(value, str):
        text = value.strip()
        try:
            value = int(text, 0) if reg.format == "int" else float(text)
        except ValueError:
            raise ValueError(f"{reg.name}: {text!r} is not "
                             f"{'an integer' if reg.format == 'int' else 'a number'}") from None
    if not math.isfinite(value):
        raise ValueError(f"{reg.name}: {value} is not a finite number")
    if reg.format == "int" and value != int(value):
        raise ValueError(f"{reg.name} takes an integer, not {value}")
    # the range first: a value far out (1e308) would overflow the conversion below
    lo, hi = value_range(reg)
    if not lo <= value <= hi:
        unit = f" {reg.unit}" if reg.unit and reg.format != "int" else ""
        raise ValueError(f"{reg.name}: {value:g} is out of range {lo:.6g} .. {hi:.6g}{unit} "
                         f"({reg.format})")
    if reg.format == "int":
        word = int(value)
    elif reg.format == "BAM32":
        word = round(value / 360 * 2 ** 32)
    else:
        word = round(value * 2 ** _FRACTION[reg.format])
    if not -2 ** 31 <= word < 2 ** 32:
        raise ValueError(f"{reg.name}: {value} does not fit its format {reg.format}")
    return word


def from_word(reg, word):
    """A register word (as read: signed 32 from the engine) -> the physical value."""
    word = int(word)
    if reg.space == "control" and BALANCE_WIDTHS.get(reg.name, (0, False))[1]:
        return word - 2 ** 32 if word >= 2 ** 31 else word      # a signed register, extended
    if reg.format == "int":
        return word
    signed = word - 2 ** 32 if word >= 2 ** 31 else word
    if reg.format == "BAM32":
        return signed * 360 / 2 ** 32
    return signed / 2 ** _FRACTION[reg.format]
