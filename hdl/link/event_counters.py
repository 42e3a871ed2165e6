"""Event counters in a block RAM: saturating counts of events read now and then by a host."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..primitives.memories import FrameRAM


__all__ = ["EventCounters"]


class EventCounters(wiring.Component):
    """``n`` counters of ``width`` bits, saturating, kept in a ``FrameRAM`` (one M9K) rather
    than in flip-flops: in a LUT4 fabric each counter in logic costs an incrementer and its
    bits in the read-back multiplexer; here all of them share one incrementer and the RAM's
    read port.

    An event sets its counter's pending bit; each cycle the lowest pending counter is read
    (unless a read is made, or it is being written back) and, the cycle after, written back
    plus one (a counter at all ones stays): one count a cycle, pipelined. A pending bit holds
    one event: an event comes to nothing only if its counter is pending and not taken in that
    cycle. So the lowest counter's events are all counted as long as no three come in
    consecutive cycles and none in a cycle with a read (its pending bit is taken the cycle
    after an event, and is set again by an event in that cycle; it waits a cycle while its
    word is written back); a higher counter's, if each comes once its last has been taken.
    The command decoder's: discarded bytes (the lowest) at most two in a row (the byte its
    second-sync check turns back, then the one the hunt takes) and never while it reads a
    counter (as a frame ends); the others at most once per byte or frame, or (the sample
    reader's early samples) once per sample.

    A reset clears a bit per counter (set by its first count) rather than the RAM: a counter
    whose bit is clear reads 0, so the counts are from the reset, as registers' would be, and
    events are counted from the first cycle after it.

    Parameters
        ``n``: the counters; ``width``: their bits (16).
    Members
        ``events`` (in, ``n``): a pulse per event, any of them in any cycle.
        ``r_en``, ``r_addr`` (in) / ``r_data`` (out, ``width``): the count of counter
            ``r_addr``, the cycle after ``r_en`` (a read takes the RAM's read port for that
            cycle: the counting waits). It includes every event taken two cycles before.
        ``ram``: the ``FrameRAM`` (``report`` counts it). Tests read the counts in
            ``ram.data`` where no reset came after the first cycle (after one, a counter not
            counted since keeps its old word there, and reads 0 through the port).
    Latency: an event is in its count two cycles after it, plus a cycle for each lower
    counter pending and each read. Throughput: one count a cycle.
    """

    def __init__(self, n, width=16):
        if n < 1 or width < 1:
            raise ValueError(f"EventCounters needs a counter and a bit at least, not n={n}, "
                             f"width={width}")
        self.n = n
        self.width = width
        # a whole power of two of words: an address beyond ``n`` reads a word (0), not nothing
        self.ram = FrameRAM(1 << max(1, (n - 1).bit_length()), width)
        super().__init__({
            "events": In(n),
            "r_en": In(1), "r_addr": In(range(n)), "r_data": Out(width),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.ram = ram = self.ram
        n = self.n
        pending = Signal(n)
        # stage 2's counter: being written back now, so not read again in this cycle (the
        # RAM would return the old word); it is read the cycle after if pending again
        counting = Signal()
        counted = Signal(range(n), reset_less=True)
        writing = Signal(n)
        m.d.comb += writing.eq(Mux(counting, 1 << counted, 0))

        # stage 1: the lowest pending counter (or the host's read) addresses the RAM's read
        ready = pending & ~writing
        pick = Signal(range(n))
        for k in reversed(range(n)):
            with m.If(ready[k]):
                m.d.comb += pick.eq(k)
        count = ~self.r_en & (ready != 0)
        addr = Mux(self.r_en, self.r_addr, pick)
        # a counter counted since the reset: its word in the RAM is its count (else it is 0)
        valid = Signal(n)
        word_valid = Signal()                   # the word read was a count
        m.d.sync += [pending.eq((pending & ~Mux(count, 1 << pick, 0)) | self.events),
                     counting.eq(count), counted.eq(pick),
                     word_valid.eq(valid.bit_select(addr, 1))]
        m.d.comb += [ram.r_en.eq(1), ram.r_addr.eq(addr)]

        # stage 2: the word read, written back plus one (at all ones it stays)
        old = ram.r_data & word_valid.replicate(self.width)
        m.d.comb += [self.r_data.eq(old), ram.w_en.eq(counting), ram.w_addr.eq(counted),
                     ram.w_data.eq(old + ~old.all())]
        with m.If(counting):
            m.d.sync += valid.bit_select(counted, 1).eq(1)
        return m
