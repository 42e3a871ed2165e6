"""Signed 32 × 32 → 64-bit multiplier, combinational.

On a MAX10 Quartus maps it onto four embedded 18×18 multipliers (a 32-bit signed operand needs
two 18-bit parts). ``blackbox=True`` instantiates an empty module (``BLACKBOX_NAME``) instead,
so that a synthesis tool which cannot map multipliers (Debian's Yosys 0.23 for MAX10) counts it
as a hard block rather than thousands of logic elements; ``report`` uses that.

Interface: ``a``, ``b`` (in, signed 32), ``p`` (out, signed 64); latency 0 (the engine registers
the product).
"""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out


__all__ = ["Multiplier", "BLACKBOX_NAME", "BLOCKS_18X18"]

BLACKBOX_NAME = "mpu9250_ahrs_mul32x32"
BLOCKS_18X18 = 4


class Multiplier(wiring.Component):
    a: In(signed(32))
    b: In(signed(32))
    p: Out(signed(64))

    def __init__(self, *, blackbox=False):
        self.blackbox = blackbox
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        if self.blackbox:
            m.submodules.mul = Instance(BLACKBOX_NAME, i_a=self.a, i_b=self.b, o_p=self.p)
        else:
            m.d.comb += self.p.eq(self.a * self.b)
        return m
