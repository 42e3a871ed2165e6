"""Frame arbiter: several framers share one UART, a whole frame at a time, and every frame
that leaves gets the next sequence number."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .frame_types import FrameByte


__all__ = ["FrameArbiter"]


class FrameArbiter(wiring.Component):
    """Passes the frames of ``n`` framers to one byte stream, never interleaving two frames.

    Parameters
        ``n``: number of inputs; input 0 has the highest priority (the command replies: a
            host waiting for an answer should not wait behind telemetry), then 1, 2 ...
    Members
        ``inputs[i]`` (in, stream of ``FrameByte``): a framer's bytes; ``last`` ends a frame.
        ``o_stream`` (out, byte stream): to the UART.
        ``seq`` (out, 8): the sequence number of the frame being sent, or of the next one;
            it goes up by one after each frame's last byte (mod 256). Framers read it when
            they send their seq byte, which is after they were granted the link.
        ``frames`` (out, 32): frames sent since reset (wrapping), while ``frames_stable``.
            Its low 8 bits (``seq``) are a counter; the high 24 go up by one bit-serially in
            the 24 cycles after the low ones wrap (a bit a cycle through one adder bit: a
            status count read now and then needs no 24-bit incrementer), and read nothing
            meaningful meanwhile: ``frames_stable`` (out) is low then. A frame is 7 bytes at
            the least, so the low bits wrap again long after.
    Latency: none; a grant is decided combinationally in a cycle with no frame in progress
    and held from the cycle its first byte is offered until that frame's last byte is taken:
    a higher-priority frame arriving while a first byte waits for the UART does not replace
    it (that would change the byte under ``valid``). Throughput: the UART's.
    """
    def __init__(self, n):
        self.n = n
        super().__init__({
            **{f"i{k}": In(stream.Signature(FrameByte)) for k in range(n)},
            "o_stream": Out(stream.Signature(8)),
            "seq": Out(8),
            "frames": Out(32),
            "frames_stable": Out(1),
        })

    @property
    def inputs(self):
        return [getattr(self, f"i{k}") for k in range(self.n)]

    def elaborate(self, platform):
        m = Module()
        inputs = self.inputs
        busy = Signal()                          # a frame is offered or in progress
        held = Signal(range(self.n))             # ... from this input
        choice = Signal(range(self.n))
        # the highest-priority valid input, or the one holding the link
        for k in reversed(range(self.n)):
            with m.If(inputs[k].valid):
                m.d.comb += choice.eq(k)
        grant = Mux(busy, held, choice)
        last = Signal()
        with m.Switch(grant):
            for k, port in enumerate(inputs):
                with m.Case(k):
                    m.d.comb += [self.o_stream.valid.eq(port.valid),
                                 self.o_stream.payload.eq(port.payload.data),
                                 last.eq(port.payload.last),
                                 port.ready.eq(self.o_stream.ready)]
        sent = self.o_stream.valid & self.o_stream.ready
        # the sequence number is the count of frames sent, mod 256: one counter, not two
        low, high = Signal(8), Signal(24)
        carry = Signal()                        # the serial increment's carry
        steps = Signal(range(len(high) + 1))    # the increment's bits still to go
        m.d.comb += [self.seq.eq(low), self.frames.eq(Cat(low, high)),
                     self.frames_stable.eq(steps == 0)]
        with m.If(steps != 0):
            # ``high`` turns once, low bit first, each bit plus the carry on its way in
            m.d.sync += [high.eq(Cat(high[1:], high[0] ^ carry)), carry.eq(high[0] & carry),
                         steps.eq(steps - 1)]
        with m.If(sent):
            m.d.sync += [busy.eq(~last), held.eq(grant)]
            with m.If(last):
                m.d.sync += low.eq(low + 1)
                with m.If(low.all()):
                    m.d.sync += [steps.eq(len(high)), carry.eq(1)]
        with m.Elif(self.o_stream.valid):
            # a first byte waits: the choice is made
            m.d.sync += [busy.eq(1), held.eq(grant)]
        return m
