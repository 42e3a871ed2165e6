"""The attitude engine's multiply-accumulate unit: a 32×32 product into a 66-bit accumulator,
written back rounded, shifted and saturated."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from .attitude_isa import MUL_SHIFTS, REG_BITS, Instr
from ..primitives.multiplier import Multiplier, whole_product


__all__ = ["MultiplyAccumulate"]


class MultiplyAccumulate(wiring.Component):
    """A MUL instruction in three steps: ``issue`` registers the product a·b (in the
    ``Multiplier``'s two parts) and the instruction; the next cycle (``pending``) adds it
    (inverted, plus one, when the instruction subtracts) to the accumulator — or to the
    rounding constant 2^(s−1) when the instruction starts a sum —; the cycle after, if the
    instruction writes back, it offers ``acc >> s`` saturated to 32 bits (= rshift_round of the
    exact sum, then sat32).

    Parameters
        ``multiplier``: the 32×32 ``Multiplier`` (a blackbox one for ``report``).
    Members
        ``a``, ``b`` (in, signed 32): the operands, read in the issue cycle.
        ``ins`` (in, ``Instr``): the MUL instruction, read in the issue cycle (``sh``: the
            ``MUL_SHIFTS`` index, its low two bits read; ``acc``, ``neg``, ``wb``, ``d``).
        ``issue`` (in): take a MUL now.
        ``pending`` (out): a product is being accumulated this cycle.
        ``wb_next``, ``wb_next_addr`` (out): that product's instruction writes back, next
            cycle, to this register.
        ``wb_en`` (out): a write-back this cycle (the MUL issued two cycles ago writes back);
            ``wb_addr``, ``wb_data`` (out, signed 32), ``wb_saturated`` (out): the register
            write.
    Latency 2: issue in cycle n, the sum in n + 1, the write-back (the sum shifted and
    saturated, from the accumulator register) in n + 2. Throughput one MUL per cycle (a MUL
    issued while earlier ones accumulate and write back overlaps them), unless the next MUL
    reads a result not yet written: the engine then waits.
    """
    a: In(signed(32))
    b: In(signed(32))
    ins: In(Instr)
    issue: In(1)
    pending: Out(1)
    wb_en: Out(1)
    wb_addr: Out(REG_BITS)
    wb_data: Out(signed(32))
    wb_saturated: Out(1)
    wb_next: Out(1)
    wb_next_addr: Out(REG_BITS)

    def __init__(self, multiplier=None):
        self.multiplier = Multiplier() if multiplier is None else multiplier
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        m.submodules.multiplier = mult = self.multiplier
        # datapath registers without reset: qualified by ``pending``
        # a·b in the multiplier's two parts (``Multiplier``), added with the accumulation:
        # the blocks and one adder, not two, are in front of these registers
        outer = Signal(signed(64), reset_less=True)
        middle = Signal(signed(33), reset_less=True)
        acc = Signal(signed(66), reset_less=True)
        acc_next = Signal(signed(66))
        rounding = Signal(signed(66))
        ins = Signal(Instr, reset_less=True)                # the MUL being accumulated
        ins_wb = Signal(Instr, reset_less=True)             # the MUL being written back
        m.d.comb += [mult.a.eq(self.a), mult.b.eq(self.b)]
        # ``sh``'s low two bits choose the shift: the assembler codes only MUL_SHIFTS's four
        # (a third bit's cases would each be a default of zeros to select from)
        shift = ins.sh[:2]
        assert len(MUL_SHIFTS) == 4
        with m.Switch(shift):
            for code, s in enumerate(MUL_SHIFTS):
                with m.Case(code):
                    m.d.comb += rounding.eq(1 << (s - 1))
        # ± product: base + (~product if neg) + neg. The inversion is here, not before the
        # product's registers: the 18x18 blocks and the adder that combines their products are
        # the longest path into them (report --timing)
        product = Signal(signed(64))
        m.d.comb += product.eq(whole_product(outer, middle))
        m.d.comb += acc_next.eq(Mux(ins.acc, acc, rounding) +
                                (product.as_unsigned() ^ ins.neg.replicate(64)).as_signed() +
                                ins.neg)
        # acc >> s saturated to 32 bits, selected per shift (each a slice of the accumulator):
        # whether it fits (the bits from s + 31 up all equal) is found with the sum and
        # registered; the write-back then only selects the slice or the limit
        # The slice is selected with the sum too, and registered: the write-back's path (into
        # the register file's write and the operands' forwarding) is then a two-way choice
        fits = Signal()
        wb_fits = Signal(reset_less=True)
        slice_next = Signal(signed(32))
        wb_slice = Signal(signed(32), reset_less=True)
        # the tops are nested (a smaller shift's holds a larger one's): their all-zeros and
        # all-ones tests are built from the largest shift's down, each from the one before
        zeros, ones = {}, {}
        zero_above, one_above, below = C(1), C(1), len(acc_next)
        for s in sorted(MUL_SHIFTS, reverse=True):
            part = acc_next[s + 31:below]
            zero_above = zeros[s] = (part == 0) & zero_above
            one_above = ones[s] = part.all() & one_above
            below = s + 31
        with m.Switch(shift):
            for code, s in enumerate(MUL_SHIFTS):
                with m.Case(code):
                    m.d.comb += [fits.eq(zeros[s] | ones[s]),
                                 slice_next.eq(acc_next[s:s + 32])]
        limit = Mux(acc[-1], C(-(1 << 31), signed(32)), C((1 << 31) - 1, signed(32)))
        m.d.comb += [self.wb_data.eq(Mux(wb_fits, wb_slice, limit)),
                     self.wb_saturated.eq(~wb_fits)]
        m.d.comb += [self.wb_addr.eq(ins_wb.d),
                     self.wb_next.eq(self.pending & ins.wb), self.wb_next_addr.eq(ins.d)]
        m.d.sync += self.wb_en.eq(self.pending & ins.wb)
        with m.If(self.pending):
            m.d.sync += [acc.eq(acc_next), ins_wb.eq(ins), wb_fits.eq(fits),
                         wb_slice.eq(slice_next),
                         self.pending.eq(0)]
        with m.If(self.issue):
            m.d.sync += [outer.eq(mult.outer), middle.eq(mult.middle), ins.eq(self.ins),
                         self.pending.eq(1)]
        return m
