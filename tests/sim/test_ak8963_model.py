"""The AK8963 model at register level."""

import pytest

from mpu9250_ahrs.hdl.contract import ak8963_regs as A
from mpu9250_ahrs.sim.models.ak8963_model import AK8963Model, AK8963Timing, constant_field


def read(m, addr, n=1):
    """A burst read as a bus does it: pointer, auto-increment, wrap."""
    m.begin_read()
    out = []
    m.pointer = addr
    for _ in range(n):
        out.append(m.read_reg(m.pointer))
        m.pointer = m.next_address(m.pointer)
    return out


def at(m, t):
    m.advance(t)
    return m


def kinds(m):
    return [v.kind for v in m.violations]


def continuous_100hz(m, t=0.0, bit16=True):
    at(m, t).write_reg(A.CNTL1, (A.CNTL1_BIT_16 if bit16 else 0) | A.MODE_CONT_100HZ)


def test_identity_and_reset_values():
    m = AK8963Model()
    assert read(m, A.WIA, 2) == [0x48, 0x9A]
    assert read(m, A.CNTL1) == [0]
    assert m.violations == []


def test_fuse_rom_only_in_fuse_mode():
    m = AK8963Model(asa=(100, 128, 200))
    assert read(m, A.ASAX) == [0] and kinds(m) == ["ASA read outside fuse-ROM mode"]
    m.violations.clear()
    m.write_reg(A.CNTL1, A.MODE_FUSE_ROM)
    assert read(m, A.ASAX, 4) == [100, 128, 200, 100]          # wraps 0x12 -> 0x10
    assert m.violations == []


def test_auto_increment_wraps_at_0x0c():
    m = AK8963Model()
    assert [m.next_address(a) for a in (0x0B, 0x0C, 0x10, 0x12)] == [0x0C, 0x00, 0x11, 0x10]


def test_continuous_measurement_little_endian_and_status():
    m = AK8963Model(source=constant_field(0x1234, -2, 300))
    continuous_100hz(m)
    at(m, 0.0101)
    data = read(m, A.ST1, A.SAMPLE_BYTES)
    assert data == [A.ST1_DRDY, 0x34, 0x12, 0xFE, 0xFF, 0x2C, 0x01, A.ST2_BITM]
    assert read(m, A.ST1) == [0]                        # DRDY cleared by the read


def test_14_bit_mode():
    m = AK8963Model(source=constant_field(400, -400, 8))
    continuous_100hz(m, bit16=False)
    at(m, 0.011)
    data = read(m, A.ST1, A.SAMPLE_BYTES)
    assert data[1:7] == [100, 0, 0x9C, 0xFF, 2, 0] and data[7] == 0


def test_overflow_sets_hofl():
    m = AK8963Model(source=constant_field(20000, 10000, 3000))   # 4950 µT in sum
    continuous_100hz(m)
    at(m, 0.011)
    assert read(m, A.ST2) == [A.ST2_HOFL | A.ST2_BITM]


def test_data_protection_and_overrun():
    m = AK8963Model(source=lambda i, t: (i, 0, 0))
    continuous_100hz(m)
    at(m, 0.0101)
    assert read(m, A.HXL) == [0]                       # protection starts
    at(m, 0.0201)                                      # so measurement 1 is skipped
    assert m.skipped == 1 and m.regs[A.ST1] & A.ST1_DOR
    assert read(m, A.HXL) == [0]                       # still frozen
    read(m, A.ST2)                                     # ends protection, clears DRDY/DOR
    assert m.regs[A.ST1] == 0
    at(m, 0.0301)
    assert read(m, A.ST1, 2) == [A.ST1_DRDY, 2]        # measurement 2 (1 was skipped)


def test_unread_data_overwritten_sets_dor():
    m = AK8963Model()
    continuous_100hz(m)
    at(m, 0.0201)
    assert read(m, A.ST1) == [A.ST1_DRDY | A.ST1_DOR]


def test_mode_change_rules():
    m = AK8963Model(timing=AK8963Timing(power_down_s=100e-6))
    continuous_100hz(m)
    at(m, 0.001).write_reg(A.CNTL1, A.MODE_FUSE_ROM)
    assert kinds(m) == ["mode change without power-down"]
    m.violations.clear()
    at(m, 0.002).write_reg(A.CNTL1, A.MODE_POWER_DOWN)
    at(m, 0.002 + 50e-6).write_reg(A.CNTL1, A.MODE_FUSE_ROM)
    assert kinds(m) == ["power-down wait"]
    m.violations.clear()
    at(m, 0.003).write_reg(A.CNTL1, A.MODE_POWER_DOWN)
    at(m, 0.003 + 101e-6).write_reg(A.CNTL1, A.MODE_FUSE_ROM)
    assert m.violations == []


def test_single_measurement_returns_to_power_down():
    m = AK8963Model(source=constant_field(7, 8, 9))
    m.write_reg(A.CNTL1, A.CNTL1_BIT_16 | A.MODE_SINGLE)
    at(m, 0.0073)
    assert m.mode == A.MODE_POWER_DOWN and read(m, A.ST1, 2) == [A.ST1_DRDY, 7]


def test_soft_reset():
    m = AK8963Model()
    continuous_100hz(m)
    m.write_reg(A.CNTL2, A.CNTL2_SRST)
    assert m.mode == A.MODE_POWER_DOWN and read(m, A.CNTL1) == [0]


def test_read_only_registers():
    m = AK8963Model()
    m.write_reg(A.WIA, 0)
    assert kinds(m) == ["write to a read-only register"]


def test_asa_adjustment_formula():
    assert A.asa_adjust(1000, 128) == 1000
    assert A.asa_adjust(1000, 255) == pytest.approx(1496.09375)
    assert A.asa_adjust(1000, 0) == 500


def test_self_test_measures_its_own_field_once():
    """Self-test mode with ASTC.SELF: one measurement of the generator's field (not the
    source's), then power-down; without SELF it measures the field as a single one would."""
    m = AK8963Model(source=constant_field(7, 8, 9), self_test_field=(30, -20, -1500))
    m.write_reg(A.ASTC, A.ASTC_SELF)
    m.write_reg(A.CNTL1, A.CNTL1_BIT_16 | A.MODE_SELF_TEST)
    at(m, 0.0073)
    assert m.mode == A.MODE_POWER_DOWN
    data = read(m, A.ST1, 8)
    assert data[0] == A.ST1_DRDY
    assert [int.from_bytes(bytes(data[1 + 2 * i:3 + 2 * i]), "little", signed=True)
            for i in range(3)] == [30, -20, -1500]
    m.write_reg(A.ASTC, 0)
    at(m, 0.0080).write_reg(A.CNTL1, A.CNTL1_BIT_16 | A.MODE_SELF_TEST)
    at(m, 0.0160)
    assert read(m, A.HXL, 2) == [7, 0] and kinds(m) == []
