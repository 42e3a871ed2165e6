"""The data-ready timer of the sample reader: the INT pin's edges, the intervals between them
against the sample period (samples skipped, a sample too early) and the data-ready time-out.

The rules (``hdl/FAULTS.md`` has what each catches):

- data-ready intervals against the sample period give ``skipped`` (samples made and never read);
  they are measured from the edge of the last burst that held a sample, so a burst without
  RAW_RDY (a spurious INT pulse, or a line stuck low) moves nothing and samples lost meanwhile
  show in the next interval;
- a data-ready interval shorter than ``EARLY_FRACTION`` (7/8) of the period (less the edge's
  allowed jitter, ``drdy_jitter_cycles``) is ``early``: whether it matters (a burst with a new
  sample: the sensor runs faster than configured) is the burst's check's to say;
- no data-ready edge for the time-out sets ``timed_out``.
"""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from ..primitives.clocking import ticks


__all__ = ["EARLY_FRACTION", "MAX_TICK_CYCLES", "tick_cycles", "DataReadyTimer"]


# A data-ready interval below this fraction of the configured period is early. The sensor's
# clock is within a few per cent of its nominal rate and an edge is seen within two cycles,
# so 7/8 leaves margin against false alarms; a rate divider that lost its value (SMPLRT_DIV
# n -> m < n: (m + 1)/(n + 1) of the period, at most 7/8 for n <= 7, or CONFIG's DLPF off:
# 1/8) is caught, and with a latched INT a rate too fast for the read shows as edges one
# read apart (read time < 7/8 of the period: ``rate_budget``'s bound is the period itself).
# Less the edge's own jitter where it has one (``DataReadyTimer``'s ``drdy_jitter_cycles``:
# with WAIT_FOR_ES, data-ready waits for the magnetometer's read, which a NACK cuts short).
EARLY_FRACTION = (7, 8)

# The longest tick: at low sample rates 1/64 of a period would be milliseconds, and the
# bring-up sequencer's waits (a millisecond between the self-test's reads) and the command
# decoder's time-out count the same tick; 1,024 cycles is 21 µs at 48 MHz.
MAX_TICK_CYCLES = 1024


