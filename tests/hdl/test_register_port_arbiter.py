"""RegisterPortArbiter: the first client wins a free port, a command owns the port until its
response, bytes and responses go to the owner only."""

from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.sensor.register_port_arbiter import RegisterPortArbiter
from mpu9250_ahrs.sim.bench.streams import check_stream_rules


def test_priority_and_ownership():
    dut = RegisterPortArbiter()
    got = {"first": [], "second": [], "order": []}

    async def port_model(ctx):
        """Takes a command, answers ``length`` bytes (reg + i) and a response."""
        ctx.set(dut.port.cmd.ready, 1)
        for _ in range(3):
            # the command taken at this edge (valid and ready then)
            *_, reg, length, _ = await ctx.tick().sample(
                dut.port.cmd.payload.reg, dut.port.cmd.payload.length,
                dut.port.cmd.valid).until(dut.port.cmd.valid)
            got["order"].append(reg)
            ctx.set(dut.port.cmd.ready, 0)
            for i in range(length):
                ctx.set(dut.port.rx.valid, 1)
                ctx.set(dut.port.rx.payload, reg + i)
                await ctx.tick()
            ctx.set(dut.port.rx.valid, 0)
            ctx.set(dut.port.rsp.valid, 1)
            await ctx.tick()
            ctx.set(dut.port.rsp.valid, 0)
            ctx.set(dut.port.cmd.ready, 1)

    def client(name, bus, commands, delay):
        async def run(ctx):
            ctx.set(bus.rx.ready, 1)
            ctx.set(bus.rsp.ready, 1)
            await ctx.tick().repeat(delay)
            for reg, length in commands:
                ctx.set(bus.cmd.payload, {"reg": reg, "length": length})
                ctx.set(bus.cmd.valid, 1)
                await ctx.tick().until(bus.cmd.ready)
                ctx.set(bus.cmd.valid, 0)
                while True:
                    _, _, rx_valid, rx, rsp_valid = await ctx.tick().sample(
                        bus.rx.valid, bus.rx.payload, bus.rsp.valid)
                    if rx_valid:
                        got[name].append(rx)
                    if rsp_valid:
                        got[name].append("rsp")
                        break
        return run

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    for name in ("first", "second"):
        for member in ("rx", "rsp"):
            check_stream_rules(sim, getattr(getattr(dut, name), member), f"{name}.{member}")
    check_stream_rules(sim, dut.port.cmd, "port.cmd")
    sim.add_testbench(port_model)
    # both offer in the same cycle: the first goes first, and again when it offers its next
    # command at once; the second's command waits, whole
    sim.add_testbench(client("first", dut.first, [(0x10, 1), (0x30, 2)], 2))
    sim.add_testbench(client("second", dut.second, [(0x20, 3)], 2))
    sim.run()
    assert got["order"] == [0x10, 0x30, 0x20]
    assert got["first"] == [0x10, "rsp", 0x30, 0x31, "rsp"]
    assert got["second"] == [0x20, 0x21, 0x22, "rsp"]
