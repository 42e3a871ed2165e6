"""Telemetry scheduler: every result of the attitude engine is taken (at once, or after the
framer's copy of it); every ``divider``-th one is framed if the UART is free, and counters say
what happened to the rest.

The engine therefore never waits for the UART: at any sample rate it filters every sample,
while the telemetry carries the latest result at the rate the link allows.
"""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..engine.attitude_result import Attitude
from ..sensor.driver_status import DriverStatus
from .frame_types import AttitudeFrame, FramedAttitude, TelemetryCounters
from ..sensor.sample import Sample


__all__ = ["TelemetryScheduler"]


class TelemetryScheduler(wiring.Component):
    """Takes every engine result and offers every ``divider``-th to a buffered framer.

    The counters (``TelemetryCounters``: three of 32 bits) share one 4-bit adder: a result's
    increments (1 to ``filtered``, the sample's ``skipped`` to ``lost``, 1 to ``not_sent`` if
    it is due and will not be framed) are made in the ``COUNT_CYCLES`` (24) cycles after it
    comes, the three counters turning through the adder a nibble a cycle, once round (each
    register loaded from its neighbour: no multiplexer in front of the adder, which costs
    about two LUTs a bit in a LUT4 fabric, no copy of the counters, which would cost an LE a
    bit, and no 32-bit adder).

    Members
        ``results`` (in, stream of ``Attitude``): a result is counted in the
            ``COUNT_CYCLES`` cycles after it is valid; one that is not framed is then taken;
            one that is framed is taken when the framer has copied it
            (``TelemetryFramer(buffered=True)``: 22 cycles for an attitude frame), never
            later.
        ``sample`` (in, ``Sample``) and ``status`` (in, ``DriverStatus``): the sample the
            present result came from and the driver status latched with it; they hold while
            the result is valid (the engine takes no new sample before its result is taken).
        ``divider`` (in, 16): frame every ``divider``-th result (0 is taken as 1).
        ``cfg_refused`` (in, 16): the engine's count of refused host writes, framed as it was
            in the cycle before the frame is offered (it may change while the frame waits: the
            frame keeps that value).
        ``framer_idle`` (in): the framer would copy a frame at once. A due result that finds
            it busy (still sending the last frame) as it comes is not framed, and counted.
            (Only this scheduler gives the framer frames: idle as a result comes, it is still
            idle when the frame is offered.)
        ``frames`` (out, stream of ``AttitudeFrame``): the result, its sample and status and
            the counters including it; valid only while the result is, payload still.
        ``counters`` (out, ``TelemetryCounters``): the counters, with every result taken and
            the one being offered; in the ``COUNT_CYCLES`` cycles after a result comes they
            turn (each field shows others' bits), and are in place again after them.

    Latency: ``COUNT_CYCLES`` (24) cycles from a result to ``frames.valid`` (or to its being
    taken, if it is not framed). Throughput: one result per 25 cycles when none is framed
    (the engine's shortest update is ten times longer).
    """
    COUNT_CYCLES = 3 * 32 // 4

    def __init__(self):
        super().__init__({
            "results": In(stream.Signature(Attitude)),
            "sample": In(Sample),
            "status": In(DriverStatus),
            "divider": In(16),
            "cfg_refused": In(16),
            "framer_idle": In(1),
            "frames": Out(stream.Signature(AttitudeFrame)),
            "counters": Out(TelemetryCounters),
        })

    def elaborate(self, platform):
        m = Module()
        c = self.counters
        phase = Signal(16)                   # results since the last due one
        due = phase == 0
        # the present result: counted (its increments made, ``counters`` updated), and
        # whether it is framed (decided as it came: due and the framer idle)
        # the nibble at the adder (with ``busy``): counter ``counting[3:]``, its nibble
        # ``counting[:3]``
        counting = Signal(range(self.COUNT_CYCLES))
        busy = Signal()
        counted = Signal()
        framing = Signal()
        # (not while ``busy``, which a reset never sets with ``counted``: so says the gate to
        # an induction proof, which starts anywhere, that the counters hold still while valid)
        m.d.comb += self.frames.valid.eq(self.results.valid & counted & framing & ~busy)
        done = self.frames.valid & self.frames.ready
        take_now = self.results.valid & counted & ~framing
        m.d.comb += self.results.ready.eq(take_now | done)

        # the counters turning through one 4-bit adder, low nibble first: the head nibble is
        # added to and goes to the back; a counter's first nibble takes its increment (at
        # most 15), the others the carry
        chain = Cat(c.filtered, c.lost, c.not_sent)
        carry = Signal()
        which, first = counting[3:], counting[:3] == 0
        step = Mux(which == 0, 1, Mux(which == 1, self.sample.skipped, ~framing & due))
        added = Signal(5)
        m.d.comb += added.eq(chain[:4] + Mux(first, step, carry))
        with m.If(self.results.valid & ~counted & ~busy):
            m.d.sync += [busy.eq(1), counting.eq(0),
                         framing.eq(due & self.framer_idle)]
        with m.If(busy):
            m.d.sync += [chain.eq(Cat(chain[4:], added[:4])), carry.eq(added[4]),
                         counting.eq(counting + 1)]
            with m.If(counting == self.COUNT_CYCLES - 1):
                m.d.sync += [busy.eq(0), counted.eq(1)]         # in order again
        with m.If(self.results.valid & self.results.ready):
            m.d.sync += [counted.eq(0),
                         phase.eq(Mux(phase + 1 >= self.divider, 0, phase + 1))]

        # the count as it was in the cycle before the frame was offered, held while it is: a
        # register loaded in every other cycle (not a choice between it and the input, a LUT
        # a bit)
        refused = Signal(16, reset_less=True)
        with m.If(~self.frames.valid):
            m.d.sync += refused.eq(self.cfg_refused)

        p = self.frames.payload
        result = self.results.payload
        m.d.comb += [*(p.attitude[name].eq(result[name]) for name, _ in FramedAttitude),
                     p.sample.eq(self.sample),
                     p.status.eq(self.status),
                     p.cfg_refused.eq(refused),
                     p.counters.eq(c)]
        return m
