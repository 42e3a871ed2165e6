"""A byte FIFO whose reader can go back: the command decoder's input, so that a frame that
fails can be searched again for a header it swallowed."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .memories import FrameRAM


__all__ = ["RewindableFIFO"]


class RewindableFIFO(wiring.Component):
    """A FIFO that keeps the bytes its reader has taken until told to let them go, and can
    offer them again.

    Three pointers: ``write`` (next free place), ``read`` (next byte offered) and ``keep``
    (oldest byte kept). A byte taken is not freed while it is at or after ``keep``. The reader
    says, in the cycle it takes a byte or any other cycle:

    - ``mark``: the byte taken in this cycle becomes the oldest kept (a frame's first byte);
      every byte before it is freed;
    - ``release``: every byte taken, this cycle's included, is freed;
    - ``rewind``: the bytes after the oldest kept one are offered again, from the one after
      it, and the oldest kept one is freed (the frame that began there failed: search the rest
      for the next header). Takes precedence over the other two. Said only in a cycle where
      the byte offered is taken, or none is offered, so the offered byte never changes under
      ``valid`` (the stream rules); a byte taken with it is offered again like the others.

    Parameters
        ``depth``: places (a power of two). Bytes kept count against it.
    Members
        ``w_stream`` (in, byte stream): taken while fewer than ``depth`` bytes are stored
            (kept or waiting).
        ``r_stream`` (out, byte stream): the byte at ``read``, held while not taken.
        ``mark``, ``release``, ``rewind`` (in): above.
    Latency: a byte written is offered the next cycle (the memory's read is registered, at
    the pointer the reader will have; a byte written there in the same cycle comes through a
    bypass register); a rewind's first byte likewise. The bytes are in a ``FrameRAM`` (one
    M9K on a MAX10: ``ram``). Throughput: a byte per cycle in and out.
    """
    def __init__(self, depth=32):
        if depth & (depth - 1) or depth < 2:
            raise ValueError(f"depth {depth} is not a power of two")
        self.depth = depth
        self.ram = FrameRAM(depth, 8)
        super().__init__({
            "w_stream": In(stream.Signature(8)),
            "r_stream": Out(stream.Signature(8)),
            "mark": In(1), "release": In(1), "rewind": In(1),
        })

    def elaborate(self, platform):
        m = Module()
        bits = self.depth.bit_length()           # one wrap bit above the address
        m.submodules.ram = ram = self.ram
        write = Signal(bits)
        read = Signal(bits)
        keep = Signal(bits)

        stored = Signal(bits)
        m.d.comb += stored.eq(write - keep)
        m.d.comb += self.w_stream.ready.eq(stored < self.depth)
        put = self.w_stream.valid & self.w_stream.ready
        m.d.comb += [ram.w_addr.eq(write), ram.w_data.eq(self.w_stream.payload),
                     ram.w_en.eq(put)]
        with m.If(put):
            m.d.sync += write.eq(write + 1)

        # the read port read last cycle at the pointer ``read`` has now (below), so its word
        # is the byte there: written before, or in that cycle (then from ``bypass``)
        bypass, bypass_data = Signal(), Signal(8)
        valid = Signal()
        m.d.comb += [self.r_stream.valid.eq(valid),
                     self.r_stream.payload.eq(Mux(bypass, bypass_data, ram.r_data))]
        take = self.r_stream.valid & self.r_stream.ready
        # a byte at ``read`` is waiting when read - keep < write - keep. ``read`` lies between
        # ``keep`` and ``write``, so this is read != write; written as distances it says so
        # to an induction proof, which starts anywhere (the inequality would offer a byte from
        # states no reset reaches, and take it back). Made from the pointers' registers, not
        # registered from their next values (the same signal, cycle for cycle: the pointers'
        # multiplexers in front of two subtractions cost about 20 LUTs more)
        m.d.comb += valid.eq((read - keep)[:bits] < (write - keep)[:bits])
        read_1, keep_1 = (read + 1)[:bits], (keep + 1)[:bits]
        read_next = Signal(bits)
        keep_next = Signal(bits)
        m.d.comb += [read_next.eq(Mux(take, read_1, read)), keep_next.eq(keep)]
        with m.If(self.rewind):
            m.d.comb += [read_next.eq(keep_1), keep_next.eq(keep_1)]
        with m.Elif(self.mark & take):
            m.d.comb += keep_next.eq(read)
        with m.Elif(self.release):
            m.d.comb += keep_next.eq(read_next)
        m.d.sync += [read.eq(read_next), keep.eq(keep_next)]
        # the RAM reads the old word at an address written in the same cycle: the byte written
        # there is taken from a register instead
        waddr = write[:bits - 1]
        m.d.comb += [ram.r_en.eq(1), ram.r_addr.eq(read_next[:bits - 1])]
        m.d.sync += [bypass.eq(put & (waddr == read_next[:bits - 1])),
                     bypass_data.eq(self.w_stream.payload)]
        return m
