"""Frame arbiter: two framers share one byte stream; frames are never interleaved, replies
go first, and every frame carries the next sequence number."""

import random

from amaranth import Elaboratable, Module
from amaranth.lib import data, wiring
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.link.frame_arbiter import FrameArbiter
from mpu9250_ahrs.hdl.link.frame_types import Reply, SensorFrame
from mpu9250_ahrs.hdl.link.telemetry import TelemetryFramer
from mpu9250_ahrs.host.protocol import decode_frames, unpack
from mpu9250_ahrs.sim.bench.streams import check_stream_rules


class Pair(Elaboratable):
    def __init__(self):
        self.replies = TelemetryFramer(Reply, 0x81)
        self.sensor = TelemetryFramer(SensorFrame, 0x01, buffered=True)
        self.arbiter = FrameArbiter(2)

    def elaborate(self, platform):
        m = Module()
        m.submodules.replies, m.submodules.sensor = self.replies, self.sensor
        m.submodules.arbiter = a = self.arbiter
        wiring.connect(m, self.replies.o_stream, a.i0)
        wiring.connect(m, self.sensor.o_stream, a.i1)
        m.d.comb += [self.replies.seq.eq(a.seq), self.sensor.seq.eq(a.seq)]
        return m


def test_frames_whole_replies_first_sequence_numbered():
    rng = random.Random(4)
    dut = Pair()
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.arbiter.o_stream, "link bytes")
    out = []
    sensor = [unpack(SensorFrame, rng.getrandbits(data.Layout.cast(SensorFrame).size))
              for _ in range(4)]
    replies = [unpack(Reply, rng.getrandbits(data.Layout.cast(Reply).size)) for _ in range(4)]

    def producer(stream, frames, gap):
        async def run(ctx):
            for f in frames:
                ctx.set(stream.payload, f)
                ctx.set(stream.valid, 1)
                await ctx.tick().until(stream.ready)
                ctx.set(stream.valid, 0)
                await ctx.tick().repeat(gap)
        return run

    async def consumer(ctx):
        ctx.set(dut.arbiter.o_stream.ready, 1)
        for n in range(3_000):
            ctx.set(dut.arbiter.o_stream.ready, n % 2)              # a slow link
            _, _, valid, ready, byte = await ctx.tick().sample(
                dut.arbiter.o_stream.valid, dut.arbiter.o_stream.ready,
                dut.arbiter.o_stream.payload)
            if valid and ready:
                out.append(byte)
    sim.add_testbench(producer(dut.sensor.i_stream, sensor, 5))
    sim.add_testbench(producer(dut.replies.i_stream, replies, 37))
    sim.add_testbench(consumer)
    sim.run()
    got = decode_frames(bytes(out), strict=True, with_seq=True)
    assert [seq for _, seq, _ in got] == list(range(8))
    assert [f for t, _, f in got if t == 0x01] == sensor
    assert [f for t, _, f in got if t == 0x81] == replies
    # a reply waiting when a frame ends goes next: the first frame is a reply (both ready at
    # once), and no two sensor frames run back to back while a reply waits
    assert got[0][0] == 0x81



def test_frames_counted_past_the_sequence_numbers():
    """``frames`` counts every frame: its low 8 bits (``seq``) at once, its high bits (a
    serial increment after each 256th frame) whenever ``frames_stable`` says they hold the
    count; they do again within 24 cycles. Frames of 7 bytes (the shortest), back to back."""
    dut = FrameArbiter(1)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    n_frames, length = 600, 7
    seen = {"stable": 0, "unstable_run": 0, "longest_unstable": 0}

    async def tb(ctx):
        ctx.set(dut.o_stream.ready, 1)
        ctx.set(dut.i0.valid, 1)
        sent = 0
        for k in range(n_frames * length):
            ctx.set(dut.i0.payload.last, k % length == length - 1)
            await ctx.tick()
            sent += k % length == length - 1
            assert ctx.get(dut.seq) == sent % 256
            if ctx.get(dut.frames_stable):
                assert ctx.get(dut.frames) == sent
                seen["stable"] += 1
                seen["unstable_run"] = 0
            else:
                seen["unstable_run"] += 1
                seen["longest_unstable"] = max(seen["longest_unstable"], seen["unstable_run"])

    sim.add_testbench(tb)
    sim.run()
    assert seen["longest_unstable"] == 24
    assert seen["stable"] > n_frames * length - 3 * 24
