"""The attitude engine's host port: register writes, register read-back and the CONTROL
register (filter select, filter reset)."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .attitude_isa import REG_BITS
from .register_map import CONTROL_ADDR
from ..contract.filter_registry import FILTER_CODE_BITS, FILTER_NAMES
from .config_write import ConfigWrite
from ..contract.numeric_contract import CONTROL_BITS, CONTROL_KEEP, CONTROL_RESET


__all__ = ["HostPort", "address_in", "control_accepted", "write_allowed", "control_code",
           "control_word_of"]


def address_in(addr, addresses):
    """1 where ``addr`` (an 8-bit value) is one of ``addresses``: a 256-entry decode of the
    address (one LUT tree), not a comparator per address. The engine's write check and the
    command decoder's (which answers "refused" before it sends a write) both use it."""
    return Const(sum(1 << a for a in addresses), 256).bit_select(addr, 1)


def control_accepted(data):
    """1 where ``data`` (a 32-bit word written to CONTROL) is a word the engine takes: no
    reserved bit set and, unless it keeps the filter, a code that names one of ``FILTER_NAMES``
    (``numeric_contract.control_fields``, the reference's statement of the same rule)."""
    data = Value.cast(data)
    keep = data[CONTROL_KEEP.bit_length() - 1]
    high = FILTER_CODE_BITS - 2                 # the code's bits from CONTROL bit 4 up
    return (data[CONTROL_BITS + high:32] == 0) & (keep | (control_code(data) < len(FILTER_NAMES)))


def write_allowed(addr, data, writable=None):
    """1 where a host's write of ``data`` to engine address ``addr`` is one the engine takes:
    ``addr`` one of ``writable`` (None: any) and, to CONTROL, a word ``control_accepted``
    takes. The one rule: the engine's port applies it, and the register executor refuses a
    write by it before sending it (the command decoder's "refused", the AXI slave's SLVERR)."""
    in_map = C(1) if writable is None else address_in(addr, writable)
    return in_map & ((addr != CONTROL_ADDR) | control_accepted(data))


def control_code(data):
    """The filter code in a CONTROL word: bits 1:0, and its higher bits from bit 4 when there
    are more than four filters (``numeric_contract.control_fields``)."""
    high = FILTER_CODE_BITS - 2
    return data[:2] if not high else Cat(data[:2], data[CONTROL_BITS:CONTROL_BITS + high])


def control_word_of(select):
    """A filter code as it reads back in the CONTROL word (``control_code``'s inverse)."""
    high = FILTER_CODE_BITS - 2
    return select if not high else Cat(select[:2], C(0, CONTROL_BITS - 2), select[2:])


class HostPort(wiring.Component):
    """Takes the host's register writes and reads while the engine lets it (``open``), using
    the register file's write port and its first read port, and holds the CONTROL register.

    Parameters
        ``filter_at_reset``: the filter select code after reset.
        ``writable``: the addresses a host may write (``CONTROL_ADDR`` among them), or None for
            every address. The others (constants, filter state, working registers) are read
            only to the host: a write to one is taken, changes nothing, and is counted. So is
            a CONTROL word the engine refuses (``control_accepted``).
    Members
        ``cfg`` (in, stream of ``ConfigWrite``): a write per transfer, taken in one cycle while
            ``open``. ``CONTROL_ADDR`` sets ``select`` (bits 1:0, unless bit 3 says keep it)
            and, with bit 2, pulses ``reset``; another filter than the present one pulses
            ``switched``. Any other writable address writes the register file.
        ``refused`` (out, 16): writes refused since reset (saturating at 65535).
        ``cfg_read`` (in, stream of addresses) / ``cfg_read_data`` (out, stream of signed 32):
            a read per transfer, taken while ``open`` and no read is outstanding; the word
            comes one cycle later and is held until taken. ``CONTROL_ADDR`` reads ``select``:
            the register file's word there is never written and reads 0 (the engine checks
            its program and reset values), and the select is ORed into its low bits.
        ``open`` (in): the engine is idle and will not start anything this cycle.
        ``w_en``, ``w_addr``, ``w_data`` (out): the register-file write (the address and data
            are the transfer's whatever ``w_en``).
        ``r_en``, ``r_addr`` (out), ``r_data`` (in, signed 32): the read port, word next cycle
            (the address is the read transfer's whatever ``r_en``).
        ``select`` (out, ``FILTER_CODE_BITS``): the filter select; ``reset``, ``switched`` (out): one-cycle pulses.
    Latency: a write reaches the register file's write port in the cycle it is taken; a
    read's word is offered the cycle after its address is taken.
    """

    def __init__(self, filter_at_reset=0, writable=None):
        self.filter_at_reset = filter_at_reset
        self.writable = None if writable is None else frozenset(writable)
        super().__init__({
            "cfg": In(stream.Signature(ConfigWrite)),
            "cfg_read": In(stream.Signature(REG_BITS)),
            "cfg_read_data": Out(stream.Signature(signed(32))),
            "open": In(1),
            "w_en": Out(1), "w_addr": Out(REG_BITS), "w_data": Out(signed(32)),
            "r_en": Out(1), "r_addr": Out(REG_BITS), "r_data": In(signed(32)),
            "select": Out(FILTER_CODE_BITS, init=filter_at_reset), "reset": Out(1), "switched": Out(1),
            "refused": Out(16),
        })

    def elaborate(self, platform):
        m = Module()
        write = self.cfg.payload
        # addresses and data pass ungated (their enables qualify them): a LUT a bit saved
        m.d.comb += [self.cfg.ready.eq(self.open), self.w_addr.eq(write.addr),
                     self.w_data.eq(write.data), self.r_addr.eq(self.cfg_read.payload)]
        allowed = Signal()
        m.d.comb += allowed.eq(write_allowed(write.addr, write.data, self.writable))
        with m.If(self.cfg.valid & self.open & ~allowed):
            with m.If(self.refused != 0xFFFF):
                m.d.sync += self.refused.eq(self.refused + 1)
        with m.Elif(self.cfg.valid & self.open):
            with m.If(write.addr == CONTROL_ADDR):
                keep = write.data[CONTROL_KEEP.bit_length() - 1]
                new = Mux(keep, self.select, control_code(write.data))
                m.d.sync += self.select.eq(new)
                m.d.comb += [self.switched.eq(new != self.select),
                             self.reset.eq(write.data[CONTROL_RESET.bit_length() - 1])]
            with m.Else():
                m.d.comb += self.w_en.eq(1)

        # read-back: the word arrives one cycle after the address
        busy, control = Signal(), Signal()
        word = Signal(signed(32), reset_less=True)
        m.d.comb += [self.cfg_read_data.payload.eq(word),
                     self.cfg_read.ready.eq(self.open & ~busy & ~self.cfg_read_data.valid)]
        with m.If(busy):
            m.d.sync += [busy.eq(0), self.cfg_read_data.valid.eq(1),
                         word.eq(self.r_data | Mux(control, control_word_of(self.select), 0))]
        with m.If(self.cfg_read_data.valid & self.cfg_read_data.ready):
            m.d.sync += self.cfg_read_data.valid.eq(0)
        with m.If(self.cfg_read.valid & self.cfg_read.ready):
            m.d.comb += self.r_en.eq(1)
            m.d.sync += [busy.eq(1), control.eq(self.cfg_read.payload == CONTROL_ADDR)]
        return m
