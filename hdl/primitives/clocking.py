"""The system clock: one default, the conversion of times to cycles, and the PLLs (the MAX10's
``SystemPLL``, the ECP5's ``ECP5PLL`` for ``build --board ulx3s``).

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


__all__ = ["OSCILLATOR_HZ", "SYSTEM_CLOCK_HZ", "cycles", "ticks", "pll_ratio", "SystemPLL",
           "ecp5_pll_dividers", "ECP5PLL"]


OSCILLATOR_HZ = 12e6
SYSTEM_CLOCK_HZ = 48e6


def cycles(seconds, clk_freq, *, minimum=1):
    """Whole clock cycles that last at least ``seconds`` at ``clk_freq`` (never fewer than
    ``minimum``). The 1e-9 forgives float noise in exact products such as 100 µs × 12 MHz."""
    return max(minimum, math.ceil(seconds * clk_freq - 1e-9))


def ticks(cycles_, tick_cycles, *, exact):
    """The count a timer of ticks (a pulse every ``tick_cycles`` cycles, at any phase) must
    reach to last at least ``cycles_`` cycles: ⌈``cycles_`` / ``tick_cycles``⌉ + 1 (the first
    tick may come at once). With ``tick_cycles`` 1 every cycle is a tick and the count is
    ``exact``, the caller's own count of cycles. A ValueError for a tick under a cycle."""
    if tick_cycles < 1:
        raise ValueError(f"a tick of {tick_cycles} cycles: at least 1")
    if tick_cycles == 1:
        return exact
    return -(-cycles_ // tick_cycles) + 1


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


# ECP5 EHXPLLL limits (Lattice TN1263, "ECP5 and ECP5-5G sysCLOCK PLL/DLL Design and Usage
# Guide"): phase detector 3.125..400 MHz, VCO 400..800 MHz, dividers 1..128.
ECP5_PFD_HZ = (3.125e6, 400e6)
ECP5_VCO_HZ = (400e6, 800e6)


def ecp5_pll_dividers(in_hz, out_hz):
    """EHXPLLL dividers that make exactly ``out_hz`` (to 1 Hz) on CLKOS from ``in_hz``, the
    feedback taken internally from CLKOP (``INT_OP``): VCO = in/CLKI_DIV · CLKFB_DIV ·
    CLKOP_DIV, CLKOS = VCO/CLKOS_DIV. Feeding back through CLKOP rather than the output
    itself reaches ratios CLKOP feedback alone cannot (25 MHz → 48 MHz: CLKOP alone gives
    46.875). A dict (``clki_div``, ``clkfb_div``, ``clkop_div``, ``clkos_div``, ``vco_hz``),
    the highest VCO first (lower jitter); a ValueError when none is exact."""
    found = []
    for clki in range(1, 129):
        pfd = in_hz / clki
        if not ECP5_PFD_HZ[0] <= pfd <= ECP5_PFD_HZ[1]:
            continue
        for clkfb in range(1, 129):
            for clkop in range(1, 129):
                vco = pfd * clkfb * clkop
                if vco > ECP5_VCO_HZ[1]:
                    break
                if vco < ECP5_VCO_HZ[0]:
                    continue
                clkos = round(vco / out_hz)
                if 1 <= clkos <= 128 and abs(vco / clkos - out_hz) <= 1:
                    found.append({"clki_div": clki, "clkfb_div": clkfb, "clkop_div": clkop,
                                  "clkos_div": clkos, "vco_hz": vco})
    if not found:
        raise ValueError(f"an ECP5 PLL cannot make {out_hz / 1e6:g} MHz from "
                         f"{in_hz / 1e6:g} MHz exactly")
    return max(found, key=lambda d: (d["vco_hz"], -d["clki_div"]))


class ECP5PLL(wiring.Component):
    """A Lattice ECP5 PLL (``EHXPLLL``) making the system clock from the oscillator, for
    ``build --board ulx3s``.

    Parameters
    ----------
    in_hz, out_hz : float
        The oscillator's and the system clock's frequencies (``ecp5_pll_dividers``).

    Members
    -------
    clk_in : In(1)
        Oscillator clock.
    clk_out : Out(1)
        System clock (CLKOS).
    locked : Out(1)
        The PLL is locked (asynchronous: ``BoardTop`` releases the reset through a
        ``ResetSynchronizer``).

    Only the ECP5 tools can elaborate the instance. Latency: none (a clock source).
    """
    def __init__(self, *, in_hz, out_hz=SYSTEM_CLOCK_HZ):
        self.dividers = ecp5_pll_dividers(in_hz, out_hz)
        self.in_hz, self.out_hz = in_hz, out_hz
        super().__init__({"clk_in": In(1), "clk_out": Out(1), "locked": Out(1)})

    def elaborate(self, platform):
        m = Module()
        d = self.dividers
        feedback = Signal()
        m.submodules.pll = Instance(
            "EHXPLLL",
            a_FREQUENCY_PIN_CLKI=f"{self.in_hz / 1e6:g}",
            a_FREQUENCY_PIN_CLKOS=f"{self.out_hz / 1e6:g}",
            a_ICP_CURRENT="12", a_LPF_RESISTOR="8",
            a_MFG_ENABLE_FILTEROPAMP="1", a_MFG_GMCREF_SEL="2",
            p_PLLRST_ENA="DISABLED", p_INTFB_WAKE="DISABLED", p_STDBY_ENABLE="DISABLED",
            p_DPHASE_SOURCE="DISABLED",
            p_OUTDIVIDER_MUXA="DIVA", p_OUTDIVIDER_MUXB="DIVB",
            p_CLKI_DIV=d["clki_div"],
            p_CLKOP_ENABLE="ENABLED", p_CLKOP_DIV=d["clkop_div"],
            p_CLKOP_CPHASE=d["clkop_div"] - 1, p_CLKOP_FPHASE=0,
            p_CLKOS_ENABLE="ENABLED", p_CLKOS_DIV=d["clkos_div"],
            p_CLKOS_CPHASE=d["clkos_div"] - 1, p_CLKOS_FPHASE=0,
            p_FEEDBK_PATH="INT_OP", p_CLKFB_DIV=d["clkfb_div"],
            i_CLKI=self.clk_in, i_CLKFB=feedback, o_CLKINTFB=feedback,
            i_RST=0, i_STDBY=0, i_PHASESEL0=0, i_PHASESEL1=0, i_PHASEDIR=1, i_PHASESTEP=1,
            i_PHASELOADREG=1, i_PLLWAKESYNC=0, i_ENCLKOP=0, i_ENCLKOS=0,
            o_CLKOS=self.clk_out, o_LOCK=self.locked,
        )
        return m
