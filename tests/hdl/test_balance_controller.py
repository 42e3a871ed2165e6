"""The balance controller against its fixed-point reference, bit for bit: random register
values (written through its bus, ranges checked), results, faults, sample periods, commands,
arming and disarming; every duty, the armed state and the last trip compared after each
event. And its safety: no output while disarmed, whatever the sequence."""

import random

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.contract.balance_regs import (BALANCE_REGS, BALANCE_WIDTHS, CONTROL_BITS,
                                                    TRIPS)
from mpu9250_ahrs.hdl.control.balance_controller import BalanceController
from mpu9250_ahrs.reference.balance_control import BalanceFixed, BalanceFixedConfig
from mpu9250_ahrs.reference.fixed_point import wrap32

FIELDS = {"BAL_KP": "kp", "BAL_KD": "kd", "BAL_KI": "ki", "BAL_KV": "kv",
          "BAL_SETPOINT": "setpoint", "BAL_CUTOFF": "cutoff", "BAL_OUT_LIMIT": "out_limit",
          "BAL_I_LIMIT": "i_limit", "BAL_STALE": "stale", "BAL_WATCHDOG": "watchdog"}


async def _write(ctx, dut, name, value):
    """A bus write; returns whether the block took it (``ok``)."""
    bus = dut.bus
    ctx.set(bus.addr, BALANCE_REGS[name])
    ctx.set(bus.w_data, value & 0xFFFFFFFF)
    ctx.set(bus.w_en, 1)
    ok = ctx.get(bus.ok)
    await ctx.tick()
    ctx.set(bus.w_en, 0)
    return ok


async def _read(ctx, dut, name):
    ctx.set(dut.bus.addr, BALANCE_REGS[name])
    await ctx.tick()
    return ctx.get(dut.bus.r_data)


async def _pulse(ctx, signal):
    ctx.set(signal, 1)
    await ctx.tick()
    ctx.set(signal, 0)


def _value(rng, name):
    bits, is_signed, low, high = BALANCE_WIDTHS[name]
    if name in ("BAL_KP", "BAL_KD", "BAL_KI", "BAL_KV") and rng.random() < 0.7:
        return rng.randint(-600, 600)                   # gains a robot would use
    if name == "BAL_CUTOFF" and rng.random() < 0.8:
        return rng.randint(1000, 8000)
    if name in ("BAL_I_LIMIT", "BAL_OUT_LIMIT") and rng.random() < 0.6:
        return rng.randint(0, 3000 if name == "BAL_I_LIMIT" else 200)    # limits reached
    if name == "BAL_STALE":
        return rng.randint(1, 6)
    if name == "BAL_WATCHDOG":
        return rng.choice([0, 1, 2, 3, rng.randint(4, 8)])
    return rng.randint(low, high)


