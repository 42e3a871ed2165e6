"""Telemetry scheduler: every result of the attitude engine is taken (at once, or after the
framer's copy of it); every ``divider``-th one is framed if the UART is free, and counters say
what happened to the rest.

The engine therefore never waits for the UART: at any sample rate it filters every sample,
while the telemetry carries the latest result at the rate the link allows.
"""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .attitude_result import Attitude
from .driver_status import DriverStatus
from .frame_types import AttitudeFrame, FramedAttitude, TelemetryCounters
from .sample import Sample


__all__ = ["TelemetryScheduler"]


class TelemetryScheduler(wiring.Component):
    """Takes every engine result and offers every ``divider``-th to a buffered framer.

    Members
        ``results`` (in, stream of ``Attitude``): a result that is not framed is taken in the
            cycle it is valid; one that is framed is taken when the framer has copied it
            (``TelemetryFramer(buffered=True)``: 22 cycles for an attitude frame), never later.
        ``sample`` (in, ``Sample``) and ``status`` (in, ``DriverStatus``): the sample the
            present result came from and the driver status latched with it; they hold while
            the result is valid (the engine takes no new sample before its result is taken).
        ``divider`` (in, 16): frame every ``divider``-th result (0 is taken as 1).
        ``cfg_refused`` (in, 16): the engine's count of refused host writes, framed as it is
            when the frame is offered (it may change while the frame waits: the frame keeps
            the value it was offered with).
        ``framer_idle`` (in): the framer would copy a frame at once. A due result that finds
            it busy (still sending the last frame) is not framed, and counted.
        ``frames`` (out, stream of ``AttitudeFrame``): the result, its sample and status and
            the counters including it; valid only while the result is, payload still.
        ``counters`` (out, ``TelemetryCounters``): the live counters.

    Latency: none (combinational) from a due result to ``frames.valid``. Throughput: one
    result per cycle when none is framed.
    """

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
        offering = Signal()                  # the present result is with the framer
        due = phase == 0
        start = self.results.valid & ~offering & due & self.framer_idle
        done = self.frames.valid & self.frames.ready
        take_now = self.results.valid & ~offering & ~start
        # ``offering`` implies ``results.valid`` (a result with the framer is not taken before
        # ``done``); saying so here lets the stream contract be proven by induction
        m.d.comb += [self.frames.valid.eq(self.results.valid & (offering | start)),
                     self.results.ready.eq(take_now | done)]
        with m.If(start & ~self.frames.ready):
            m.d.sync += offering.eq(1)
        with m.If(done):
            m.d.sync += offering.eq(0)

        # the count as offered, frozen while the frame waits to be copied (``offering``)
        refused = Signal(16, reset_less=True)   # loaded each cycle while not offering
        with m.If(~offering):
            m.d.sync += refused.eq(self.cfg_refused)

        p = self.frames.payload
        result = self.results.payload
        m.d.comb += [*(p.attitude[name].eq(result[name]) for name, _ in FramedAttitude),
                     p.sample.eq(self.sample),
                     p.status.eq(self.status), p.cfg_refused.eq(Mux(offering, refused, self.cfg_refused)),
                     p.counters.filtered.eq(c.filtered + 1),
                     p.counters.lost.eq(c.lost + self.sample.skipped),
                     p.counters.not_sent.eq(c.not_sent)]
        with m.If(self.results.valid & self.results.ready):
            m.d.sync += [c.filtered.eq(p.counters.filtered), c.lost.eq(p.counters.lost),
                         phase.eq(Mux(phase + 1 >= self.divider, 0, phase + 1))]
            with m.If(due & take_now):
                m.d.sync += c.not_sent.eq(c.not_sent + 1)
        return m
