"""The system clock: one default, the conversion of times to cycles, and the MAX10 PLL.

``SYSTEM_CLOCK_HZ`` is the clock every part of the design, ``build``, ``simulate`` and
``report`` use unless told otherwise (``--clk-freq``). On the board it comes from
``SystemPLL``: the 12 MHz oscillator (``OSCILLATOR_HZ``) multiplied by 4 in a MAX10 PLL.
The SPI read clock and the update time at this clock are what ``SPITiming.for_clock`` and
``python -m mpu9250_ahrs report`` give; whether the design closes timing at 48 MHz is for
Quartus' timing analysis to say (there is no Quartus here).
"""

import math
from fractions import Fraction

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out


__all__ = ["OSCILLATOR_HZ", "SYSTEM_CLOCK_HZ", "cycles", "pll_ratio", "SystemPLL"]


OSCILLATOR_HZ = 12e6
SYSTEM_CLOCK_HZ = 48e6


def cycles(seconds, clk_freq, *, minimum=1):
    """Whole clock cycles that last at least ``seconds`` at ``clk_freq`` (never fewer than
    ``minimum``). The 1e-9 forgives float noise in exact products such as 100 µs × 12 MHz."""
    return max(minimum, math.ceil(seconds * clk_freq - 1e-9))


def pll_ratio(in_hz, out_hz):
    """(multiply, divide) making ``out_hz`` from ``in_hz``, both at most 512; a ValueError
    when no such ratio gives the frequency to within 1 Hz."""
    ratio = Fraction(out_hz / in_hz).limit_denominator(512)
    if abs(float(ratio) * in_hz - out_hz) > 1 or ratio.numerator > 512:
        raise ValueError(f"a PLL cannot make {out_hz / 1e6:g} MHz from {in_hz / 1e6:g} MHz "
                         f"with multiply/divide factors up to 512")
    return ratio.numerator, ratio.denominator


class SystemPLL(wiring.Component):
    """A MAX10 PLL (Quartus ``altpll``) making the system clock from the oscillator.

    Parameters
    ----------
    in_hz : float
        Frequency of ``clk_in`` (the board's oscillator).
    out_hz : float
        Frequency wanted on ``clk_out``; it must be ``in_hz`` times a ratio of small integers
        (multiply and divide at most 512), e.g. 12 MHz × 4 = 48 MHz.

    Members
    -------
    clk_in : In(1)
        Oscillator clock.
    clk_out : Out(1)
        System clock (PLL output c0).
    locked : Out(1)
        The PLL is locked. It is asynchronous to ``clk_out``: ``BoardTop`` holds the design in
        reset through a ``ResetSynchronizer`` until it rises.

    Only Quartus can elaborate the instance; simulations drive the system clock directly.
    Latency: none (a clock source); ``locked`` rises after the PLL's lock time, which Quartus'
    device data gives (there is no Quartus here).
    """
    def __init__(self, *, in_hz=OSCILLATOR_HZ, out_hz=SYSTEM_CLOCK_HZ):
        self.multiply, self.divide = pll_ratio(in_hz, out_hz)
        self.in_hz, self.out_hz = in_hz, out_hz
        super().__init__({"clk_in": In(1), "clk_out": Out(1), "locked": Out(1)})

    def elaborate(self, platform):
        m = Module()
        clk = Signal(5)
        m.submodules.pll = Instance(
            "altpll",
            p_intended_device_family="MAX 10",
            p_lpm_type="altpll",
            p_operation_mode="NORMAL",
            p_pll_type="AUTO",
            p_width_clock=5,
            p_inclk0_input_frequency=int(round(1e12 / self.in_hz)),    # period in ps
            p_clk0_multiply_by=self.multiply,
            p_clk0_divide_by=self.divide,
            p_clk0_duty_cycle=50,
            p_clk0_phase_shift="0",
            p_port_clk0="PORT_USED",
            p_port_locked="PORT_USED",
            p_port_inclk0="PORT_USED",
            p_port_areset="PORT_UNUSED",
            i_inclk=Cat(self.clk_in, C(0, 1)),
            o_clk=clk,
            o_locked=self.locked,
        )
        m.d.comb += self.clk_out.eq(clk[0])
        return m
