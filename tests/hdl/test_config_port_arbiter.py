"""The engine's config port shared by two clients: every write and read delivered once, in
each client's order, the first client first when both wait, a waiting transfer never changing
under ``valid`` (the stream rules, checked every cycle), each read's word back to its client."""

import random

from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.engine.config_port_arbiter import ConfigPortArbiter
from mpu9250_ahrs.sim.bench.streams import check_stream_rules, stream_get


def test_two_clients_share_the_port():
    rng = random.Random(7)
    dut = ConfigPortArbiter()
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    for name in ("cfg", "cfg_read", "first_read_data", "second_read_data"):
        check_stream_rules(sim, getattr(dut, name), name)
    writes = {c: [{"addr": rng.randrange(256), "data": rng.randrange(-2 ** 31, 2 ** 31)}
                  for _ in range(30)] for c in ("first", "second")}
    reads = {c: [rng.randrange(256) for _ in range(15)] for c in ("first", "second")}
    taken, words = [], {"first": [], "second": []}

    def client(name):
        async def run(ctx):
            w_port, r_port = getattr(dut, name), getattr(dut, f"{name}_read")
            d_port = getattr(dut, f"{name}_read_data")
            for k, write in enumerate(writes[name]):
                await ctx.tick().repeat(1 + rng.randrange(3))
                ctx.set(w_port.payload, write)
                ctx.set(w_port.valid, 1)
                await ctx.tick().until(w_port.ready)
                ctx.set(w_port.valid, 0)
                if k % 2 == 0:
                    ctx.set(r_port.payload, reads[name][k // 2])
                    ctx.set(r_port.valid, 1)
                    await ctx.tick().until(r_port.ready)
                    ctx.set(r_port.valid, 0)
                    words[name].append(await stream_get(ctx, d_port, timeout=200))
        return run

    async def engine(ctx):
        pending = None
        async for _, _, valid, ready, payload, r_valid, r_ready, r_addr, d_valid, d_ready in \
                ctx.tick().sample(dut.cfg.valid, dut.cfg.ready, dut.cfg.payload,
                                  dut.cfg_read.valid, dut.cfg_read.ready, dut.cfg_read.payload,
                                  dut.cfg_read_data.valid, dut.cfg_read_data.ready):
            if valid and ready:
                taken.append({"addr": payload.addr, "data": payload.data})
            if d_valid and d_ready:
                pending = None
            if r_valid and r_ready:
                pending = r_addr
            busy = rng.random() < 0.4
            ctx.set(dut.cfg.ready, not busy)
            # the engine's port takes no address while a word waits
            ctx.set(dut.cfg_read.ready, not busy and pending is None)
            ctx.set(dut.cfg_read_data.valid, pending is not None)
            ctx.set(dut.cfg_read_data.payload, 3 * (pending or 0) + 1)

    sim.add_testbench(client("first"))
    sim.add_testbench(client("second"))
    sim.add_testbench(engine, background=True)
    sim.run()
    for name in ("first", "second"):
        mine = [t for t in taken if t in writes[name]]
        assert mine == writes[name], name                   # all, once, in order
        assert words[name] == [3 * a + 1 for a in reads[name]], name
    assert len(taken) == 60
