"""``StreamTap`` against a model: random watched transfers and a consumer with random ready;
every copy offered is a watched payload, in order, the stream rules hold, and what is not
offered is counted. And the whole core's ``attitude`` port (issue #56): the first result held
while nobody takes it, every later one counted as dropped, the engine and telemetry unaffected."""

import random

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.link.stream_tap import StreamTap
from mpu9250_ahrs.sim.bench.streams import check_stream_rules


def test_tap_offers_every_transfer_it_can_and_counts_the_rest():
    dut = StreamTap(16)
    rng = random.Random(5)
    sent, got = [], []
    expected_dropped = []

    async def bench(ctx):
        waiting = None                     # the model: the copy offered, or None
        dropped = 0
        for cycle in range(3000):
            taken = rng.random() < 0.3
            value = rng.randrange(1 << 16)
            ready = rng.random() < 0.4
            ctx.set(dut.taken, taken)
            ctx.set(dut.payload, value)
            ctx.set(dut.o.ready, ready)
            # the design's offer this cycle is the model's
            assert bool(ctx.get(dut.o.valid)) == (waiting is not None), cycle
            if waiting is not None:
                assert ctx.get(dut.o.payload) == waiting, cycle
            transfer = waiting is not None and ready
            if transfer:
                got.append(waiting)
                waiting = None
            if taken:
                sent.append(value)
                if waiting is None:
                    waiting = value
                else:
                    dropped += 1
            await ctx.tick()
            assert ctx.get(dut.dropped) == dropped, cycle
        expected_dropped.append(dropped)

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.o, "tap")
    sim.add_testbench(bench)
    sim.run()
    assert len(got) > 300 and expected_dropped[0] > 100
    # what the consumer got is what was sent, in order, less what was dropped
    it = iter(sent)
    assert all(any(v == s for s in it) for v in got)


def test_the_dropped_count_saturates():
    dut = StreamTap(4)

    async def bench(ctx):
        ctx.set(dut.taken, 1)              # a transfer every cycle, nobody taking the copy
        for _ in range(0x10005):
            await ctx.tick()
        assert ctx.get(dut.dropped) == 0xFFFF and ctx.get(dut.o.valid)

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()


# a core build of its own (about 15 s to compile on a clean machine): the slow step
@pytest.mark.slow
def test_the_core_attitude_port_never_holds_the_engine():
    """The quick core with the port and nobody taking from it: the engine and telemetry run as
    without it; the port holds the first result (bit for bit) and counts every later one, and
    the sample port the first sample."""
    from mpu9250_ahrs.sim.scenarios.core import run_core
    from mpu9250_ahrs.sim.scenarios.setup import QUICK_CORE_BAUD, quick_core_setup
    run = run_core(quick_core_setup(), n_results=4, baud=QUICK_CORE_BAUD,
                   core_kwargs={"attitude_port": True})
    assert len(run.results) >= 4
    assert run.ports["attitude_valid"] == 1
    assert run.ports["attitude_payload"] == run.results[0]
    assert run.ports["attitude_dropped"] == len(run.results) - 1
    # the sample stream the same way: the first sample the engine took, the later ones counted
    assert run.ports["attitude_sample_valid"] == 1
    assert run.ports["attitude_sample_payload"] == run.samples[0]
    assert run.ports["attitude_sample_dropped"] == len(run.samples) - 1
    assert run.counters["lost"] == 0
