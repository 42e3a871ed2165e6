"""CORDIC, formally: equal to the reference's integer model for every input, at a reduced width.

The model is ``reference.fixed_point.cordic_vector`` / ``cordic_rotate`` written line for line
as Amaranth expressions (``vector_model``, ``rotate_model``: the loop unrolled, on wide signals
that cannot overflow, as Python's integers do). It shares nothing with the gateware's tricks
(operands inverted to subtract, the zero vector started at −Σatan, one adder per register).
``test_model_is_the_reference`` checks the model against the Python reference itself at the
datapath's width on random and corner inputs, so the proof is about the reference.

Reduced width: 8-bit inputs and angles, 6 iterations, 3 when short (the gateware is the same
logic for any width and table: ``CORDIC(width=, atan_table=, inv_gain=, short_iterations=)``).
"""

import math
import random

import pytest
from amaranth import *
from amaranth.asserts import AnyConst
from amaranth.hdl import Assert, Cover
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.engine.cordic import CORDIC, cordic_word
from mpu9250_ahrs.reference import fixed_point as fx

from .harness import counter, harness_module


WIDTH, ITERATIONS, SHORT = 8, 6, 3


def table(width, iterations):
    return tuple(int(round(math.atan(2.0 ** -i) / (2 * math.pi) * 2 ** width))
                 for i in range(iterations))


def inv_gain(width, iterations):
    k = math.prod(math.sqrt(1 + 2.0 ** (-2 * i)) for i in range(iterations))
    return int(round((1 << (width - 2)) / k))


def _wide(m, value, bits, name):
    s = Signal(signed(bits), name=name)
    m.d.comb += s.eq(value)
    return s


def vector_model(m, x, y, *, width, atan):
    """``cordic_vector``: (angle, magnitude, saturated)."""
    wide = width + 6
    left = x < 0
    x_ = _wide(m, Mux(left, ~x, x), wide, "vx0")
    y_ = _wide(m, Mux(left, ~y, y), wide, "vy0")
    a_ = _wide(m, Mux(left, 1 << (width - 1), 0), wide, "va0")
    for i, t in enumerate(atan):
        up = y_ >= 0
        x_, y_, a_ = (_wide(m, Mux(up, x_ + (y_ >> i), x_ - (y_ >> i)), wide, f"vx{i + 1}"),
                      _wide(m, Mux(up, y_ - (x_ >> i), y_ + (x_ >> i)), wide, f"vy{i + 1}"),
                      _wide(m, Mux(up, a_ + t, a_ - t), wide, f"va{i + 1}"))
    zero = (x == 0) & (y == 0)
    top = (1 << (width - 1)) - 1
    angle = Mux(zero, 0, a_[:width].as_signed())        # wrap to the BAM width
    magnitude = Mux(zero, 0, Mux(x_ > top, top, Mux(x_ < -top - 1, -top - 1, x_)))
    saturated = ~zero & ((x_ > top) | (x_ < -top - 1))
    return angle, magnitude, saturated


def rotate_model(m, angle, *, width, atan, gain):
    """``cordic_rotate``: (cos, sin)."""
    wide = width + 6
    quarter = 1 << (width - 2)
    beyond = (angle > quarter) | (angle < -quarter)
    turned = (angle + (1 << (width - 1)))[:width].as_signed()
    z = _wide(m, Mux(beyond, turned, angle), wide, "rz0")
    x_ = _wide(m, Mux(beyond, -gain, gain), wide, "rx0")
    y_ = _wide(m, 0, wide, "ry0")
    for i, t in enumerate(atan):
        pos = z >= 0
        x_, y_, z = (_wide(m, Mux(pos, x_ - (y_ >> i), x_ + (y_ >> i)), wide, f"rx{i + 1}"),
                     _wide(m, Mux(pos, y_ + (x_ >> i), y_ - (x_ >> i)), wide, f"ry{i + 1}"),
                     _wide(m, Mux(pos, z - t, z + t), wide, f"rz{i + 1}"))
    return x_, y_


