"""Signed 32 × 32 → 64-bit multiplier, combinational."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out


__all__ = ["Multiplier", "whole_product", "BLACKBOX_NAME", "BLACKBOX_STUB"]

BLACKBOX_NAME = "mpu9250_ahrs_mul18x18"
BLACKBOX_STUB = (f"(* blackbox *) module {BLACKBOX_NAME}(input signed [17:0] a, "
                 f"input signed [17:0] b, output signed [35:0] p);\nendmodule\n")


def whole_product(outer, middle):
    """The product from the ``Multiplier``'s two parts: ``outer`` + ``middle``·2¹⁷."""
    return outer + (middle << 17)


class Multiplier(wiring.Component):
    """Signed 32 × 32 → 64-bit multiplier from four 18 × 18 products, combinational, with its
    last addition left to the user.

    On a MAX10 (or an ECP5) it takes four embedded 18 × 18 multipliers: with a = a_h·2¹⁷ + a_l
    (a_l the low 17 bits, unsigned; a_h the top 15, signed) and b likewise,

        a·b = a_h·b_h·2³⁴ + (a_h·b_l + a_l·b_h)·2¹⁷ + a_l·b_l,

    where a_l·b_l < 2³⁴, so the first and last terms are just placed side by side (``outer``)
    and the logic adds only the two middle products (``middle``). ``p`` = ``outer`` +
    ``middle``·2¹⁷ is the whole product; the engine's multiply-accumulate registers ``outer``
    and ``middle`` instead and adds them with its accumulation, so that the blocks and one
    adder, not two, are in front of its product registers (report --timing).

    ``blackbox`` (an attribute ``report`` sets before elaborating; False otherwise) instantiates the
    four blocks as empty modules (``BLACKBOX_NAME``) with the same logic around them, so that a
    synthesis tool which cannot map multipliers (Debian's Yosys 0.23 for MAX10) counts the blocks
    apart and the adders as logic.

    Interface: ``a``, ``b`` (in, signed 32); ``outer`` (out, signed 64), ``middle`` (out,
    signed 33), ``p`` (out, signed 64); latency 0.
    """
    a: In(signed(32))
    b: In(signed(32))
    outer: Out(signed(64))
    middle: Out(signed(33))
    p: Out(signed(64))

    blackbox = False

    def elaborate(self, platform):
        m = Module()

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
        m.d.comb += [
            self.middle.eq(products["lh"] + products["hl"]),
            self.outer.eq(Cat(products["ll"][:34], products["hh"][:30]).as_signed()),
            self.p.eq(whole_product(self.outer, self.middle)),
        ]
        return m
