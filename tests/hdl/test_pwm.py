"""PWM outputs: servo and motor timing, range checks, updates at period boundaries, low at
reset and while disabled, the command watchdog."""

from amaranth.sim import Simulator
from hypothesis import example, given, settings, strategies as st

from mpu9250_ahrs.hdl.contract.pwm_regs import PWM_REGS
from mpu9250_ahrs.hdl.link.pwm import PWMOutputs

CLK = 4e6          # 4 cycles a µs; the motor period's minimum is 200 cycles (20 kHz)


async def read(ctx, dut, name):
    """A register's read-back: the bus's reads are registered (a word the cycle after its
    address, ``BoardBusSignature``)."""
    ctx.set(dut.bus.addr, PWM_REGS[name])
    await ctx.tick()
    return ctx.get(dut.bus.r_data)


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
        out["status"] = await read(ctx, dut, "PWM_STATUS")
        ctx.set(dut.kick, 1)                                       # the host is back: a
        await write("PWM_ENABLE", 0b0100)                         # command (it kicks too)
        ctx.set(dut.kick, 0)
        out["again"] = ctx.get(dut.tripped), len((await edges(2, 800))[0])
    out = bench(body)
    assert out["kept"] == (0, 2) and out["tripped"] == (1, 0)
    assert out["status"] & 1 == 1 and out["again"] == (0, 2)


def test_a_mode_change_drops_the_high_time():
    """The case of issue #25: a servo high time of 1,500 µs, the channel switched to motor
    mode and enabled. The 1,500 is not read as cycles (longer than the motor period: 100 %
    duty); the channel's high time is 0 after the change, so it stays low until a high time
    is written in its new unit."""
    async def body(ctx, dut, write, edges, out):
        assert await write("PWM_HIGH0", 1_500)
        assert await write("PWM_MODE", 1)
        out["high"] = await read(ctx, dut, "PWM_HIGH0")
        assert await write("PWM_ENABLE", 1)
        out["level"] = await edges(0, 1_000)
        assert await write("PWM_HIGH0", 50)                       # 25 % of the 200 cycles
        rises, falls = await edges(0, 1_000)
        out["pulses"] = [f - r for r, f in zip(rises, falls)]
    out = bench(body)
    assert out["high"] == 0 and out["level"] == ([], [])
    assert out["pulses"] and set(out["pulses"]) == {50}


def test_a_new_period_drops_the_groups_high_times():
    """A period written under a high time of its group (enabled or not) would hold that
    output high for the whole period: a new period sets the group's high times to 0 (write
    the period first); the other group keeps its own."""
    async def body(ctx, dut, write, edges, out):
        await write("PWM_HIGH0", 3_000)                           # servo, disabled
        await write("PWM_MODE", 0b10)
        await write("PWM_MOTOR_PERIOD", 1_000)
        await write("PWM_HIGH1", 800)
        assert await write("PWM_SERVO_PERIOD", 2_500)
        highs = []
        for k in range(2):
            highs.append(await read(ctx, dut, f"PWM_HIGH{k}"))
        out["after_servo"] = highs
        assert await write("PWM_MOTOR_PERIOD", 700)
        out["after_motor"] = await read(ctx, dut, "PWM_HIGH1")
    out = bench(body)
    assert out["after_servo"] == [0, 800] and out["after_motor"] == 0


# values around the edges of the ranges at CLK_PROP (one cycle a µs: a servo period of 2,500
# cycles at the least, a motor one of 50)
CLK_PROP = 1e6
_VALUES = {"PWM_SERVO_PERIOD": (2_500, 2_600, 3_000),
           "PWM_MOTOR_PERIOD": (50, 60, 100, 2_600),
           "PWM_MODE": tuple(range(16)), "PWM_ENABLE": tuple(range(16)),
           "PWM_WATCHDOG_MS": (0,),
           **{f"PWM_HIGH{k}": (0, 1, 49, 50, 60, 100, 1_500, 2_500, 2_600, 3_000)
              for k in range(4)}}


def _op(name, value):
    return name, _VALUES[name].index(value)


@settings(max_examples=20, deadline=None)
# the two ways today's checks let through: a high time read in the other unit, a period
# shrunk under a high time
@example([_op("PWM_HIGH0", 1_500), _op("PWM_MODE", 1), _op("PWM_ENABLE", 1), ("wait", 300)])
@example([_op("PWM_SERVO_PERIOD", 3_000), _op("PWM_HIGH2", 3_000), _op("PWM_HIGH2", 2_600),
          _op("PWM_SERVO_PERIOD", 2_500), _op("PWM_ENABLE", 4), ("wait", 3_200),
          ("wait", 3_200)])
# a period shorter than a pulse under way, written during it: the pulse ends in the frame of
# the old period (2,600 of 20,000 µs), and none follows (the high time was dropped)
@example([_op("PWM_HIGH3", 2_600), _op("PWM_ENABLE", 8), _op("PWM_SERVO_PERIOD", 2_500),
          ("wait", 2_500), ("wait", 3_200)])
@given(st.lists(st.one_of(st.tuples(st.sampled_from(sorted(_VALUES)), st.integers(0, 99)),
                          st.tuples(st.just("wait"), st.integers(1, 3_200))),
                min_size=4, max_size=14))
