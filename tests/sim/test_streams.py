"""The testbench stream helpers: ``stream_get`` takes transfers, and both checkers of the
stream rules (the Python process and the ``StreamMonitor`` logic) catch a producer that
changes its payload under ``valid``, and pass one that keeps the rules."""

import pytest
from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import Out
from amaranth.sim import Simulator

from mpu9250_ahrs.sim.bench.streams import StreamMonitor, check_stream_rules, stream_get


class Counter(wiring.Component):
    """Offers 1, 2, 3 ... (valid on all but multiples of 4); ``torn``: the count also moves
    while a transfer waits."""
    o: Out(stream.Signature(data.StructLayout({"low": 4, "high": 4})))

    def __init__(self, torn):
        self.torn = torn
        super().__init__()

    def elaborate(self, platform):
        m = Module()
        count = Signal(8)
        m.d.comb += [self.o.valid.eq(count[:2] != 0), self.o.payload.eq(count)]
        with m.If(~self.o.valid | self.o.ready | self.torn):
            m.d.sync += count.eq(count + 1)
        return m


class Watched(Elaboratable):
    def __init__(self, dut):
        self.dut, self.monitor = dut, StreamMonitor(dut.o, "o")

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut, m.submodules.monitor = self.dut, self.monitor
        return m


@pytest.mark.parametrize("checker", ["process", "monitor"])
@pytest.mark.parametrize("torn", [False, True])
def test_checkers(checker, torn):
    top = Watched(Counter(torn))
    got = []

    async def consumer(ctx):
        for _ in range(4):
            got.append(Const.cast(await stream_get(ctx, top.dut.o, timeout=20)).value)
            await ctx.tick().repeat(3)                    # back-pressure between transfers
        if checker == "monitor":
            top.monitor.check(ctx)

    sim = Simulator(top)
    sim.add_clock(1e-6)
    sim.add_testbench(consumer)
    if checker == "process":
        check_stream_rules(sim, top.dut.o, "o")
    if torn:
        with pytest.raises(AssertionError, match="changed under valid|withdrawn before"):
            sim.run()
    else:
        sim.run()
        assert got == [1, 2, 3, 5]
