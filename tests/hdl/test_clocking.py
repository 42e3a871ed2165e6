"""The clock module: one default, seconds to cycles, and the PLL's ratio."""

import pytest

from amaranth.back import verilog

from mpu9250_ahrs.hdl.primitives.clocking import (OSCILLATOR_HZ, SYSTEM_CLOCK_HZ, SystemPLL, cycles,
                                                  pll_ratio)


def test_cycles_rounds_up_and_forgives_float_noise():
    assert cycles(100e-6, 12e6) == 1200            # 100e-6 * 12e6 is 1200.0000000000002
    assert cycles(1e-9, 48e6) == 1 and cycles(0, 48e6, minimum=0) == 0
    assert cycles(21e-9, 48e6) == 2


def test_pll_ratio():
    multiply, divide = pll_ratio(OSCILLATOR_HZ, SYSTEM_CLOCK_HZ)
    assert (multiply, divide) == (4, 1)
    assert pll_ratio(12e6, 36e6) == (3, 1) and pll_ratio(12e6, 50e6) == (25, 6)
    with pytest.raises(ValueError, match="cannot make"):
        pll_ratio(12e6, 48.0001e6)


def test_pll_instance_parameters():
    text = verilog.convert(SystemPLL(), name="pll")
    for parameter in (".clk0_multiply_by(32'd4)", ".clk0_divide_by(32'd1)",
                      ".inclk0_input_frequency(32'd83333)", '.intended_device_family("MAX 10")'):
        assert parameter in text
