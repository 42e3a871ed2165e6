"""PWM outputs: servo and motor timing, range checks, updates at period boundaries, low at
reset and while disabled, the command watchdog."""

from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.pwm import PWM_REGS, PWMOutputs

CLK = 4e6          # 4 cycles a µs; the motor period's minimum is 200 cycles (20 kHz)


def bench(body):
    dut = PWMOutputs(clk_freq=CLK)
    sim = Simulator(dut)
    sim.add_clock(1 / CLK)
    out = {}

    async def tb(ctx):
        async def write(name, value):
            ctx.set(dut.bus.addr, PWM_REGS[name])
            ctx.set(dut.bus.w_data, value)
            ok = ctx.get(dut.bus.ok)
            ctx.set(dut.bus.w_en, 1)
            await ctx.tick()
            ctx.set(dut.bus.w_en, 0)
            return ok

        async def edges(channel, cycles):
            """(rising edge cycles, falling edge cycles) of one output over ``cycles``."""
            rises, falls, prev = [], [], 0
            for k in range(cycles):
                _, _, level = await ctx.tick().sample(dut.pwm)
                level = (level >> channel) & 1
                if level and not prev:
                    rises.append(k)
                if prev and not level:
                    falls.append(k)
                prev = level
            return rises, falls
        await body(ctx, dut, write, edges, out)
    sim.add_testbench(tb)
    sim.run()
    return out


def test_servo_and_motor_timing_and_low_until_enabled():
    async def body(ctx, dut, write, edges, out):
        out["reset"] = (await edges(0, 50))[0]
        assert await write("PWM_SERVO_PERIOD", 2_500)             # 400 Hz frame
        assert await write("PWM_HIGH0", 1_500)                    # 1.5 ms
        assert await write("PWM_MODE", 0b0010)                    # channel 1: motor
        assert await write("PWM_MOTOR_PERIOD", 400)               # 10 kHz
        assert await write("PWM_HIGH1", 100)                      # 25 %
        out["disabled"] = (await edges(0, 100))[0]
        assert await write("PWM_ENABLE", 0b0011)
        out["servo"] = await edges(0, 3 * 10_000)
        out["motor"] = await edges(1, 1_300)
    out = bench(body)
    assert out["reset"] == [] and out["disabled"] == []
    rises, falls = out["servo"]
    # a channel starts at its group's next period: every pulse, the first too, is whole
    assert [b - a for a, b in zip(rises, rises[1:])] == [10_000] * (len(rises) - 1)
    assert len(rises) >= 2 and all(f - r == 6_000 for r, f in zip(rises, falls))
    rises, falls = out["motor"]
    assert [b - a for a, b in zip(rises, rises[1:])] == [400] * (len(rises) - 1)
    assert all(f - r == 100 for r, f in zip(rises, falls))


def test_out_of_range_refused_and_updates_wait_for_the_period():
    async def body(ctx, dut, write, edges, out):
        out["refused"] = [await write("PWM_SERVO_PERIOD", 2_499),
                          await write("PWM_SERVO_PERIOD", 20_001),
                          await write("PWM_HIGH0", 20_001),        # above the period
                          await write("PWM_WATCHDOG_MS", 1 << 16)]
        await write("PWM_MODE", 1)
        out["motor_fast"] = await write("PWM_MOTOR_PERIOD", 199)   # above 20 kHz
        await write("PWM_MOTOR_PERIOD", 1_000)
        await write("PWM_HIGH0", 500)
        await write("PWM_ENABLE", 1)
        out["mode_locked"] = await write("PWM_MODE", 0)            # enabled: refused
        await edges(0, 1_200)
        await write("PWM_HIGH0", 200)                              # mid-period
        out["after"] = await edges(0, 2_500)
    out = bench(body)
    assert out["refused"] == [0, 0, 0, 0] and out["motor_fast"] == 0
    assert out["mode_locked"] == 0
    rises, falls = out["after"]
    widths = [f - r for r, f in zip(rises, falls)]
    # the pulse under way when the write came keeps its 500 cycles (its tail is seen here)
    assert widths[0] > 200 and widths[1:] == [200] * (len(widths) - 1), (widths, rises)


def test_watchdog_disables_outputs_when_the_host_goes_quiet():
    async def body(ctx, dut, write, edges, out):
        await write("PWM_MODE", 0b0100)
        await write("PWM_MOTOR_PERIOD", 400)
        await write("PWM_HIGH2", 200)
        await write("PWM_WATCHDOG_MS", 2)                          # 8,000 cycles
        await write("PWM_ENABLE", 0b0100)
        for _ in range(5):                                         # kicked: stays on
            ctx.set(dut.kick, 1)                                   # (the decoder kicks at
            await ctx.tick()                                       # every good command)
            ctx.set(dut.kick, 0)
            await ctx.tick().repeat(5_000)
        out["kept"] = ctx.get(dut.tripped), len((await edges(2, 800))[0])
        await ctx.tick().repeat(9_000)
        out["tripped"] = ctx.get(dut.tripped), len((await edges(2, 800))[0])
        ctx.set(dut.bus.addr, PWM_REGS["PWM_STATUS"])
        out["status"] = ctx.get(dut.bus.r_data)
        ctx.set(dut.kick, 1)                                       # the host is back: a
        await write("PWM_ENABLE", 0b0100)                         # command (it kicks too)
        ctx.set(dut.kick, 0)
        out["again"] = ctx.get(dut.tripped), len((await edges(2, 800))[0])
    out = bench(body)
    assert out["kept"] == (0, 2) and out["tripped"] == (1, 0)
    assert out["status"] & 1 == 1 and out["again"] == (0, 2)