def cordic_harness(width=WIDTH, iterations=ITERATIONS, short_iterations=SHORT, dut=None):
    atan, gain = table(width, iterations), inv_gain(width, iterations)
    m = harness_module()
    m.submodules.dut = dut = dut or CORDIC(width=width, atan_table=atan, inv_gain=gain,
                                           short_iterations=short_iterations)
    x, y, a = AnyConst(signed(width)), AnyConst(signed(width)), AnyConst(signed(width))
    mode, short = AnyConst(1), AnyConst(1)
    cycle = counter(m, range(iterations + 4), name="cycle")  # the start is at cycle 0
    m.d.comb += [dut.x_in.eq(x), dut.y_in.eq(y), dut.angle_in.eq(a), dut.mode.eq(mode),
                 dut.short.eq(short), dut.start.eq(cycle == 0)]
    # short: the same iterations, stopped after ``short_iterations`` (the models' first ones)
    models = [(vector_model(m, x, y, width=width, atan=t),
               rotate_model(m, a, width=width, atan=t, gain=gain))
              for t in (atan, atan[:short_iterations])]
    (angle, magnitude, saturated), (cos, sin) = [
        tuple(Mux(short, s, w) for w, s in zip(whole, cut))
        for whole, cut in zip(models[0], models[1])]

    # the two results as the engine writes them (``cordic_word``)
    mag_sin, angle_cos = cordic_word(dut, 1, 0), cordic_word(dut, 0, 1)
    # a rotation's first iteration is made with the start: a cycle less
    m.d.comb += Assert(dut.done == (cycle == Mux(short, short_iterations, iterations) + 1 -
                                    mode), "latency")
    with m.If(dut.done & ~mode):
        m.d.comb += [Assert(angle_cos == angle, "angle"),
                     Assert(mag_sin == magnitude, "magnitude"),
                     Assert(dut.saturated == saturated, "saturated"),
                     Cover((x == 0) & (y == 0), "zero_vector"),
                     Cover((x < 0) & (y > 0), "left_half_plane_up"),
                     Cover((x < 0) & (y < 0), "left_half_plane_down"),
                     Cover(saturated, "magnitude_saturates"),
                     Cover(short & (x == 0) & (y == 0), "short_zero_vector")]
    with m.If(dut.done & mode):
        m.d.comb += [Assert(angle_cos == cos[:width].as_signed(), "cos"),
                     Assert(mag_sin == sin[:width].as_signed(), "sin"),
                     # the rotated vector fits the outputs: no wrap hidden by the slices above
                     Assert((cos >> (width - 1) == 0) | (cos >> (width - 1) == -1), "cos_fits"),
                     Assert((sin >> (width - 1) == 0) | (sin >> (width - 1) == -1), "sin_fits"),
                     Cover((a > (1 << (width - 2))), "beyond_90_degrees")]
    return m


@pytest.mark.formal
@pytest.mark.slow
def test_cordic_equals_model(formal):
    # every input (AnyConst) and both modes through one whole operation: latency + 2
    formal(cordic_harness(), name="cordic", mode="bmc", depth=ITERATIONS + 3)


@pytest.mark.formal
def test_cordic_cover(formal):
    formal(cordic_harness(), name="cordic_cover", mode="cover", depth=ITERATIONS + 3)


def test_model_is_the_reference():
    """The Amaranth model at 32 bits and the reference's table gives the reference's results."""
    width, atan, gain = 32, fx.ATAN_TABLE, fx.INV_GAIN_Q30
    x, y, a = Signal(signed(32)), Signal(signed(32)), Signal(signed(32))
    m = Module()
    angle, magnitude, _ = vector_model(m, x, y, width=width, atan=atan)
    cos, sin = rotate_model(m, a, width=width, atan=atan, gain=gain)
    rng = random.Random(14)
    edge = [0, 1, -1, (1 << 31) - 1, -(1 << 31), 1 << 30, -(1 << 30)]
    cases = [(p, q) for p in edge for q in edge]
    cases += [(rng.randrange(-(1 << 31), 1 << 31) >> rng.randrange(31),
               rng.randrange(-(1 << 31), 1 << 31) >> rng.randrange(31)) for _ in range(300)]
    sim = Simulator(m)

    async def tb(ctx):
        for p, q in cases:
            ctx.set(x, p)
            ctx.set(y, q)
            ctx.set(a, p)
            assert (ctx.get(angle), ctx.get(magnitude)) == fx.cordic_vector(p, q), (p, q)
            assert (ctx.get(cos), ctx.get(sin)) == fx.cordic_rotate(p), p
    sim.add_testbench(tb)
    sim.run()
