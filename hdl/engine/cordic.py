"""Iterative CORDIC: vectoring (atan2 and magnitude) and rotation (cos and sin), BAM32 angles."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..contract.numeric_contract import ATAN_TABLE, CORDIC_SHORT_ITERATIONS, INV_GAIN_Q30
from ..primitives.memories import FrameRAM
from ..primitives.multiplier import BLACKBOX_NAME


__all__ = ["CORDIC", "cordic_word"]


def cordic_word(cordic, first, second):
    """A result of ``cordic`` (its outputs, a Value): with ``first``, ``mag_sin`` (vectoring:
    the magnitude √(x² + y²)·K saturated to 32 bits; rotation: sin in Q1.30), with ``second``,
    ``angle_cos`` (vectoring: the angle, BAM32, atan2(y, x), (0, 0) giving 0; rotation: cos in
    Q1.30); 0 with neither (never both). An AND of each of the CORDIC's registers with its
    select, OR-ed: a user choosing among other words as well (the engine's write data) folds
    this choice into its own, and the CORDIC has no output multiplexer. In vectoring x is
    never negative: over 2^(n-1) - 1 when a bit from n - 1 up is set (``saturated``), and the
    limit is then x with its low bits forced to ones: no comparator."""
    first, second = Value.cast(first), Value.cast(second)
    n, rot = len(cordic.x_out), cordic.rotating
    top = cordic.x_out[n - 1] & rot             # the magnitude's sign bit is 0
    return (Mux(first & rot, cordic.y_out.as_unsigned(), 0) |
            Mux((first & ~rot) | (second & rot), Cat(cordic.x_out[:n - 1], top), 0) |
            Mux(second & ~rot, cordic.z_out.as_unsigned(), 0) |
            Mux(first & cordic.saturated, C((1 << (n - 1)) - 1, n), 0))[:n].as_signed()


def _beyond_right_angle(a):
    """Whether a BAM angle ``a`` (signed, n bits) is beyond ±90°: a > 2^(n−2) (its top bits 01
    and the rest not all 0) or a < −2^(n−2) (its top bits 10), from the bits rather than two
    comparators."""
    n = len(a)
    return (~a[n - 1] & a[n - 2] & a[:n - 2].any()) | (a[n - 1] & ~a[n - 2])


class CORDIC(wiring.Component):
    """Iterative CORDIC: vectoring (atan2 and magnitude) and rotation (cos and sin), BAM32 angles.

    Computes exactly ``reference.fixed_point.cordic_vector`` / ``cordic_rotate``:
    ``CORDIC_ITERATIONS`` (16) iterations, one per cycle, arctangent table ``ATAN_TABLE`` (BAM32,
    rounded), arithmetic shifts of the values before each iteration.

    Interface
        ``start`` (in): pulse with ``mode`` (0 vectoring, 1 rotation), ``short``, ``x_in``,
            ``y_in`` (signed 32, vectoring) or ``angle_in`` (BAM32, rotation) valid. Ignored
            until the cycle after ``done``.
        ``short`` (in): stop after ``short_iterations`` (``CORDIC_SHORT_ITERATIONS``, 8): a
            vectoring whose angle is not wanted (a length: ``cordic_vector(iterations=)``).
        ``done`` (out): one-cycle pulse when the results are valid; they hold until the next start.
        ``busy`` (out): an operation is running (from the cycle after ``start`` to the one
            before ``done``): the results are valid whenever it is low and an operation was
            started since reset. A user that goes on with other work after ``start`` (the
            engine's background VEC and ROT) waits for it to fall rather than for ``done``.
        ``x_out``, ``y_out``, ``z_out`` (out, signed 32): the registers x, y (their low 32
            bits) and z: vectoring, x the magnitude √(x² + y²)·K before its clamp and z the
            angle; rotation, x cos and y sin. ``rotating`` (out): the last operation was a
            rotation. ``saturated`` (out): vectoring's magnitude is beyond 32 bits (clamped);
            0 after a rotation. ``cordic_word`` forms the results from them: ``mag_sin``
            (the magnitude, or sin) and ``angle_cos`` (the angle, or cos), which the engine
            writes one after the other (``mag_sin`` into d + 1, then ``angle_cos`` into d: the
            same register last in both modes).
    Parameters (the datapath's by default; the formal check, ``tests/formal/test_cordic.py``, proves
    the same logic at a reduced width): ``width`` (32: inputs, results and the angle's BAM bits),
    ``atan_table`` (one entry per iteration, BAM of ``width`` bits), ``inv_gain`` (1/K in
    Q1.(``width`` − 2)), ``short_iterations`` (at most the table's).
    Latency: ``done`` ``CORDIC_ITERATIONS`` + 1 cycles after ``start`` (``short``:
    ``short_iterations`` + 1) in vectoring, a cycle less in rotation (its first iteration,
    from y = 0, is made with the start); throughput one operation per that many cycles.
    Internal width 34 bits: a 32-bit vector's length times K (1.647) is below 2³³, so any
    32-bit input converges without overflow. The arctangents are a ROM in a ``FrameRAM``
    (``atan_rom``: one M9K, not a LUT a bit; ``report`` counts it). Two 18 × 18 multipliers
    shift y by i, a third x's high bits (``blackbox``: ``report`` makes them empty blocks, as
    the engine's multiplier's).
    """
    blackbox = False        # ``report``: the shift's multipliers as empty 18 x 18 blocks

    def __init__(self, *, width=32, atan_table=ATAN_TABLE, inv_gain=INV_GAIN_Q30,
                 short_iterations=CORDIC_SHORT_ITERATIONS):
        self.width, self.atan_table, self.inv_gain = width, tuple(atan_table), inv_gain
        if not 1 <= short_iterations <= len(self.atan_table):
            raise ValueError(f"CORDIC: {short_iterations} short iterations of "
                             f"{len(self.atan_table)}")
        self.short_iterations = short_iterations
        n = width
        # y >> i's multipliers take its low bits (one per iteration at least, at most 17) and
        # its high bits (at most 18) as 18-bit operands
        self.low_bits = max(len(self.atan_table), n + 2 - 18)
        if not self.low_bits <= 17 or self.low_bits >= n + 2:
            raise ValueError(f"CORDIC: {len(self.atan_table)} iterations at width {width} do not "
                             f"fit the shift's 18 x 18 multipliers")
        # the arctangents in a block RAM's ROM (one M9K) rather than in logic (a LUT a bit)
        self.atan_rom = FrameRAM(len(self.atan_table), n,
                                 init=[v & ((1 << n) - 1) for v in self.atan_table])
        super().__init__({
            "start": In(1),
            "mode": In(1),                  # 0: vectoring, 1: rotation
            "short": In(1),                 # stop after ``short_iterations``
            "x_in": In(signed(n)), "y_in": In(signed(n)), "angle_in": In(signed(n)),
            "done": Out(1),
            "busy": Out(1),
            "x_out": Out(signed(n)), "y_out": Out(signed(n)), "z_out": Out(signed(n)),
            "rotating": Out(1),
            "saturated": Out(1),
        })

    def _arctangent(self, m, i):
        """The arctangent of the iteration under way (returned, from ``atan_rom``), and the
        read's address (returned, for the FSM to drive): it is read the cycle before, at the
        start the first iteration's i, in RUN the next one's."""
        m.submodules.atan_rom = atan_rom = self.atan_rom
        atan_next = Signal.like(i)
        m.d.comb += [atan_rom.r_en.eq(1), atan_rom.r_addr.eq(atan_next)]
        return atan_rom.r_data.as_signed(), atan_next

    def elaborate(self, platform):
        m = Module()
        n = self.width
        iterations = len(self.atan_table)
        inner = n + 2           # a vector's length times K (< 1.65) fits: no overflow inside
        # reset-less: loaded by every start (a reset would cost a LUT per bit)
        x = Signal(signed(inner), reset_less=True)
        y = Signal(signed(inner), reset_less=True)
        # angle accumulator: BAM wraps by itself, and in rotation |z| stays below 100°, so
        # its sign is the direction
        z = Signal(signed(n), reset_less=True)
        i = Signal(range(iterations), reset_less=True)
        rotate = Signal(reset_less=True)
        last = Signal(range(iterations), reset_less=True)     # the final iteration's i

        atan_i, atan_next = self._arctangent(m, i)
        whole_sum, short_sum = (sum(self.atan_table[:k])
                                for k in (iterations, self.short_iterations))
        # σ = +1: x −= σ·(y >> i) … written out for both directions
        up = Signal()
        # the signs alone (y ≥ 0 rather than y > 0: no zero test)
        m.d.comb += up.eq(Mux(rotate, z[-1], ~y[-1]))
        xs, ys = Signal(signed(inner)), Signal(signed(inner))
        # y >> i by two 18 x 18 multipliers, not a shifter of logic (x's by one, below):
        # y = hi·2ᴸ + lo, lo the low L bits (unsigned), and with c = 2ᴸ⁻¹⁻ⁱ,
        # y >> i = (hi·c)·2 | (lo·c) >> (L − 1): the two parts in disjoint bits, no adder
        low = self.low_bits
        # c is a register shifted right each iteration (no decoder of i before the blocks)
        c = Signal(18, reset_less=True)
        hi, lo = y[low:].as_signed(), Cat(y[:low], C(0, 1)).as_signed()
        p_hi, p_lo = Signal(signed(36)), Signal(signed(36))
        if self.blackbox:
            m.submodules.shift_hi = Instance(BLACKBOX_NAME, i_a=hi, i_b=c.as_signed(), o_p=p_hi)
            m.submodules.shift_lo = Instance(BLACKBOX_NAME, i_a=lo, i_b=c.as_signed(), o_p=p_lo)
        else:
            m.d.comb += [p_hi.eq(hi * c.as_signed()), p_lo.eq(lo * c.as_signed())]
        # x >> i: its high bits through a third block (times 2^(low − i): they land above
        # bit low − i − 1), its low ``low`` bits through a shifter of their own (a LUT4
        # fabric pays about a LUT per bit per shift stage: a shifter of all 34 bits cost
        # twice as much)
        x_hi, x_lo = x[low:].as_signed(), x[:low]
        c2 = (c << 1)[:18].as_signed()                            # 2^(low − i)
        p_x = Signal(signed(36))
        if self.blackbox:
            m.submodules.shift_x = Instance(BLACKBOX_NAME, i_a=x_hi, i_b=c2, o_p=p_x)
        else:
            m.d.comb += p_x.eq(x_hi * c2)
        m.d.comb += [xs.eq(p_x[:inner].as_signed() | (x_lo >> i)),
                     ys.eq((p_hi << 1)[:inner].as_signed() |
                           p_lo[low - 1:low - 1 + inner].as_unsigned())]

        with m.FSM():
            with m.State("IDLE"):
                # a rotation starts at i = 1 (below), a vectoring at 0
                m.d.comb += atan_next.eq(self.mode)
                with m.If(self.start):
                    m.d.sync += [rotate.eq(self.mode),
                                 last.eq(Mux(self.short, self.short_iterations - 1,
                                             iterations - 1))]
                    m.next = "RUN"
                    with m.If(self.mode):
                        a = self.angle_in
                        # beyond ±90°: turn by 180° (wrapping add of 2³¹), start from (±1/K, 0)
                        beyond = _beyond_right_angle(a)
                        z0 = Cat(a[:n - 1], a[n - 1] ^ beyond).as_signed()
                        x0 = Mux(beyond, -self.inv_gain, self.inv_gain)
                        # The first iteration is made here: from y = 0 it is x1 = x0,
                        # y1 = ±x0 and z1 = z0 ∓ atan 0 (the signs z0's), constants and a
                        # constant added to z (2²⁹ at 32 bits: its top three bits), so a
                        # rotation takes one cycle less than a vectoring
                        neg = z0[-1]
                        m.d.sync += [
                            i.eq(1), c.eq(1 << (low - 2)),
                            x.eq(x0),
                            y.eq(Mux(beyond ^ neg, -self.inv_gain, self.inv_gain)),
                            z.eq(z0 + Mux(neg, self.atan_table[0], -self.atan_table[0])),
                        ]
                        # a rotation of one iteration is done with this one
                        with m.If(Mux(self.short, self.short_iterations, iterations) == 1):
                            m.next = "DONE"
                    with m.Else():
                        m.d.sync += [i.eq(0), c.eq(1 << (low - 1))]
                        xi, yi = self.x_in, self.y_in
                        # left half-plane: invert (−v − 1: no adder), start at 180°
                        left = xi[n - 1]
                        # (0, 0) stays (0, 0) and turns the same way (y ≥ 0) every iteration,
                        # so starting it at −Σ atan ends it at angle 0: no output multiplexer
                        zero = (xi == 0) & (yi == 0)
                        m.d.sync += [x.eq(xi ^ left.replicate(n).as_signed()),
                                     y.eq(yi ^ left.replicate(n).as_signed()),
                                     z.eq(Mux(zero, Mux(self.short, -short_sum, -whole_sum),
                                              Cat(C(0, n - 1), left)))]
            with m.State("RUN"):
                m.d.comb += self.busy.eq(1)
                # x ∓ (y >> i), y ± (x >> i), z ∓ atan: one adder each, the operand inverted
                # (plus one) to subtract
                m.d.sync += [
                    x.eq(x + Mux(up, ys, ~ys) + ~up),
                    y.eq(y + Mux(up, ~xs, xs) + up),
                    z.eq(z + Mux(up, atan_i, ~atan_i) + ~up),
                ]
                m.d.comb += atan_next.eq(i + 1)
                m.d.sync += [i.eq(i + 1), c.eq(c >> 1)]
                with m.If(i == last):
                    m.next = "DONE"
            with m.State("DONE"):
                m.d.comb += self.done.eq(1)
                m.next = "IDLE"

        # In vectoring x is never negative: it starts at |x_in| (or -x_in - 1) and each
        # iteration adds |y| >> i. So it is over 2^(n-1) - 1 when a bit from n - 1 up is set
        # (``cordic_word`` then forces its low bits to ones). In rotation x and y are cos and
        # sin (Q1.30: they fit 32 bits), passed on whole
        m.d.comb += [
            self.x_out.eq(x[:n]), self.y_out.eq(y[:n]), self.z_out.eq(z),
            self.rotating.eq(rotate),
            self.saturated.eq(x[n - 1:].any() & ~rotate),
        ]
        return m
