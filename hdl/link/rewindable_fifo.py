"""A byte FIFO whose reader can go back: the command decoder's input, so that a frame that
fails can be searched again for a header it swallowed."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..primitives.memories import FrameRAM


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
        ``invariant()``: what holds between the pointers in every reachable state (a
            ``Value``, for the formal checks).
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
        bits = depth.bit_length()               # one wrap bit above the address
        # the pointers, made here so that ``invariant`` can name them
        self._write = Signal(bits, name="write")
        self._read = Signal(bits, name="read")
        self._keep = Signal(bits, name="keep")
        super().__init__({
            "w_stream": In(stream.Signature(8)),
            "r_stream": Out(stream.Signature(8)),
            "mark": In(1), "release": In(1), "rewind": In(1),
        })

    def invariant(self):
        """What holds in every state a reset reaches (a ``Value``): ``read`` lies between
        ``keep`` and ``write`` (as distances from ``keep``). The byte offered is then the one
        at ``read`` exactly when ``read != write`` (``elaborate``). It holds whatever the
        reader says, a rewind with nothing kept included. The formal checks assert it, so that
        k-induction, which starts anywhere, starts only where it holds."""
        bits = len(self._write)
        return (self._read - self._keep)[:bits] <= (self._write - self._keep)[:bits]

    def elaborate(self, platform):
        m = Module()
        bits = self.depth.bit_length()           # one wrap bit above the address
        m.submodules.ram = ram = self.ram
        write, read, keep = self._write, self._read, self._keep

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
        # a byte at ``read`` is waiting when read - keep < write - keep: as ``read`` lies
        # between ``keep`` and ``write`` (``invariant``), when read != write. The equality
        # is 3 LUTs where the distances' two subtractions and comparison were about 20; the
        # formal checks prove the invariant, so their induction needs no more
        m.d.comb += valid.eq(read != write)
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
