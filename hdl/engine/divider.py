"""Fixed-point divider for the Kalman gains: q = ⌊num·2²⁴ / den⌋, saturated to 32 bits."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out


__all__ = ["Divider", "divider_word"]

BITS_PER_CYCLE = 1


def divider_word(divider, select):
    """The quotient of ``divider`` (a Value, signed ``width``) with ``select``, else 0: its
    register (``word``), unless the quotient saturates (2^(w−1) − 1, or −2^(w−1) for a negative
    numerator) or the denominator is ≤ 0 (0). Each an AND with its own select, OR-ed: a user
    choosing among other words as well (the engine's write data) folds this choice into its
    own, and the divider has no output multiplexer (as ``cordic_word``)."""
    select = Value.cast(select)
    w = len(divider.word)
    fits = select & ~divider.den_bad & ~divider.overflow
    limit = select & divider.overflow                   # ``overflow`` is 0 with ``den_bad``
    return (Mux(fits, divider.word, 0) |
            Mux(limit & ~divider.negative, C((1 << (w - 1)) - 1, w), 0) |
            Mux(limit & divider.negative, C(1 << (w - 1), w), 0))[:w].as_signed()


class Divider(wiring.Component):
    """Fixed-point divider for the Kalman gains: q = ⌊num·2²⁴ / den⌋, saturated to 32 bits.

    Computes exactly ``reference.fixed_point.div_q24``: a non-restoring divider,
    ``BITS_PER_CYCLE`` quotient bits per cycle (one: two cost another 33-bit adder for 16
    cycles less per division), 32 quotient bits. Non-restoring: the partial remainder may go
    negative (−den ≤ r < den), and the next step adds den back instead of subtracting it, so
    there is no multiplexer to restore it; its quotient bits (1 where the new remainder is
    ≥ 0) are the restoring divider's. A quotient that does not fit 32 bits saturates (2³¹ − 1,
    or −2³¹) and a denominator ≤ 0 gives 0; both set ``saturated``.

    Why it is small: there is no negation anywhere. The result rounds towards −∞ (floor), so for a
    negative numerator N = num·2²⁴ it divides ~N ≥ 0 (the inverted numerator followed by 24 ones)
    and inverts the quotient: ⌊N/d⌋ = ~⌊~N/d⌋. Why 32 iterations are enough: they start with the
    partial remainder at the numerator's top bits (``|num| >> 8``); if that is already ≥ den the
    first quotient bit (2³¹) is set by the first step anyway, and a set bit 31 means "saturate"
    either way. One register holds the dividend's low bits, shifted out at the top, and the
    quotient, shifted in at the bottom (each bit inverted for a negative numerator as it goes
    in, so that the register ends with the quotient itself, unless it saturates).

    Parameters
        ``width`` (32), ``frac`` (24): q = ⌊num·2^frac / den⌋ on ``width``-bit operands. The
        datapath uses 32/24; the formal check (``tests/formal/test_divider.py``) proves the same
        logic at a reduced width over every input.

    Interface
        ``start`` (in): pulse with ``num``, ``den`` (signed 32) valid; ignored until the cycle after
            ``done``.
        ``done`` (out): one-cycle pulse; the results hold until the next start.
        ``word`` (out, ``width``), ``negative``, ``overflow``, ``den_bad`` (out): the results:
            the quotient register, the numerator's sign, a quotient beyond ``width`` bits (it
            saturates), a denominator ≤ 0 (the quotient is 0); ``divider_word`` forms the
            quotient from them. ``saturated`` (out): ``overflow`` or ``den_bad``.
        ``busy`` (out): a division is running (from the cycle after ``start`` to the one before
            ``done``): the results are valid whenever it is low and a division was started
            since reset (the engine's background DIV waits for it to fall).
    Latency: ``done`` 32 / ``BITS_PER_CYCLE`` + 1 cycles after ``start`` (33 with one bit per
    cycle; 1 cycle for a denominator ≤ 0); throughput one division per 32 / ``BITS_PER_CYCLE`` + 2
    cycles (34).
    """
    def __init__(self, *, width=32, frac=24):
        if not 0 < frac < width:
            raise ValueError(f"Divider needs 0 < frac < width, not frac={frac}, width={width}")
        self.width, self.frac = width, frac
        super().__init__({
            "start": In(1), "num": In(signed(width)), "den": In(signed(width)),
            "done": Out(1), "busy": Out(1), "word": Out(width), "negative": Out(1),
            "overflow": Out(1), "den_bad": Out(1), "saturated": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        w, f = self.width, self.frac
        # reset-less: loaded by every start (a reset would cost a LUT per bit)
        rem = Signal(signed(w), reset_less=True)  # −den ≤ rem < den (non-restoring)
        shreg = Signal(w, reset_less=True)      # dividend bits (top) / quotient bits (bottom)
        den = Signal(w - 1, reset_less=True)
        negative = Signal(reset_less=True)
        den_bad = Signal(reset_less=True)
        count = Signal(range(w // BITS_PER_CYCLE), reset_less=True)

        r, q = rem, shreg
        for _ in range(BITS_PER_CYCLE):
            trial = Cat(q[w - 1], r).as_signed()             # (r << 1) | next bit, w + 1 bits
            nxt = Signal(signed(w + 1))
            # r >= 0: subtract den, else add it back (the restoring divider's quotient bits)
            d = Cat(den, C(0, 2)).as_signed()
            m.d.comb += nxt.eq(trial + Mux(r[w - 1], d, ~d) + ~r[w - 1])
            r = nxt[:w]
            # each quotient bit goes in inverted for a negative numerator (⌊N/d⌋ = ~⌊~N/d⌋):
            # the quotient is whole in the register at the end, no inversion of 32 bits after
            q = Cat(~nxt[w] ^ negative, q[:w - 1])

        num = self.num
        inverted = (num ^ num[w - 1].replicate(w))[:w - 1]   # num ≥ 0: num; else ~num ≥ 0
        overflow = shreg[w - 1] ^ negative                   # ⌊~N/d⌋ or ⌊N/d⌋ ≥ 2^(w−1)
        m.d.comb += [
            self.word.eq(shreg), self.negative.eq(negative),
            self.overflow.eq(overflow & ~den_bad), self.den_bad.eq(den_bad),
            self.saturated.eq(den_bad | overflow),
        ]
        with m.FSM():
            with m.State("IDLE"):
                with m.If(self.start):
                    bad = self.den[w - 1] | (self.den == 0)
                    m.d.sync += [
                        negative.eq(num[w - 1]), den.eq(self.den[:w - 1]), den_bad.eq(bad),
                        rem.eq((inverted >> (w - f)).as_unsigned()),
                        # the dividend's low w bits: the numerator's low w − f, then f fill bits
                        shreg.eq(Cat(num[w - 1].replicate(f), inverted[:w - f])),
                        count.eq(0),
                    ]
                    with m.If(bad):
                        m.next = "DONE"
                    with m.Else():
                        m.next = "RUN"
            with m.State("RUN"):
                m.d.comb += self.busy.eq(1)
                m.d.sync += [rem.eq(r), shreg.eq(q), count.eq(count + 1)]
                with m.If(count == w // BITS_PER_CYCLE - 1):
                    m.next = "DONE"
            with m.State("DONE"):
                m.d.comb += self.done.eq(1)
                m.next = "IDLE"
        return m