def test_no_output_high_for_a_whole_period_unless_asked(ops):
    """Random register sequences: no output is ever high for a whole period of its group
    unless that channel was given a high time equal to the period in its own unit (written
    while in its present mode and period). A model mirrors the accepted writes; a mode or
    period change leaves nothing asked."""
    dut = PWMOutputs(clk_freq=CLK_PROP)
    sim = Simulator(dut)
    sim.add_clock(1 / CLK_PROP)
    failures = []

    async def tb(ctx):
        period = [20_000, dut.motor_min]
        mode, asked = 0, [0] * 4
        run = [0] * 4                 # cycles high in a row
        full = [False] * 4            # 100 % was asked during that run
        shortest = [None] * 4         # the shortest group period (cycles) during the run

        def group(k):
            return (mode >> k) & 1

        def note_asked(channels=range(4)):
            for k in channels:
                p = period[group(k)]
                full[k] |= asked[k] == p
                shortest[k] = p if shortest[k] is None else min(shortest[k], p)

        def note_period(g, old):
            """A period written for group ``g`` takes effect at its next wrap: a frame under
            way, or one that starts in the write's own cycle, keeps the ``old`` one (and the
            new period drops the group's high times, so an output falls at the next wrap
            at the latest)."""
            for k in range(4):
                if group(k) == g:
                    asked[k] = 0                  # a duty of the old period: dropped
                    if not run[k]:
                        shortest[k] = old if shortest[k] is None else min(shortest[k], old)
                else:
                    note_asked([k])

        async def step(cycles):
            for _ in range(cycles):
                _, _, level = await ctx.tick().sample(dut.pwm)
                for k in range(4):
                    if (level >> k) & 1:
                        run[k] += 1
                        if run[k] >= shortest[k] and not full[k]:
                            failures.append((k, run[k], shortest[k], asked[k]))
                            return
                    else:
                        run[k], full[k], shortest[k] = 0, False, None
                        note_asked([k])

        note_asked()
        for name, x in ops:
            if name == "wait":
                await step(x)
            else:
                values = _VALUES[name]
                value = values[x % len(values)]
                ctx.set(dut.bus.addr, PWM_REGS[name])
                ctx.set(dut.bus.w_data, value)
                ok = ctx.get(dut.bus.ok)
                ctx.set(dut.bus.w_en, 1)
                await step(1)
                ctx.set(dut.bus.w_en, 0)
                if ok:
                    if name == "PWM_MODE":
                        for k in range(4):
                            if (value ^ mode) >> k & 1:
                                asked[k] = 0          # nothing asked in the new unit yet
                        mode = value
                    elif name.startswith("PWM_HIGH"):
                        asked[int(name[-1])] = value
                    if name in ("PWM_SERVO_PERIOD", "PWM_MOTOR_PERIOD"):
                        g = int(name == "PWM_MOTOR_PERIOD")
                        old, period[g] = period[g], value
                        note_period(g, old)
                    else:
                        note_asked()
            if failures:
                return
    sim.add_testbench(tb)
    sim.run()
    assert not failures, failures


def test_an_asynchronous_reset_drops_the_outputs_at_once():
    """As a board builds it (``hdl/board/top.py``: the core's domain has an asynchronous reset), a
    reset takes every output low at once, before any clock edge, and they stay low after it
    (every channel disabled at reset). The registers read their reset values after it, though
    the read-back's block RAM kept the words written before."""
    from amaranth import ClockDomain, Elaboratable, Module

    class InAsyncReset(Elaboratable):
        def __init__(self, dut):
            self.dut = dut
            self.domain = ClockDomain("sync", async_reset=True)

        def elaborate(self, platform):
            m = Module()
            m.domains += self.domain
            m.submodules.dut = self.dut
            return m

    dut = PWMOutputs(clk_freq=CLK)
    top = InAsyncReset(dut)
    sim = Simulator(top)
    sim.add_clock(1 / CLK)
    out = {}

    async def tb(ctx):
        for name, value in (("PWM_MODE", 0b1111), ("PWM_MOTOR_PERIOD", 400),
                            ("PWM_SERVO_PERIOD", 2_500), ("PWM_WATCHDOG_MS", 7),
                            *((f"PWM_HIGH{k}", 400) for k in range(4)),   # high all period
                            ("PWM_ENABLE", 0b1111)):
            ctx.set(dut.bus.addr, PWM_REGS[name])
            ctx.set(dut.bus.w_data, value)
            ctx.set(dut.bus.w_en, 1)
            await ctx.tick()
        ctx.set(dut.bus.w_en, 0)
        await ctx.tick().repeat(1_000)
        out["running"] = ctx.get(dut.pwm)
        await ctx.delay(0.1 / CLK)                 # between clock edges
        ctx.set(top.domain.rst, 1)
        await ctx.delay(0.1 / CLK)                 # still no edge since
        out["in_reset"] = ctx.get(dut.pwm)
        await ctx.delay(3 / CLK)                   # three clock periods in reset
        ctx.set(top.domain.rst, 0)
        await ctx.tick().repeat(1_000)
        out["after"] = ctx.get(dut.pwm)
        out["enable"] = await read(ctx, dut, "PWM_ENABLE")
        out["read"] = {name: await read(ctx, dut, name) for name in (
            "PWM_MODE", "PWM_MOTOR_PERIOD", "PWM_SERVO_PERIOD", "PWM_WATCHDOG_MS", "PWM_HIGH0")}
    sim.add_testbench(tb)
    sim.run()
    assert out["running"] == 0b1111
    assert out["in_reset"] == 0 and out["after"] == 0 and out["enable"] == 0
    assert out["read"] == {"PWM_MODE": 0, "PWM_MOTOR_PERIOD": dut.motor_min,
                           "PWM_SERVO_PERIOD": 20_000, "PWM_WATCHDOG_MS": 500, "PWM_HIGH0": 0}
