"""A tap on a stream: each transfer it sees, held and offered as a stream of its own that never
holds the watched stream up (the attitude for the user's logic, ``AHRSCore(attitude_port=True)``)."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out


__all__ = ["StreamTap"]


class StreamTap(wiring.Component):
    """Offers a copy of every transfer of a watched stream, without taking part in it.

    Parameters
        ``shape``: the watched stream's payload shape (``Attitude`` for the core's results).
    Members
        ``taken`` (in): the watched stream transfers this cycle (its ``valid & ready``);
            ``payload`` (in, ``shape``): its payload then.
        ``o`` (out, stream of ``shape``): each transfer's payload, held until taken (the stream
            rules: ``valid`` stays up and the payload still until a cycle with ``ready``).
        ``dropped`` (out, 16): transfers not offered because the one before was still waiting
            (saturating at 0xFFFF; reset only with the design). A slow consumer therefore sees
            the oldest result it has not taken, then the next that comes after it: the
            payload's own counter shows the gap.
    Latency: the copy is offered the cycle after the watched transfer. Throughput: one a
    cycle (taken and a new transfer in one cycle: the new one follows at once).
    """

    def __init__(self, shape):
        super().__init__({
            "taken": In(1),
            "payload": In(shape),
            "o": Out(stream.Signature(shape)),
            "dropped": Out(16),
        })

    def watch(self, stream):
        """The statements (comb) that make this tap watch ``stream``: its transfers and
        payload."""
        return [self.taken.eq(stream.valid & stream.ready), self.payload.eq(stream.payload)]

    def elaborate(self, platform):
        m = Module()
        waiting = self.o.valid & ~self.o.ready
        with m.If(self.o.valid & self.o.ready):
            m.d.sync += self.o.valid.eq(0)
        with m.If(self.taken):
            with m.If(waiting):
                # the copy offered stays (its payload must hold still): this one is lost
                with m.If(~self.dropped.all()):
                    m.d.sync += self.dropped.eq(self.dropped + 1)
            with m.Else():
                m.d.sync += [self.o.payload.eq(self.payload), self.o.valid.eq(1)]
        return m
