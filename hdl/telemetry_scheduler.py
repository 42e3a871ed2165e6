"""Telemetry scheduler: every result of the attitude engine is taken at once; every
``divider``-th one is framed if the UART is free, and counters say what happened to the rest.

The engine therefore never waits for the UART: at any sample rate it filters every sample,
while the telemetry carries the latest result at the rate the link allows.
"""

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from .sample import Attitude, DriverStatus, Sample


__all__ = ["TelemetryCounters", "AttitudeFrame", "TelemetryScheduler"]


class TelemetryCounters(data.Struct):
    """Counters carried in every attitude frame (all since reset, wrapping at 2³²).

    - ``filtered``: results the engine produced, this frame's included.
    - ``lost``: sensor samples that were never filtered: gaps in the driver's sample counter
      (the driver dropped a sample because the engine was still busy) plus the samples the
      driver saw the sensor produce but could not read (``Sample.skipped``). A restart of the
      driver's counter at 0 (a new bring-up) is not counted.
    - ``not_sent``: results that were due for telemetry (every ``divider``-th) while the
      previous frame was still being sent.
    """
    filtered: 32
    lost: 32
    not_sent: 32


class AttitudeFrame(data.Struct):
    """Frame type 0x02: an attitude result, the sample it came from, the driver status latched
    with that sample, and the telemetry counters at the time the result was taken."""
    attitude: Attitude
    sample: Sample
    status: DriverStatus
    counters: TelemetryCounters


class TelemetryScheduler(wiring.Component):
    """Takes every engine result and offers every ``divider``-th to the framer.

    Members
        ``results`` (in, stream of ``Attitude``): always ready (taken in the cycle it is valid).
        ``sample`` (in, ``Sample``) and ``status`` (in, ``DriverStatus``): the sample the
            present result came from and the driver status latched with it; read in the cycle
            a result is taken.
        ``divider`` (in, 16): frame every ``divider``-th result (0 is taken as 1).
        ``frames`` (out, stream of ``AttitudeFrame``): the payload is a copy made when the
            result was taken and holds still until the framer takes it (with its last byte).
        ``counters`` (out, ``TelemetryCounters``): the live counters.

    Latency: a due result is valid on ``frames`` one cycle after it was taken. Throughput:
    one result per cycle in; frames as fast as the framer takes them.
    """

    def __init__(self):
        super().__init__({
            "results": In(stream.Signature(Attitude)),
            "sample": In(Sample),
            "status": In(DriverStatus),
            "divider": In(16),
            "frames": Out(stream.Signature(AttitudeFrame)),
            "counters": Out(TelemetryCounters),
        })

    def elaborate(self, platform):
        m = Module()
        c = self.counters
        phase = Signal(16)                   # results since the last due one
        prev_counter = Signal(16)
        m.d.comb += self.results.ready.eq(1)

        with m.If(self.frames.valid & self.frames.ready):
            m.d.sync += self.frames.valid.eq(0)

        sample = self.sample
        # samples between the previous result's and this one's that were never filtered
        gap = Signal(16)
        m.d.comb += gap.eq(Mux(sample.counter == 0, 0, sample.counter - prev_counter - 1))
        filtered = c.filtered + 1
        lost = c.lost + gap + sample.skipped
        due = phase == 0
        with m.If(self.results.valid):
            m.d.sync += [c.filtered.eq(filtered), c.lost.eq(lost),
                         prev_counter.eq(sample.counter),
                         phase.eq(Mux(phase + 1 >= self.divider, 0, phase + 1))]
            with m.If(due & self.frames.valid):
                m.d.sync += c.not_sent.eq(c.not_sent + 1)
            with m.If(due & ~self.frames.valid):
                p = self.frames.payload
                m.d.sync += [self.frames.valid.eq(1), p.attitude.eq(self.results.payload),
                             p.sample.eq(sample), p.status.eq(self.status),
                             p.counters.filtered.eq(filtered), p.counters.lost.eq(lost),
                             p.counters.not_sent.eq(c.not_sent)]
        return m
