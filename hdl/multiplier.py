"""Signed 32 × 32 → 64-bit multiplier, combinational."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out


__all__ = ["Multiplier", "BLACKBOX_NAME", "BLACKBOX_STUB"]

BLACKBOX_NAME = "mpu9250_ahrs_mul18x18"
BLACKBOX_STUB = (f"(* blackbox *) module {BLACKBOX_NAME}(input signed [17:0] a, "
                 f"input signed [17:0] b, output signed [35:0] p);\nendmodule\n")


class Multiplier(wiring.Component):
    """Signed 32 × 32 → 64-bit multiplier, combinational.

    On a MAX10 it takes four embedded 18 × 18 multipliers: with a = a_h·2¹⁷ + a_l (a_l the low 17
    bits, unsigned; a_h the top 15, signed) and b likewise,

        a·b = a_h·b_h·2³⁴ + (a_h·b_l + a_l·b_h)·2¹⁷ + a_l·b_l,

    where a_l·b_l < 2³⁴, so the first and last terms are just placed side by side and the logic
    adds only the two middle products and the sum into bits 17 up (the MAX10's blocks have no
    adders; Quartus puts these in logic elements too).

    ``blackbox`` (an attribute ``report`` sets before elaborating; False otherwise) instantiates the
    four blocks as empty modules (``BLACKBOX_NAME``) with that adder logic around them, so that a
    synthesis tool which cannot map multipliers (Debian's Yosys 0.23 for MAX10) counts the blocks
    apart and the adders as logic.
    ``split=True`` builds the same structure with real 18 × 18 products, for simulation (the test
    that the decomposition is exact).

    Interface: ``a``, ``b`` (in, signed 32), ``p`` (out, signed 64); latency 0 (the engine registers
    the product).
    """
    a: In(signed(32))
    b: In(signed(32))
    p: Out(signed(64))

    blackbox = False

    def __init__(self, *, split=False):
        self.split = split
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        if not (self.split or self.blackbox):
            m.d.comb += self.p.eq(self.a * self.b)
            return m

        def halves(v):
            # 18-bit signed block inputs: the low 17 bits zero-extended, the top 15 sign-extended
            return v[:17].as_unsigned(), v[17:].as_signed()

        (al, ah), (bl, bh) = halves(self.a), halves(self.b)
        products = {}
        for name, x, y in (("ll", al, bl), ("lh", al, bh), ("hl", ah, bl), ("hh", ah, bh)):
            product = Signal(signed(36), name=f"p_{name}")
            if self.blackbox:
                m.submodules[f"mul_{name}"] = Instance(BLACKBOX_NAME, i_a=x, i_b=y, o_p=product)
            else:
                m.d.comb += product.eq(x * y)
            products[name] = product
        middle = Signal(signed(33))
        m.d.comb += [
            middle.eq(products["lh"] + products["hl"]),
            self.p.eq(Cat(products["ll"][:34], products["hh"][:30]).as_signed()
                      + (middle << 17)),
        ]
        return m
