"""The engine's host port: register writes, the CONTROL register's select / switch / reset,
read-back one cycle later, nothing taken while the engine is not open."""

from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.engine.register_map import CONTROL_ADDR, control_word
from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_CODES
from mpu9250_ahrs.hdl.engine.host_port import HostPort
from mpu9250_ahrs.sim.bench.streams import check_stream_rules


def test_writes_control_and_read_back():
    dut = HostPort(filter_at_reset=FILTER_CODES["flagship"])
    seen = {}

    async def write(ctx, addr, data):
        """Offer a write; returns what the port drove in the cycle it was taken (the
        register-file write's address and data as 0 when it writes nothing: they are the
        transfer's whatever ``w_en``)."""
        ctx.set(dut.cfg.payload, {"addr": addr, "data": data})
        ctx.set(dut.cfg.valid, 1)
        w_en = ctx.get(dut.w_en)
        taken = (ctx.get(dut.cfg.ready), w_en, ctx.get(dut.w_addr) if w_en else 0,
                 ctx.get(dut.w_data) if w_en else 0, ctx.get(dut.switched), ctx.get(dut.reset))
        await ctx.tick()
        ctx.set(dut.cfg.valid, 0)
        return taken

    async def testbench(ctx):
        # closed: nothing is taken
        ctx.set(dut.open, 0)
        ctx.set(dut.cfg.payload, {"addr": 5, "data": 1})
        ctx.set(dut.cfg.valid, 1)
        assert not ctx.get(dut.cfg.ready) and not ctx.get(dut.w_en)
        ctx.set(dut.cfg.valid, 0)
        ctx.set(dut.open, 1)
        assert await write(ctx, 0x05, -123) == (1, 1, 0x05, -123, 0, 0)
        assert ctx.get(dut.select) == FILTER_CODES["flagship"]
        # the same filter: no switch; another: a switch; bit 2: a reset
        assert await write(ctx, CONTROL_ADDR, control_word("flagship")) == (1, 0, 0, 0, 0, 0)
        assert await write(ctx, CONTROL_ADDR, control_word("kalman")) == (1, 0, 0, 0, 1, 0)
        assert ctx.get(dut.select) == FILTER_CODES["kalman"]
        assert (await write(ctx, CONTROL_ADDR, control_word("kalman", reset=True)))[4:] == (0, 1)
        # read-back: the address to the read port now, the word (r_data) the next cycle
        for addr, word in ((0x33, 777), (CONTROL_ADDR, None)):
            ctx.set(dut.cfg_read.payload, addr)
            ctx.set(dut.cfg_read.valid, 1)
            assert ctx.get(dut.cfg_read.ready) and ctx.get(dut.r_en)
            assert ctx.get(dut.r_addr) == addr
            await ctx.tick()
            ctx.set(dut.cfg_read.valid, 0)
            # the register file's word at CONTROL_ADDR is never written: it reads 0
            ctx.set(dut.r_data, 777 if addr != CONTROL_ADDR else 0)
            assert not ctx.get(dut.cfg_read.ready)          # one read outstanding at a time
            await ctx.tick()
            assert ctx.get(dut.cfg_read_data.valid)
            seen[addr] = ctx.get(dut.cfg_read_data.payload)
            ctx.set(dut.cfg_read_data.ready, 1)
            await ctx.tick()
            ctx.set(dut.cfg_read_data.ready, 0)
            assert not ctx.get(dut.cfg_read_data.valid)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.cfg_read_data, "cfg_read_data")
    sim.add_testbench(testbench)
    sim.run()
    assert seen == {0x33: 777, CONTROL_ADDR: FILTER_CODES["kalman"]}


def test_read_only_and_state_registers_refuse_writes():
    """With the engine's ``HOST_WRITABLE``, a write to a constant (ZERO, INV_GAIN, SHL8) or to
    filter state (0x20 up) is taken, writes nothing, and is counted; run-time registers and
    CONTROL are written as before."""
    from mpu9250_ahrs.hdl.engine.register_map import CONFIG_REGS, HOST_WRITABLE, REGS
    dut = HostPort(filter_at_reset=FILTER_CODES["flagship"], writable=HOST_WRITABLE)
    refused = [CONFIG_REGS["ZERO"], CONFIG_REGS["INV_GAIN"], CONFIG_REGS["SHL8"],
               REGS["P0_00"], REGS["THETA0"], 0x20, 0xFD]
    allowed = [CONFIG_REGS["R"], CONFIG_REGS["K_REST"], CONFIG_REGS["TELEMETRY_DIV"]]
    log = []

    async def testbench(ctx):
        ctx.set(dut.open, 1)
        for addr in refused + allowed:
            ctx.set(dut.cfg.payload, {"addr": addr, "data": 5})
            ctx.set(dut.cfg.valid, 1)
            log.append((addr, ctx.get(dut.cfg.ready), ctx.get(dut.w_en)))
            await ctx.tick()
        ctx.set(dut.cfg.valid, 0)
        log.append(("refused", ctx.get(dut.refused)))
        ctx.set(dut.cfg.payload, {"addr": CONTROL_ADDR, "data": control_word("kalman")})
        ctx.set(dut.cfg.valid, 1)
        await ctx.tick()
        log.append(("select", ctx.get(dut.select)))
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.cfg_read_data, "cfg_read_data")
    sim.add_testbench(testbench)
    sim.run()
    assert log[:len(refused)] == [(a, 1, 0) for a in refused]
    assert log[len(refused):len(refused) + len(allowed)] == [(a, 1, 1) for a in allowed]
    assert log[-2:] == [("refused", len(refused)), ("select", FILTER_CODES["kalman"])]


def test_control_words_against_the_contract():
    """Issue #25: every CONTROL word with bits 31:4 clear, and some with reserved bits set,
    against ``numeric_contract.control_fields`` (the reference's rule): the select, the
    reset pulse and the refusal count agree for each. A code that names no filter without keep
    is refused (with four filters there is none: code 3 is Madgwick)."""
    from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_NAMES
    from mpu9250_ahrs.hdl.contract.numeric_contract import control_fields
    words = list(range(16)) + [0x10, 0x13, 0x8000_0000, -1, -16, 0x7FFF_FFF0 | 0x2]
    dut = HostPort(filter_at_reset=FILTER_CODES["flagship"])
    got = []

    async def testbench(ctx):
        ctx.set(dut.open, 1)
        for word in words:
            before = ctx.get(dut.select), ctx.get(dut.refused)
            ctx.set(dut.cfg.payload, {"addr": CONTROL_ADDR, "data": word})
            ctx.set(dut.cfg.valid, 1)
            reset = ctx.get(dut.reset)
            await ctx.tick()
            ctx.set(dut.cfg.valid, 0)
            got.append((word, before[0], ctx.get(dut.select), reset,
                        ctx.get(dut.refused) - before[1]))
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()
    for word, before, after, reset, refused in got:
        fields = control_fields(word, len(FILTER_NAMES))
        if fields is None:
            assert (after, reset, refused) == (before, 0, 1), hex(word)
        else:
            code, want_reset = fields
            assert after == (before if code is None else code), hex(word)
            assert (reset, refused) == (want_reset, 0), hex(word)
    assert control_fields(3, 3) is None and control_fields(3, len(FILTER_NAMES)) == (3, False)
