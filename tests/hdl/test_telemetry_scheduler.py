"""TelemetryScheduler against a model: which results are framed, what is counted."""

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.link.telemetry_scheduler import TelemetryScheduler
from mpu9250_ahrs.sim.bench.streams import check_stream_rules


@pytest.mark.parametrize("divider", [1, 3])
def test_every_nth_result_framed_when_the_framer_is_idle(divider):
    """Ten results; the framer is busy for results 4 and 5 (a frame still going out) and
    takes a frame 3 cycles after it is offered. Framed: every ``divider``-th result that
    finds the framer idle; the others are counted in ``not_sent`` if they were due. Every
    result is taken, and ``lost`` sums the samples' ``skipped``."""
    dut = TelemetryScheduler()
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.frames, "frames")
    skipped = [0, 0, 2, 0, 1, 0, 0, 0, 3, 0]
    busy = {4, 5}
    framed, counters_seen = [], []

    async def tb(ctx):
        ctx.set(dut.divider, divider)
        for k in range(10):
            ctx.set(dut.framer_idle, k not in busy)
            ctx.set(dut.sample.counter, k)
            ctx.set(dut.sample.skipped, skipped[k])
            ctx.set(dut.results.payload.counter, k)
            ctx.set(dut.results.payload.quat[0], 100 + k)   # the frame's result (no counter)
            ctx.set(dut.cfg_refused, 7 * k)
            ctx.set(dut.results.valid, 1)
            waited = 0
            while True:
                if ctx.get(dut.frames.valid):
                    waited += 1
                    ctx.set(dut.frames.ready, waited == 3)
                    if waited == 3:
                        p = dut.frames.payload
                        assert ctx.get(p.attitude.quat[0]) == 100 + k
                        assert ctx.get(p.cfg_refused) == 7 * k
                        framed.append(ctx.get(p.sample.counter))
                        counters_seen.append(
                            {n: ctx.get(getattr(dut.frames.payload.counters, n))
                             for n in ("filtered", "lost", "not_sent")})
                taken = ctx.get(dut.results.ready)
                await ctx.tick()
                if taken:
                    break
            ctx.set(dut.frames.ready, 0)
            ctx.set(dut.results.valid, 0)
            await ctx.tick()
        c = dut.counters
        assert ctx.get(c.filtered) == 10 and ctx.get(c.lost) == sum(skipped)
        due = [k for k in range(10) if k % divider == 0]
        assert ctx.get(c.not_sent) == len([k for k in due if k in busy])
    sim.add_testbench(tb)
    sim.run()
    due = [k for k in range(10) if k % divider == 0]
    assert framed == [k for k in due if k not in busy]
    for k, c in zip(framed, counters_seen):
        assert c["filtered"] == k + 1 and c["lost"] == sum(skipped[:k + 1])
