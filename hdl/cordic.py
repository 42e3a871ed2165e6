"""Iterative CORDIC: vectoring (atan2 and magnitude) and rotation (cos and sin), BAM32 angles.

Computes exactly ``reference.fixed_point.cordic_vector`` / ``cordic_rotate``:
``CORDIC_ITERATIONS`` (16) iterations, one per cycle, arctangent table ``ATAN_TABLE`` (BAM32,
rounded), arithmetic shifts of the values before each iteration.

Interface
    ``start`` (in): pulse with ``mode`` (0 vectoring, 1 rotation), ``x_in``, ``y_in`` (signed
        32, vectoring) or ``angle_in`` (BAM32, rotation) valid. Ignored while ``busy``.
    ``done`` (out): one-cycle pulse when the results are valid; they hold until the next start.
    Vectoring results: ``angle`` (BAM32, atan2(y, x); (0, 0) gives 0), ``magnitude``
        (√(x² + y²)·K saturated to 32 bits; ``saturated`` set if it was clamped).
    Rotation results: ``cos``, ``sin`` in Q1.30 (on ``magnitude``/``angle``'s neighbours
        ``x_out``, ``y_out``).
Latency: ``done`` ``CORDIC_ITERATIONS`` + 1 cycles after ``start``; throughput one operation per
that many cycles. Internal width 34 bits: a 32-bit vector's length times K (1.647) is below 2³³,
so any 32-bit input converges without overflow.
"""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..reference.fixed_point import ATAN_TABLE, CORDIC_ITERATIONS, INV_GAIN_Q30


__all__ = ["CORDIC"]

WIDTH = 34
ATAN_SUM = sum(ATAN_TABLE)


class CORDIC(wiring.Component):
    start: In(1)
    mode: In(1)                 # 0: vectoring, 1: rotation
    x_in: In(signed(32))
    y_in: In(signed(32))
    angle_in: In(signed(32))

    busy: Out(1)
    done: Out(1)
    angle: Out(signed(32))      # vectoring: atan2(y, x)
    magnitude: Out(signed(32))  # vectoring: |(x, y)|·K, saturated
    saturated: Out(1)
    cos: Out(signed(32))        # rotation, Q1.30
    sin: Out(signed(32))

    def elaborate(self, platform):
        m = Module()
        # reset-less: loaded by every start (a reset would cost a LUT per bit)
        x = Signal(signed(WIDTH), reset_less=True)
        y = Signal(signed(WIDTH), reset_less=True)
        # angle accumulator: BAM32 wraps by itself, and in rotation |z| stays below 100°, so
        # its sign is the direction
        z = Signal(signed(32), reset_less=True)
        i = Signal(range(CORDIC_ITERATIONS), reset_less=True)
        rotate = Signal(reset_less=True)

        atan = Array(Const(v, signed(32)) for v in ATAN_TABLE)
        # σ = +1: x −= σ·(y >> i) … written out for both directions
        up = Signal()
        # the signs alone (y ≥ 0 rather than y > 0: no zero test)
        m.d.comb += up.eq(Mux(rotate, z[-1], ~y[-1]))
        xs, ys = Signal(signed(WIDTH)), Signal(signed(WIDTH))
        m.d.comb += [xs.eq(x >> i), ys.eq(y >> i)]

        with m.FSM():
            with m.State("IDLE"):
                with m.If(self.start):
                    m.d.sync += [i.eq(0), rotate.eq(self.mode)]
                    with m.If(self.mode):
                        a = self.angle_in
                        # beyond ±90°: turn by 180° (wrapping add of 2³¹), start from (−1/K, 0)
                        beyond = (a > (1 << 30)) | (a < -(1 << 30))
                        m.d.sync += [x.eq(Mux(beyond, -INV_GAIN_Q30, INV_GAIN_Q30)), y.eq(0),
                                     z.eq(Cat(a[:31], a[31] ^ beyond))]
                    with m.Else():
                        xi, yi = self.x_in, self.y_in
                        # left half-plane: invert (−v − 1: no adder), start at 180°
                        left = xi[31]
                        # (0, 0) stays (0, 0) and turns the same way (y ≥ 0) every iteration,
                        # so starting it at −Σ atan ends it at angle 0: no output multiplexer
                        zero = (xi == 0) & (yi == 0)
                        m.d.sync += [x.eq(xi ^ left.replicate(32).as_signed()),
                                     y.eq(yi ^ left.replicate(32).as_signed()),
                                     z.eq(Mux(zero, -ATAN_SUM, Cat(C(0, 31), left)))]
                    m.next = "RUN"
            with m.State("RUN"):
                m.d.comb += self.busy.eq(1)
                # x ∓ (y >> i), y ± (x >> i), z ∓ atan: one adder each, the operand inverted
                # (plus one) to subtract
                m.d.sync += [
                    x.eq(x + Mux(up, ys, ~ys) + ~up),
                    y.eq(y + Mux(up, ~xs, xs) + up),
                    z.eq(z + Mux(up, atan[i], ~atan[i]) + ~up),
                ]
                m.d.sync += i.eq(i + 1)
                with m.If(i == CORDIC_ITERATIONS - 1):
                    m.next = "DONE"
            with m.State("DONE"):
                m.d.comb += self.done.eq(1)
                m.next = "IDLE"

        max32 = (1 << 31) - 1
        m.d.comb += [
            self.angle.eq(z),
            self.magnitude.eq(Mux(x > max32, max32, x)),
            self.saturated.eq(x > max32),
            self.cos.eq(x),
            self.sin.eq(y),
        ]
        return m
