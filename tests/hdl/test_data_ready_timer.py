"""The data-ready timer (``DataReadyTimer``) on its own, driven by a reader that reads a burst
whenever an edge is pending: intervals judged against the period (samples skipped, an early
sample), a spurious burst that moves nothing, an edge during a read judged at its check, a
latched INT read again, the time-out, the tick."""

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.sensor.data_ready_timer import (MAX_TICK_CYCLES, DataReadyTimer,
                                                      tick_cycles)


PERIOD = 256            # ticks of 4 cycles, 64 to a period
READ = 40               # cycles from a burst's start to its check
PULSE = 16              # cycles an INT pulse is high (not latched)


def run(edges, *, spurious=(), read=READ, latched=False, level=None, cycles=None,
        timeout=4 * PERIOD):
    """INT pulses rising at the cycles in ``edges`` (or, latched, the pin given per cycle by
    ``level``); a reader that starts a burst the cycle it sees ``pending`` and checks it
    ``read`` cycles later (no sample in the bursts whose index is in ``spurious``). Returns,
    per check, (start cycle, ``skipped``, ``early``) as the reader sees them at its check, and
    the cycles ``timed_out`` was high."""
    dut = DataReadyTimer(int_latched=latched, period_cycles=PERIOD,
                         first_timeout_cycles=timeout, timeout_cycles=timeout)
    end = cycles if cycles is not None else max(edges, default=0) + PERIOD
    checks, timed_out = [], []

    async def bench(ctx):
        # the pin as it was before streaming began (``level(-1)``), through the synchroniser
        ctx.set(dut.int_pin, level(-1) if level else 0)
        await ctx.tick().repeat(4)
        ctx.set(dut.start, 1)
        await ctx.tick()
        ctx.set(dut.start, 0)
        burst, started = 0, None
        for cycle in range(end):
            pin = level(cycle) if level else any(e <= cycle < e + PULSE for e in edges)
            ctx.set(dut.int_pin, pin)
            ctx.set(dut.burst_start, 0)
            ctx.set(dut.check, 0)
            if started is None and ctx.get(dut.pending):
                ctx.set(dut.burst_start, 1)
                started = cycle
            elif started is not None and cycle - started == read:
                ctx.set(dut.check, 1)
                ctx.set(dut.spurious, burst in spurious)
                checks.append((started, ctx.get(dut.skipped), ctx.get(dut.early)))
                burst, started = burst + 1, None
            ctx.set(dut.reading, started is not None and cycle != started)
            if ctx.get(dut.timed_out):
                timed_out.append(cycle)
            await ctx.tick()

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return checks, timed_out


def test_intervals_on_time_skipped_and_early():
    """A period apart: nothing skipped, nothing early (the first edge has no base); three
    periods: two samples skipped; 5/8 of a period: early; 15/16: on time (the threshold is
    7/8)."""
    P = PERIOD
    edges = [10, 10 + P, 10 + 2 * P, 10 + 5 * P, 10 + 5 * P + 5 * P // 8,
             10 + 5 * P + 5 * P // 8 + 15 * P // 16]
    checks, _ = run(edges)
    assert [(s, e) for _, s, e in checks] == [(0, 0), (0, 0), (0, 0), (2, 0), (0, 1), (0, 0)]
    # each burst starts four cycles after its edge (synchroniser, edge, pending)
    assert [c for c, _, _ in checks] == [e + 3 for e in edges]


def test_spurious_burst_moves_nothing():
    """A burst without a sample (a spurious pulse half a period in) is not a base: the next
    edge, a period after the last sample's, is on time, not early. (The spurious edge itself
    is early: the reader acts on ``early`` only for a burst with a sample.)"""
    P = PERIOD
    edges = [10, 10 + P, 10 + P + P // 2, 10 + 2 * P]
    checks, _ = run(edges, spurious={2})
    assert [(s, e) for _, s, e in checks] == [(0, 0), (0, 0), (0, 1), (0, 0)]
    # without the spurious flag that edge is early and the next is early from it too
    checks, _ = run(edges)
    assert [e for _, _, e in checks] == [0, 0, 1, 1]


def test_edge_during_a_read_is_judged_at_its_check():
    """An edge while a burst is read is pending once the check is made (a burst follows at
    once), judged from that burst's edge if it held a sample: early here (the part runs
    fast)."""
    P = PERIOD
    edges = [10, 10 + P, 10 + P + 20]           # the third comes while the second is read
    checks, _ = run(edges, read=60)
    assert [(s, e) for _, s, e in checks] == [(0, 0), (0, 0), (0, 1)]
    assert checks[2][0] == checks[1][0] + 60 + 1


def test_latched_int_still_active_after_a_spurious_burst_is_read_again():
    """Latched: INT rises under a spurious burst's read (no new edge: the pin stays high); the
    check asks for one more burst, once."""
    P = PERIOD

    def level(cycle):
        return 10 <= cycle < 30 or cycle >= P

    checks, _ = run([], latched=True, level=level, spurious={1}, cycles=2 * P)
    starts = [c for c, _, _ in checks]
    assert starts[1] == P + 3 and starts[2] == starts[1] + READ + 1 and len(starts) == 3


def test_time_out_and_its_restart_at_each_check():
    """``timed_out`` rises after the first time-out without a check, and a check starts it
    again; it lasts its cycles to two ticks more."""
    timeout = 2 * PERIOD
    _, timed_out = run([], cycles=3 * PERIOD, timeout=timeout)
    tick = tick_cycles(PERIOD)
    assert timeout <= timed_out[0] <= timeout + 2 * tick
    _, timed_out = run([PERIOD], cycles=4 * PERIOD, timeout=timeout)
    assert PERIOD + READ + timeout <= timed_out[0] <= PERIOD + READ + timeout + 2 * tick + 4


def test_tick_is_about_a_64th_of_a_period_at_most_max():
    """The timer's tick, which the bring-up waits and the command time-out count too: 1/64 of
    the period, at most ``MAX_TICK_CYCLES`` (so the self-test's 1 ms between reads stays
    about 1 ms at low sample rates), at least a cycle."""
    assert tick_cycles(48_000) == 750                      # 1 kHz at 48 MHz
    assert tick_cycles(48_000_000 // 4) == MAX_TICK_CYCLES == 1024
    assert tick_cycles(10) == 1


@pytest.mark.parametrize("latched", [False, True])
def test_start_with_int_active_counts_as_an_edge(latched):
    """An INT already active at ``start`` (a latched one gives no edge) asks for a burst; its
    interval has no base."""
    checks, _ = run([], latched=latched, level=lambda cycle: 1, cycles=PERIOD)
    assert len(checks) == 1 and checks[0] == (0, 0, 0)