def tick_cycles(period_cycles):
    """The cycles of the timer's tick (``DataReadyTimer.tick``): about 1/64 of the sample
    period, at most ``MAX_TICK_CYCLES``, which its interval clocks and time-outs count (and
    the driver's bring-up timer and the core's command time-out)."""
    return max(1, min(period_cycles // 64, MAX_TICK_CYCLES))


class DataReadyTimer(wiring.Component):
    """Data-ready edges, and the intervals a burst reader needs judged: one edge asks for one
    burst (``pending``); each burst's start and check (``burst_start``, ``check``) tell the
    timer which edge a burst was read for and whether it held a sample.

    Parameters
        ``int_active_low``: the INT pin's polarity; ``int_latched``: INT is latched until
            INT_STATUS is read (else a 50 µs pulse).
        ``period_cycles``: the sample period. ``first_timeout_cycles``: the data-ready
            time-out after ``start``; ``timeout_cycles`` after each check (each counted in
            ticks: it lasts its cycles to two ticks more).
        ``drdy_jitter_cycles`` (0): how much sooner a data-ready edge may come from a part
            that keeps its rate: an interval is early under ``EARLY_FRACTION`` of the period
            less this (rounded up to 4 ticks of its clocks: a sixteenth of a period at most),
            but never under half a period (``DriverTiming.drdy_jitter_cycles``).
    Members
        ``int_pin`` (in): INT, raw (synchronised here: two cycles).
        ``start`` (in, pulse): streaming begins: the time-out starts at
            ``first_timeout_cycles``, no interval has a base, and an INT already active counts
            as an edge (a latched one gives none).
        ``pending`` (out): an edge (or a read to be made again) waits for a burst.
        ``burst_start`` (in, pulse): a burst's read begins: it takes ``pending`` (an edge in
            this very cycle leaves it set).
        ``reading`` (in): a burst is in flight, before its check (an edge then is judged at
            the check).
        ``retry`` (in, pulse): the burst's read failed before INT_STATUS: an INT still active
            (latched: it gives no new edge) asks for a burst again.
        ``check`` (in, pulse) with ``spurious`` (in): a burst's check, and whether the burst
            held no sample (RAW_RDY 0). A burst with a sample moves the intervals' base to its
            edge (if an edge started it); one without leaves it where it was. With a latched
            INT still active after a spurious burst, a burst is asked for again (once per
            such burst: a line stuck high still times out). The time-out restarts at
            ``timeout_cycles``.
        ``skipped`` (out, 4 bits) and ``early`` (out): the judgement of the last edge's
            interval from the base: whole periods less one (samples made and never read), and
            under ``EARLY_FRACTION`` of a period. Set the cycle after an edge that comes
            between bursts, or after the check of the burst in flight when it came; cleared by
            ``start``.
        ``timed_out`` (out): no check for the time-out since the last (or since ``start``).
        ``tick`` (out): a pulse every ``tick_cycles(period_cycles)`` cycles, free-running (the
            prescaler of its clocks and time-out; the driver's sequencer counts it too).
        ``period`` (out): a pulse per sample period since the base, free-running (the
            magnetometer's freshness is counted in these).

    Latency: an edge is seen three cycles after the pin's (synchroniser, edge). Throughput: an
    edge a cycle.
    """

    def __init__(self, *, int_active_low=False, int_latched=True, period_cycles,
                 first_timeout_cycles, timeout_cycles, drdy_jitter_cycles=0):
        self.int_active_low = int_active_low
        self.int_latched = int_latched
        self.period_cycles = period_cycles
        self.first_timeout_cycles = first_timeout_cycles
        self.timeout_cycles = timeout_cycles
        self.drdy_jitter_cycles = drdy_jitter_cycles
        super().__init__({
            "int_pin": In(1), "start": In(1), "pending": Out(1),
            "burst_start": In(1), "reading": In(1), "retry": In(1),
            "check": In(1), "spurious": In(1),
            "skipped": Out(4), "early": Out(1), "timed_out": Out(1),
            "tick": Out(1), "period": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        int_sync = Signal()
        m.submodules.int_sync = FFSynchronizer(self.int_pin, int_sync)
        int_active, int_prev, int_edge = Signal(), Signal(), Signal()
        m.d.comb += [int_active.eq(int_sync ^ int(self.int_active_low)),
                     int_edge.eq(int_active & ~int_prev)]
        m.d.sync += int_prev.eq(int_active)

        # Intervals are measured from the edge of the last burst that held a sample
        # (``since_sample``), so a spurious pulse (its burst has no RAW_RDY: nothing was made)
        # moves nothing; an interval of n periods (rounded: a clock's phase starts half a
        # period in) means n - 1 samples made and never read (e.g. a latched INT still high
        # from the sample before). ``since_edge`` runs from the edge of the burst in flight (or
        # the latest), ``since_next`` from an edge that came while a burst was being read: that
        # one is judged at the burst's check, early if the burst held a sample (a read ends
        # well within a period, ``rate_budget``), else against the base before it.
        # The clocks count in ticks of about 1/64 of a period (one prescaler for all; at most
        # ``MAX_TICK_CYCLES``, so more at low rates): the rounding to whole periods and the
        # 7/8 threshold need no finer time, and a clock is then 10 bits, not 20 (1 kHz,
        # 48 MHz). ``steps`` ticks make a period, within half a tick.
        tick_len = tick_cycles(self.period_cycles)
        steps = max(2, round(self.period_cycles / tick_len))
        prescale = Signal(range(tick_len))
        step = self.tick
        m.d.comb += step.eq(prescale == tick_len - 1)
        m.d.sync += prescale.eq(Mux(step, 0, prescale + 1))
        clocks = [(Signal(range(steps), name=f"{c}_phase"), Signal(4, name=f"{c}_periods"))
                  for c in ("sample", "edge", "next")]
        since_sample, since_edge, since_next = clocks

        def advanced(clock):
            """``clock``'s value after this cycle's count."""
            ph, pe = clock
            wrap = step & (ph == steps - 1)
            return (Mux(wrap, 0, ph + step),
                    Mux(wrap & (pe != 15), pe + 1, pe))

        for clock in clocks:
            m.d.sync += [c.eq(v) for c, v in zip(clock, advanced(clock))]
        phase, periods = since_sample
        m.d.comb += self.period.eq(step & (phase == steps - 1))

        def restart_clock(clock):
            m.d.sync += [clock[0].eq(steps // 2), clock[1].eq(0)]

        def copy_clock(dst, src):
            """``dst`` takes ``src``'s value, advanced by this cycle's count."""
            m.d.sync += [d.eq(v) for d, v in zip(dst, advanced(src))]

        judge = self._judge(m, since_sample, self._early_phase(steps, tick_len))

        pending = self.pending
        seen_edge = Signal()                    # ``since_sample`` is a base
        pending_edge = Signal()                 # ``pending`` came from an edge
        read_edge = Signal()                    # the burst in flight was started by an edge
        deferred = Signal()                     # an edge came while it was read
        deferred_base = (Signal.like(phase), Signal.like(periods))   # ``since_sample`` then
        snap_edge = (Signal.like(phase), Signal.like(periods))       # ``since_edge`` then
        with m.If(int_edge):
            m.d.sync += [pending.eq(1), pending_edge.eq(1)]
            with m.If(self.reading):
                restart_clock(since_next)
                m.d.sync += [deferred.eq(1), deferred_base[0].eq(phase),
                             deferred_base[1].eq(periods), snap_edge[0].eq(since_edge[0]),
                             snap_edge[1].eq(since_edge[1])]
            with m.Else():
                restart_clock(since_edge)
                judge(since_sample, seen_edge)

        self._time_out(m, tick_len)

        with m.If(self.start):
            m.d.sync += [pending.eq(int_active), seen_edge.eq(0),
                         pending_edge.eq(0), deferred.eq(0), self.skipped.eq(0),
                         self.early.eq(0)]

        with m.If(self.burst_start):
            m.d.sync += [pending.eq(int_edge), read_edge.eq(pending_edge),
                         pending_edge.eq(int_edge)]

        with m.If(self.retry):
            m.d.sync += pending.eq(pending | int_active)

        with m.If(self.check):
            # A burst with a sample: intervals are measured from its edge (a base only if an
            # edge started its read: the one at ``start``, or one made again for a level
            # still high, has no known edge). An edge that came during its read is judged
            # now: from this burst's edge if it held a sample, else from the base.
            spurious = self.spurious
            with m.If(~spurious):
                m.d.sync += seen_edge.eq(read_edge)
                copy_clock(since_sample, since_edge)
            base_ok = Mux(~spurious, read_edge, seen_edge)
            with m.If(int_edge):                    # an edge in this very cycle
                restart_clock(since_edge)
                m.d.sync += deferred.eq(0)
                judge([Mux(~spurious, e, b) for e, b in zip(since_edge, since_sample)],
                      base_ok)
            with m.Elif(deferred):
                copy_clock(since_edge, since_next)
                m.d.sync += deferred.eq(0)
                judge([Mux(~spurious, e, b) for e, b in zip(snap_edge, deferred_base)],
                      base_ok)
            if self.int_latched:
                # after a spurious pulse's burst, a latched INT still active means a sample is
                # waiting that gave no edge (it rose under the pulse): read again
                with m.If(spurious & int_active & ~pending & ~int_edge):
                    m.d.sync += [pending.eq(1), pending_edge.eq(0)]
        return m

    def _judge(self, m, clock, early_phase):
        """One judge for the places an edge is judged (the last call that applies wins, as a
        statement would): returned, a function of the interval (phase, periods, like
        ``clock``'s) and whether its base is known, that sets ``skipped`` and ``early``."""
        judging = Signal()
        judged = (Signal.like(clock[0]), Signal.like(clock[1]))
        judged_ok = Signal()

        def judge(interval, base_ok):
            m.d.comb += [judging.eq(1), judged_ok.eq(base_ok),
                         *(j.eq(v) for j, v in zip(judged, interval))]

        with m.If(judging):
            ph, pe = judged
            m.d.sync += [self.skipped.eq(Mux(judged_ok & (pe > 1), pe - 1, 0)),
                         self.early.eq(judged_ok & ((pe == 0) |
                                                    ((pe == 1) & (ph < early_phase))))]
        return judge

    def _early_phase(self, steps, tick_len):
        """The phase (in ticks) under which an interval of one period is early: t < f·P - J
        with periods == 1 (at least half a period: then periods == 0 only), J the data-ready
        edge's allowed jitter (``drdy_jitter_cycles``) in the clocks' ticks; with a jitter,
        rounded down to a multiple of 4 ticks (a sixteenth of a period more allowance at most),
        so that the comparison leaves out the phase's two low bits."""
        num, den = EARLY_FRACTION
        jitter_ticks = -(-self.drdy_jitter_cycles // tick_len)
        early_phase = steps * (2 * num - den) // (2 * den)
        if jitter_ticks:
            early_phase = max(0, early_phase - jitter_ticks) // 4 * 4
        return early_phase

    def _time_out(self, m, tick_len):
        """The data-ready time-out: it counts the clocks' ticks, not cycles (a 12-bit count
        rather than a 22-bit one at 48 MHz and 1 kHz), from ``start`` and from each check."""
        # ``ticks``: at least the time-out (with ticks of a cycle, one cycle more)
        first_ticks, after_ticks = (ticks(cycles, tick_len, exact=cycles + 1) for cycles in
                                    (self.first_timeout_cycles, self.timeout_cycles))
        timer = Signal(range(max(first_ticks, after_ticks) + 1))
        m.d.comb += self.timed_out.eq(timer == 0)
        # the loads and the count as the flip-flops' enable: a LUT a bit chooses among two
        # constants and the decrement (a decrement of 0 or 1 every cycle with the loads over
        # it cost about 4 LUTs more, the mean of six syntheses of the timer alone)
        with m.If(self.check):
            m.d.sync += timer.eq(after_ticks)
        with m.Elif(self.start):
            m.d.sync += timer.eq(first_ticks)
        with m.Elif(self.tick & ~self.timed_out):
            m.d.sync += timer.eq(timer - 1)
