"""The host's register map: physical values to words and back, and values out of a register's
range refused with the range (never wrapped)."""

import pytest

from mpu9250_ahrs.host.regmap import REGISTERS, from_word, lookup, to_word, value_range


@pytest.mark.parametrize("name,value,message", [
    # issue #25: a sample period of 200 s wrapped to -56 s in Q0.24's signed word
    ("T", "200", "T: 200 is out of range 3.125e-05 .. 1 s"),
    ("T", "0", "out of range"),
    ("R", "-1", "R: -1 is out of range 0 .."),
    ("SOFT00", "2", "out of range -2 .. 1.99994"),
    ("TELEMETRY_DIV", "0", "out of range 1 .. 65535"),
    ("CONTROL", "16", "out of range 0 .. 15"),
    ("A_ACC", "1.5", "out of range 0 .. 1"),
    ("GYRO_OFF0", str(2 ** 31), "out of range"),
    # issue #60: a traceback (OverflowError), and a count beyond 16 bits accepted
    ("T", "1e308", "T: 1e+308 is out of range"),
    ("GYRO_OFF0", "100000", "GYRO_OFF0: 100000 is out of range -32768 .. 32767"),
    ("HARD2", "-40000", "out of range -32768"),
    ("GATE_DIP", "nan", "not a finite number"),
    # (Python's "invalid literal for int() with base 0" before)
    ("PWM_HIGH0", "abc", "PWM_HIGH0: 'abc' is not an integer"),
    ("R", "1,5", "R: '1,5' is not a number"),
])
def test_out_of_range_values_are_refused_with_the_range(name, value, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(".", r"\.")
                       .replace("*", r"\*").replace("+", r"\+")):
        to_word(lookup(name), value)


def test_every_register_round_trips_its_range_ends():
    """The ends of every engine register's range convert and read back (within a step)."""
    for reg in REGISTERS.values():
        if reg.space != "engine":
            continue
        lo, hi = value_range(reg)
        for value in (lo, hi):
            word = to_word(reg, value)
            signed = word - 2 ** 32 if word >= 2 ** 31 else word
            back = from_word(reg, signed)
            step = 360 / 2 ** 32 if reg.format == "BAM32" else (
                1 if reg.format == "int" else 2.0 ** -int(reg.format.split(".")[1]))
            assert abs(back - value) <= step, (reg.name, value, back)


def test_the_balance_controllers_registers_by_name():
    """Space 0x03 (issue #57): each BAL_ register by name with the controller's own range; a
    signed one written as its two's complement and read back signed; the read-only ones (status,
    duty) not writable."""
    from mpu9250_ahrs.hdl.contract.balance_regs import BALANCE_REGS, BALANCE_WIDTHS
    for name, addr in BALANCE_REGS.items():
        reg = lookup(name)
        assert (reg.space, reg.addr, reg.writable) == ("control", addr, name in BALANCE_WIDTHS)
    kp = lookup("BAL_KP")
    assert value_range(kp) == (-(1 << 17), (1 << 17) - 1)
    assert to_word(kp, "-5") == -5 and from_word(kp, 2 ** 32 - 5) == -5
    with pytest.raises(ValueError, match="BAL_STALE: 0 is out of range 1 .. 255"):
        to_word(lookup("BAL_STALE"), "0")
