"""The attitude engine's adder: ADD or SUB of two 32-bit registers, then wrapped (angles), or
saturated to 32 or 16 bits."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out


__all__ = ["ALU", "saturate"]


def saturate(m, value, bits, *, keep=C(0)):
    """(clamped value, clamped?) of a signed value to a signed ``bits``-bit range. It fits when
    the bits from ``bits`` − 1 up are all equal (a reduction, cheaper than two comparators).
    ``keep``: the low ``bits`` go through unclamped (wrapped) whatever the flag says."""
    top = value[bits - 1:]
    fits = (top == 0) | (top == (1 << len(top)) - 1)
    sign = value[-1]
    out, flag = Signal(signed(bits)), Signal()
    hi = (1 << (bits - 1)) - 1
    m.d.comb += [flag.eq(~fits),
                 out.eq(Mux(fits | keep, value[:bits],
                            Mux(sign, C(hi + 1, bits), C(hi, bits))))]
    return out, flag


class ALU(wiring.Component):
    """One adder for a ± b (exact at 33 bits), then the result wrapped to 32 bits or saturated
    to 32 bits, or to 16 (calibrated sensor values: sat16 of sat32, which is sat16). No OR:
    the zero tests it served are register tests (``filters.shared.zero_tests``), and its
    choice cost a LUT a bit (``report``).

    Members
        ``a``, ``b`` (in, signed 32): the operands.
        ``sub`` (in): a − b instead of a + b.
        ``wrap`` (in): wrap instead of saturating (angles in BAM32); ``sat16`` (in): saturate
            to 16 bits.
        ``result`` (out, signed 32), ``saturated`` (out): a clamp happened (never with wrap).
    Latency 0 (combinational); the engine writes ``result`` back in the same cycle.
    """
    a: In(signed(32))
    b: In(signed(32))
    sub: In(1)
    wrap: In(1)
    sat16: In(1)
    result: Out(signed(32))
    saturated: Out(1)

    def elaborate(self, platform):
        m = Module()
        full = Signal(signed(33))
        m.d.comb += full.eq(self.a + Mux(self.sub, ~self.b, self.b) + self.sub)   # one adder
        # both clamps of the one sum, side by side rather than one after the other (the
        # ALU's result is forwarded to the next instruction's operands in the same cycle:
        # the longest path of the engine, report --timing). sat16 of the sum is sat16 of its
        # sat32: a sum beyond 32 bits is beyond 16 with the same sign
        # Wrapping is the 32-bit clamp that never clamps, so it shares the clamp's
        # multiplexer: one fewer 32-bit choice
        v32, f32 = saturate(m, full, 32, keep=self.wrap)
        v16, f16 = saturate(m, full, 16)
        m.d.comb += [
            self.result.eq(Mux(self.sat16 & ~self.wrap, v16, v32)),
            self.saturated.eq(~self.wrap & Mux(self.sat16, f16, f32)),
        ]
        return m