def _run(seed, events=1200):
    rng = random.Random(seed)
    dut = BalanceController(clk_freq=4e6)
    ref = BalanceFixed(BalanceFixedConfig(kv_shift=dut.kv_shift, stale=5, watchdog=500))
    checked = {"steps": 0, "trips": set(), "refused": 0, "integral_held": 0, "duty_limited": 0}

    async def bench(ctx):
        control = 0
        for _ in range(events):
            kind = rng.random()
            if kind < 0.15:                             # a register, in range or not
                name = rng.choice(list(FIELDS))
                value = _value(rng, name)
                if rng.random() < 0.1:
                    value = BALANCE_WIDTHS[name][3] + rng.randint(1, 100)
                    checked["refused"] += 1
                    assert not await _write(ctx, dut, name, value)
                    continue
                assert await _write(ctx, dut, name, value)
                ref.write(**{FIELDS[name]: value})
            elif kind < 0.22:                           # arm, disarm, the axis
                control = rng.randrange(8)
                assert await _write(ctx, dut, "BAL_CONTROL", control)
                if control & 1:
                    ref.arm(by_host=True)
                else:
                    ref.disarm()
            elif kind < 0.32:                           # sample periods, a few in a row
                for _ in range(rng.choice([1, 1, 2, 4, 8])):
                    await _pulse(ctx, dut.period)
                    await ctx.tick()                    # the count, then the trip
                    ref.period()
                    assert ctx.get(dut.armed) == ref.armed
            elif kind < 0.36:
                await _pulse(ctx, dut.kick)
                ref.kick()
            else:                                       # a sample, then its result
                axis = 0 if control >> CONTROL_BITS["roll"] & 1 else 1
                gyro = [rng.randint(-32768, 32767) for _ in range(2)]
                ctx.set(dut.gyro, gyro)
                await _pulse(ctx, dut.sample_taken)
                cutoff = ref.config.cutoff
                e = rng.randint(-cutoff - 200, cutoff + 200) if rng.random() < 0.95 else \
                    rng.randint(-32768, 32767)
                angles = [((ref.config.setpoint + e) << 16) + rng.randrange(1 << 16)
                          for _ in range(2)]
                angles = [((a + (1 << 31)) & 0xFFFFFFFF) - (1 << 31) for a in angles]
                bias = [rng.randint(-1 << 31, (1 << 31) - 1) if rng.random() < 0.2 else
                        rng.randint(-1 << 22, 1 << 22) for _ in range(2)]
                fault = rng.random() < 0.03
                ctx.set(dut.angles, angles)
                ctx.set(dut.bias, bias)
                ctx.set(dut.fault, fault)
                await _pulse(ctx, dut.done)
                ctx.set(dut.fault, 0)
                await ctx.tick().repeat(10)
                held = ref.integral
                expected = ref.step(angles[axis], gyro[axis], bias[axis], fault)
                checked["steps"] += 1
                if ref.armed and ref.integral == held and \
                        abs(held + (wrap32(angles[axis] - (ref.config.setpoint << 16)) >> 16)) > \
                        ref.config.i_limit:
                    checked["integral_held"] += 1
                if ref.armed and expected and abs(expected) == ref.config.out_limit:
                    checked["duty_limited"] += 1
                assert ctx.get(dut.duty) == expected == ref.duty, checked["steps"]
            assert ctx.get(dut.armed) == ref.armed
            if not ref.armed:
                assert ctx.get(dut.pwm) == 0
            status = await _read(ctx, dut, "BAL_STATUS")
            trip = [TRIPS[k] for k in range(len(TRIPS)) if status >> (4 + k) & 1]
            assert trip == ([ref.tripped] if ref.tripped else []), (trip, ref.tripped)
            if ref.tripped:
                checked["trips"].add(ref.tripped)

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    return checked


@pytest.mark.parametrize("seed", [0, 1, 3])      # seeds whose runs reach every trip
def test_matches_the_reference_bit_for_bit(seed):
    checked = _run(seed)
    assert checked["steps"] > 150 and checked["refused"] > 0
    assert checked["trips"] == set(TRIPS), checked
    assert checked["integral_held"] > 0 and checked["duty_limited"] > 0, checked


