"""Fixed-point divider for the Kalman gains: q = (num·2²⁴)/den truncated towards zero.

Computes exactly ``reference.fixed_point.div_q24``: a restoring divider on |num| with the sign
applied at the end; a quotient that does not fit 32 bits saturates (2³¹ − 1, or −2³¹), and a
denominator ≤ 0 gives 0; both set ``saturated``.

Why it can stop at 32 quotient bits: if |num| >> 7 < den the quotient is below 2³¹, so the
partial remainder after the dividend's top 24 bits is just |num| >> 8 and only the 32 bits
below need iterations (one overflow test replaces 24 iterations). If |num| < den (a Kalman
gain below 1, the usual case) the quotient is below 2²⁴ and 24 iterations suffice.

Interface
    ``start`` (in): pulse with ``num``, ``den`` (signed 32) valid; ignored while ``busy``.
    ``done`` (out): one-cycle pulse; ``quotient`` and ``saturated`` hold until the next start.
Latency: iterations / ``bits_per_cycle`` + 2 cycles: 10 (|num| ≥ den) or 8 (|num| < den)
with the default 4 bits per cycle, 2 for the saturating cases.
"""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out


__all__ = ["Divider"]


class Divider(wiring.Component):
    start: In(1)
    num: In(signed(32))
    den: In(signed(32))

    busy: Out(1)
    done: Out(1)
    quotient: Out(signed(32))
    saturated: Out(1)

    def __init__(self, bits_per_cycle=4):
        if 24 % bits_per_cycle or 32 % bits_per_cycle:
            raise ValueError("bits_per_cycle must divide 24 and 32")
        self.bits_per_cycle = bits_per_cycle
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        k = self.bits_per_cycle
        rem = Signal(32)                     # < den ≤ 2³¹ − 1
        dividend = Signal(32)                # the bits still to bring down, MSB first
        q = Signal(32)
        den = Signal(32)
        negative = Signal()
        count = Signal(range(32 // k + 1))

        # k restoring steps per cycle, unrolled
        r, d, qq = rem, dividend, q
        for _ in range(k):
            trial = Cat(d[31], r)            # (r << 1) | next dividend bit, 33 bits
            diff = trial - den               # one subtractor: its sign is the comparison
            ge = ~diff[33]
            r = Mux(ge, diff, trial)[:32]
            qq = Cat(ge, qq[:31])
            d = Cat(C(0, 1), d[:31])
        next_rem, next_div, next_q = r, d, qq

        magnitude = Mux(self.num < 0, -self.num, self.num)[:32]     # |num| ≤ 2³¹
        max32 = (1 << 31) - 1
        # saturated results are held in q with negative = 0
        m.d.comb += self.quotient.eq(Mux(negative, -q.as_signed(), q.as_signed()))
        with m.FSM():
            with m.State("IDLE"):
                with m.If(self.start):
                    m.d.sync += [negative.eq(self.num < 0), den.eq(self.den),
                                 self.saturated.eq(0), q.eq(0)]
                    with m.If(self.den <= 0):
                        m.d.sync += [negative.eq(0), self.saturated.eq(1)]
                        m.next = "DONE"
                    with m.Elif((magnitude >> 7) >= self.den):
                        m.d.sync += [q.eq(Mux(self.num < 0, 1 << 31, max32)), negative.eq(0),
                                     self.saturated.eq(1)]
                        m.next = "DONE"
                    with m.Elif(magnitude < self.den):
                        # quotient < 2²⁴: the remainder after the top 32 dividend bits is
                        # |num| itself; iterate over the 24 zero bits below
                        m.d.sync += [rem.eq(magnitude), dividend.eq(0), count.eq(8 // k)]
                        m.next = "RUN"
                    with m.Else():
                        m.d.sync += [rem.eq(magnitude >> 8), dividend.eq(magnitude[:8] << 24),
                                     count.eq(0)]
                        m.next = "RUN"
            with m.State("RUN"):
                m.d.comb += self.busy.eq(1)
                m.d.sync += [rem.eq(next_rem), dividend.eq(next_div), q.eq(next_q),
                             count.eq(count + 1)]
                with m.If(count == 32 // k - 1):
                    m.next = "DONE"
            with m.State("DONE"):
                m.d.comb += self.done.eq(1)
                m.next = "IDLE"
        return m
