"""Fixed-point divider for the Kalman gains: q = ⌊num·2²⁴ / den⌋, saturated to 32 bits.

Computes exactly ``reference.fixed_point.div_q24``: a restoring divider, ``BITS_PER_CYCLE``
quotient bits per cycle (one: a second bit per cycle costs another 33-bit subtractor and
multiplexer, about 130 LEs of the whole design's count, for 16 cycles per division), 32
quotient bits. A quotient that does not fit 32 bits saturates (2³¹ − 1, or −2³¹) and a
denominator ≤ 0 gives 0; both set ``saturated``.

Why it is small: there is no negation anywhere. The result rounds towards −∞ (floor), so for a
negative numerator N = num·2²⁴ it divides ~N ≥ 0 (the inverted numerator followed by 24 ones)
and inverts the quotient: ⌊N/d⌋ = ~⌊~N/d⌋. Why 32 iterations are enough: they start with the
partial remainder at the numerator's top bits (``|num| >> 8``); if that is already ≥ den the
first quotient bit (2³¹) is set by the first trial anyway, and a set bit 31 means "saturate"
either way. One register holds the dividend's low bits, shifted out at the top, and the
quotient, shifted in at the bottom.

Interface
    ``start`` (in): pulse with ``num``, ``den`` (signed 32) valid; ignored while ``busy``.
    ``done`` (out): one-cycle pulse; ``quotient`` and ``saturated`` hold until the next start.
Latency: ``done`` 32 / ``BITS_PER_CYCLE`` + 1 cycles after ``start`` (33 with one bit per
cycle); throughput one division per 32 / ``BITS_PER_CYCLE`` + 2 cycles (34).
"""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out


__all__ = ["Divider"]

BITS_PER_CYCLE = 1


class Divider(wiring.Component):
    start: In(1)
    num: In(signed(32))
    den: In(signed(32))

    busy: Out(1)
    done: Out(1)
    quotient: Out(signed(32))
    saturated: Out(1)

    def elaborate(self, platform):
        m = Module()
        # reset-less: loaded by every start (a reset would cost a LUT per bit)
        rem = Signal(31, reset_less=True)    # < den ≤ 2³¹ − 1
        shreg = Signal(32, reset_less=True)  # dividend bits (top) / quotient bits (bottom)
        den = Signal(31, reset_less=True)
        negative = Signal(reset_less=True)
        den_bad = Signal(reset_less=True)
        count = Signal(range(32 // BITS_PER_CYCLE), reset_less=True)

        r, q = rem, shreg
        for _ in range(BITS_PER_CYCLE):
            trial = Cat(q[31], r)                            # (r << 1) | next bit, 32 bits
            diff = Signal(signed(33))
            m.d.comb += diff.eq(trial - den)                 # its sign is the comparison
            ge = ~diff[32]
            r = Mux(ge, diff[:31], trial[:31])
            q = Cat(ge, q[:31])

        num = self.num
        inverted = (num ^ num[31].replicate(32))[:31]        # num ≥ 0: num; else ~num ≥ 0
        overflow = shreg[31]                                 # quotient ≥ 2³¹
        magnitude = Mux(overflow, C((1 << 31) - 1, 32), shreg)
        m.d.comb += [
            self.quotient.eq(Mux(den_bad, 0, magnitude ^ negative.replicate(32))),
            self.saturated.eq(den_bad | overflow),
        ]
        with m.FSM():
            with m.State("IDLE"):
                with m.If(self.start):
                    bad = self.den[31] | (self.den == 0)
                    m.d.sync += [
                        negative.eq(num[31]), den.eq(self.den[:31]), den_bad.eq(bad),
                        rem.eq(inverted >> 8),
                        # the dividend's low 32 bits: the numerator's low 8, then 24 fill bits
                        shreg.eq(Cat(num[31].replicate(24), inverted[:8])),
                        count.eq(0),
                    ]
                    with m.If(bad):
                        m.next = "DONE"
                    with m.Else():
                        m.next = "RUN"
            with m.State("RUN"):
                m.d.comb += self.busy.eq(1)
                m.d.sync += [rem.eq(r), shreg.eq(q), count.eq(count + 1)]
                with m.If(count == 32 // BITS_PER_CYCLE - 1):
                    m.next = "DONE"
            with m.State("DONE"):
                m.d.comb += self.done.eq(1)
                m.next = "IDLE"
        return m