def test_pwm_follows_the_duty_and_is_low_disarmed():
    """Armed with a duty of +300/1024: channels 0 and 2 high for 300 of 1024 steps, 1 and 3
    low; disarmed by a command: all low in the cycle after."""
    dut = BalanceController(clk_freq=4e6, reset={"BAL_KP": 1 << 16, "BAL_OUT_LIMIT": 300,
                                                "BAL_CUTOFF": 30000})
    seen = {}

    async def bench(ctx):
        assert await _write(ctx, dut, "BAL_CONTROL", 1)
        ctx.set(dut.angles, [0, 5000 << 16])
        await _pulse(ctx, dut.done)
        await ctx.tick().repeat(10)
        assert ctx.get(dut.duty) == 300
        highs = [0] * 4
        for _ in range(1024 * dut.prescale):
            await ctx.tick()
            for k in range(4):
                highs[k] += ctx.get(dut.pwm) >> k & 1
        seen["highs"] = [h // dut.prescale for h in highs]
        assert await _write(ctx, dut, "BAL_CONTROL", 0)
        seen["after"] = max(ctx.get(dut.pwm) for _ in range(1) if True)
        for _ in range(2048):
            await ctx.tick()
            assert ctx.get(dut.pwm) == 0

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    assert seen["highs"] == [300, 0, 300, 0] and seen["after"] == 0


def test_registers_read_back_and_reset():
    """Each register reads back what was written (a signed one sign-extended to 32 bits, from
    the shadow RAM); after a reset, its reset value again, though the RAM kept the write."""
    from amaranth.hdl import Module, ResetInserter, Signal
    reset = {"BAL_KP": -300, "BAL_OUT_LIMIT": 700, "BAL_STALE": 5}
    dut = BalanceController(clk_freq=4e6, reset=reset)
    do_reset = Signal()
    top = Module()
    top.submodules.dut = ResetInserter(do_reset)(dut)
    rng = random.Random(5)
    seen = {}

    async def bench(ctx):
        for name in FIELDS:
            seen[("before", name)] = await _read(ctx, dut, name)
        for name in FIELDS:
            value = _value(rng, name)
            assert await _write(ctx, dut, name, value)
            seen[("wrote", name)] = value & 0xFFFFFFFF
            seen[("after", name)] = await _read(ctx, dut, name)
        ctx.set(do_reset, 1)
        await ctx.tick()
        ctx.set(do_reset, 0)
        for name in FIELDS:
            seen[("reset", name)] = await _read(ctx, dut, name)

    sim = Simulator(top)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    expected = {**{name: 0 for name in FIELDS}, "BAL_WATCHDOG": 500,
                **{name: v & 0xFFFFFFFF for name, v in reset.items()}}
    for name in FIELDS:
        assert seen[("before", name)] == expected[name], name
        assert seen[("after", name)] == seen[("wrote", name)], name
        assert seen[("reset", name)] == expected[name], name


def test_the_command_channel_reaches_its_registers():
    """Space 0x03 through the command decoder's executor: a gain written and read back, a
    value out of range refused, a read-only register refused."""
    from amaranth.hdl import Module
    from amaranth.lib import wiring
    from mpu9250_ahrs.hdl.contract.commands import RESULTS
    from mpu9250_ahrs.hdl.engine.register_map import HOST_WRITABLE
    from mpu9250_ahrs.hdl.link.command_decoder import CommandDecoder
    from mpu9250_ahrs.host.protocol import encode_command, to_python
    dec = CommandDecoder(writable=HOST_WRITABLE, version=1, timeout=200)
    dut = BalanceController(clk_freq=4e6)
    top = Module()
    top.submodules.dec, top.submodules.dut = dec, dut
    wiring.connect(top, dec.control, dut.bus)
    commands = [("write", BALANCE_REGS["BAL_KP"], -7), ("read", BALANCE_REGS["BAL_KP"], None),
                ("write", BALANCE_REGS["BAL_STALE"], 0), ("write", BALANCE_REGS["BAL_DUTY"], 1)]
    replies = []

    async def bench(ctx):
        ctx.set(dec.replies.ready, 1)
        for k, (name, addr, value) in enumerate(commands):
            for byte in encode_command(name, k, addr=addr, value=value, space="control"):
                ctx.set(dec.i_stream.valid, 1)
                ctx.set(dec.i_stream.payload, byte)
                await ctx.tick().until(dec.i_stream.ready)
            ctx.set(dec.i_stream.valid, 0)
            while not ctx.get(dec.replies.valid):
                await ctx.tick()
            replies.append(to_python(ctx.get(dec.replies.payload)))
            await ctx.tick()

    sim = Simulator(top)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    assert [r["result"] for r in replies] == [RESULTS["ok"], RESULTS["ok"], RESULTS["refused"],
                                              RESULTS["refused"]]
    assert replies[1]["value"] == (-7) & 0xFFFFFFFF
    assert replies[0]["addr"] == 0x0300 | BALANCE_REGS["BAL_KP"]
