"""The attitude engine's config port shared by two clients: the core's own ``cfg`` port and the
command decoder."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .attitude_isa import REG_BITS
from .config_write import ConfigWrite


__all__ = ["ConfigPortArbiter"]


class ConfigPortArbiter(wiring.Component):
    """Two clients of the engine's register writes and reads, ``first`` before ``second``.

    A write or read address offered to the engine stays the one offered until the engine
    takes it (the choice is held from the cycle it is offered: a ``first`` arriving meanwhile
    waits), so a waiting transfer's payload never changes; otherwise ``first`` goes first. A
    read's word goes back to the client whose address the engine took (one read is
    outstanding at a time: the engine's port takes no address while a word waits).

    Members
        ``first``, ``second`` (in, streams of ``ConfigWrite``): the clients' writes.
        ``first_read``, ``second_read`` (in, streams of addresses): their reads.
        ``first_read_data``, ``second_read_data`` (out, streams of signed 32): their words.
        ``cfg``, ``cfg_read`` (out), ``cfg_read_data`` (in): the engine's port.
    Latency: none: a transfer passes through in the cycle the engine takes it.
    Throughput: one write and one read per cycle.
    """
    def __init__(self):
        super().__init__({
            "first": In(stream.Signature(ConfigWrite)),
            "second": In(stream.Signature(ConfigWrite)),
            "cfg": Out(stream.Signature(ConfigWrite)),
            "first_read": In(stream.Signature(REG_BITS)),
            "second_read": In(stream.Signature(REG_BITS)),
            "cfg_read": Out(stream.Signature(REG_BITS)),
            "cfg_read_data": In(stream.Signature(signed(32))),
            "first_read_data": Out(stream.Signature(signed(32))),
            "second_read_data": Out(stream.Signature(signed(32))),
        })

    @staticmethod
    def _share(m, name, a, b, out):
        """``out`` from ``a`` or ``b``; the choice held while ``out`` waits. Returns the
        choice (0: ``a``) in effect this cycle."""
        waiting = Signal(name=f"{name}_waiting")        # out was offered and not taken
        held = Signal(name=f"{name}_held")              # ... from this client
        choice = Signal(name=f"{name}_choice")
        m.d.comb += choice.eq(Mux(waiting, held, ~a.valid))
        m.d.comb += [out.valid.eq(Mux(choice, b.valid, a.valid)),
                     out.payload.eq(Mux(choice, b.payload, a.payload)),
                     a.ready.eq(out.ready & ~choice), b.ready.eq(out.ready & choice)]
        m.d.sync += [waiting.eq(out.valid & ~out.ready), held.eq(choice)]
        return choice

    def elaborate(self, platform):
        m = Module()
        self._share(m, "write", self.first, self.second, self.cfg)
        read_choice = self._share(m, "read", self.first_read, self.second_read, self.cfg_read)
        # whose read is outstanding: its word goes back to it
        reader = Signal()                                   # 1: second's
        with m.If(self.cfg_read.valid & self.cfg_read.ready):
            m.d.sync += reader.eq(read_choice)
        data = self.cfg_read_data
        m.d.comb += [self.first_read_data.payload.eq(data.payload),
                     self.second_read_data.payload.eq(data.payload),
                     self.first_read_data.valid.eq(data.valid & ~reader),
                     self.second_read_data.valid.eq(data.valid & reader),
                     data.ready.eq(Mux(reader, self.second_read_data.ready,
                                       self.first_read_data.ready))]
        return m
