"""Rewindable FIFO: random writes, reads, marks, releases and rewinds against a model of the
three pointers; nothing lost, nothing duplicated but what a rewind offers again, and the
stream rules kept on both sides."""

import random

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.link.rewindable_fifo import RewindableFIFO
from mpu9250_ahrs.sim.bench.streams import check_stream_rules


class Model:
    """The FIFO as a list: ``kept`` (taken, not freed) then ``waiting`` (not taken yet)."""
    def __init__(self, depth):
        self.depth, self.kept, self.waiting = depth, [], []

    def room(self):
        return len(self.kept) + len(self.waiting) < self.depth

    def cycle(self, put, take, mark, release, rewind):
        """One clock cycle: ``put`` a byte (or None), ``take`` the offered byte or not; returns
        the byte taken (None if none)."""
        taken = None
        if rewind:          # (a byte offered in that cycle is not taken)
            self.waiting = self.kept[1:] + self.waiting
            self.kept = []
        else:
            if take and self.waiting:
                taken = self.waiting.pop(0)
                self.kept = [taken] if mark else self.kept + [taken]
            if release and not (mark and take):     # a mark with a take is the stronger word
                self.kept = []
        if put is not None:
            self.waiting.append(put)
        return taken


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_against_model(seed):
    rng = random.Random(seed)
    dut = RewindableFIFO(depth=8)
    model = Model(8)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.w_stream, "w_stream")
    check_stream_rules(sim, dut.r_stream, "r_stream")
    log = {"taken": 0, "rewinds": 0}
    invariant = dut.invariant()

    async def tb(ctx):
        nxt = 0
        offering = None
        for _ in range(3_000):
            # the writer: a new byte sometimes; an offered one stays until taken
            if offering is None and rng.random() < 0.6:
                offering = nxt & 0xFF
                nxt += 1
            ctx.set(dut.w_stream.valid, offering is not None)
            ctx.set(dut.w_stream.payload, offering or 0)
            ready = rng.random() < 0.7
            mark = rng.random() < 0.2
            release = rng.random() < 0.05
            valid = ctx.get(dut.r_stream.valid)
            # a rewind only when something is kept (the decoder rewinds a frame it kept), and
            # (the stream rules) with the byte offered taken or none offered
            rewind = (rng.random() < 0.05 and bool(model.kept) and (ready or not valid))
            ctx.set(dut.r_stream.ready, ready)
            ctx.set(dut.mark, mark)
            ctx.set(dut.release, release)
            ctx.set(dut.rewind, rewind)
            w_ready = ctx.get(dut.w_stream.ready)
            assert w_ready == model.room()
            assert ctx.get(invariant)           # (the formal checks prove it)
            valid = ctx.get(dut.r_stream.valid)
            # the model offers what it has waiting; the FIFO offers it a cycle after it came
            assert valid == bool(model.waiting)
            if valid:
                assert ctx.get(dut.r_stream.payload) == model.waiting[0]
            take = valid and ready
            put = offering if (offering is not None and w_ready) else None
            taken = model.cycle(put, take, mark, release, rewind)
            log["taken"] += taken is not None
            log["rewinds"] += rewind
            if put is not None:
                offering = None
            await ctx.tick()
    sim.add_testbench(tb)
    sim.run()
    assert log["taken"] > 500 and log["rewinds"] > 50


@pytest.mark.filterwarnings("ignore::amaranth.hdl.UnusedElaboratable")
def test_depth_must_be_a_power_of_two():
    with pytest.raises(ValueError, match="power of two"):
        RewindableFIFO(depth=12)
