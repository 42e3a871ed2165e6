"""Event counters in a block RAM: every event counted (within the documented rate), counts
saturate, and a read returns the count."""

import random

from amaranth.hdl import Module, ResetInserter, Signal
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.link.event_counters import EventCounters


def run(dut, events, reads=None):
    """Drive ``events`` (a list of per-cycle bit masks) and ``reads`` ({cycle: counter}); return
    the counts left in the RAM and the reads' words with the events before them."""
    reads = reads or {}
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    out = {"reads": []}

    async def tb(ctx):
        so_far = [0] * dut.n                # events up to this cycle, per counter
        for cycle, mask in enumerate(events + [0] * (dut.n + 4)):
            ctx.set(dut.events, mask)
            k = reads.get(cycle)
            ctx.set(dut.r_en, k is not None)
            ctx.set(dut.r_addr, k or 0)
            for i in range(dut.n):
                so_far[i] += (mask >> i) & 1
            await ctx.tick()
            if k is not None:               # the word, the cycle after the read
                out["reads"].append((k, ctx.get(dut.r_data), so_far[k]))
        out["counts"] = [ctx.get(dut.ram.data[i]) for i in range(dut.n)]
    sim.add_testbench(tb)
    sim.run()
    return out


def test_sparse_random_events_and_reads():
    rng = random.Random(3)
    dut = EventCounters(5)
    n_cycles = 2_000
    # each counter's events at least n + 2 cycles apart: never merged, whatever the others
    events = [0] * n_cycles
    for k in range(dut.n):
        t = rng.randrange(8)
        while t < n_cycles:
            events[t] |= 1 << k
            t += dut.n + 2 + rng.randrange(20)
    reads = {t: rng.randrange(dut.n) for t in rng.sample(range(n_cycles), 200)}
    out = run(dut, events, reads)
    assert out["counts"] == [sum((e >> k) & 1 for e in events) for k in range(dut.n)]
    for k, word, before in out["reads"]:
        # the events up to the read's cycle, less those of its last three cycles (pending,
        # or written back as it reads): with these events' spacing, one at most
        assert before - 1 <= word <= before


def test_a_counter_every_other_cycle_beside_the_others():
    dut = EventCounters(5)
    events = [(1 if t % 2 == 0 else 0) | (0b11110 if t == 7 else 0) for t in range(60)]
    out = run(dut, events)
    assert out["counts"] == [30, 1, 1, 1, 1]


def test_counts_saturate():
    dut = EventCounters(3, width=4)
    events = [0b101 if t % 3 == 0 else 0 for t in range(60)]
    out = run(dut, events)
    assert out["counts"] == [15, 0, 15]


def test_two_events_in_consecutive_cycles_count_two():
    # the second is taken while the first is written back: it waits a cycle for that word
    dut = EventCounters(5)
    out = run(dut, [0] * 8 + [0b100, 0b100])
    assert out["counts"] == [0, 0, 2, 0, 0]


def test_a_reset_clears_the_counts():
    """A reset leaves the RAM but clears the counters: they read 0 through the read port and
    count from 0, from the first cycle after the reset."""
    dut = EventCounters(3)
    rst = Signal()
    top = Module()
    top.submodules.dut = ResetInserter(rst)(dut)
    sim = Simulator(top)
    sim.add_clock(1e-6)

    async def counts_after(ctx, masks):
        for mask in masks + [0] * 6:
            ctx.set(dut.events, mask)
            await ctx.tick()
        words = []
        for k in range(3):                  # through the read port, a word the cycle after
            ctx.set(dut.r_en, 1)
            ctx.set(dut.r_addr, k)
            await ctx.tick()
            words.append(ctx.get(dut.r_data))
        ctx.set(dut.r_en, 0)
        return words

    async def tb(ctx):
        assert await counts_after(ctx, [0] * 4 + [0b111, 0, 0b010]) == [1, 2, 1]
        ctx.set(rst, 1)
        await ctx.tick()
        ctx.set(rst, 0)
        assert await counts_after(ctx, []) == [0, 0, 0]
        assert await counts_after(ctx, [0b001, 0b001, 0, 0b100]) == [2, 0, 1]
    sim.add_testbench(tb)
    sim.run()
