"""BringUpSequencer against a register-port model: the program's commands in order, what a
failed check does, a restart asked for, and the magnetometer's part run again."""

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.contract import ak8963_regs as A
from mpu9250_ahrs.hdl.contract import mpu9250_regs as R
from mpu9250_ahrs.hdl.sensor.bring_up_sequencer import (BringUpSequencer, Op, SelfTestWaits,
                                                        bring_up_program)
from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
from mpu9250_ahrs.sim.bench.streams import check_stream_rules

from .register_port_model import RegisterPortModel
from .test_mpu9250_driver import expected_writes


class Chip:
    """The MPU9250 with an AK8963 behind SLV4, as far as bring-up sees them."""
    def __init__(self, who_am_i=0x71, wia=A.WIA_VALUE):
        self.who_am_i, self.wia, self.slv4_reg = who_am_i, wia, None

    def answer(self, device, reg, length):
        if reg == R.WHO_AM_I:
            return [self.who_am_i]
        if reg == R.I2C_MST_STATUS:
            return [R.I2C_MST_STATUS_SLV4_DONE]
        if reg == R.I2C_SLV4_DI:
            return [self.wia if self.slv4_reg == A.WIA else 0x80 + self.slv4_reg - A.ASAX]
        return [0]


def make(config=MPU9250Config()):
    program = bring_up_program(config, 3, 3, 2, SelfTestWaits(settle=3, interval=2, mag=2))
    # the magnetometer's part, the one run again, starts with SLV4 disabled (a transfer left
    # enabled by a set-up that timed out is dropped), then the I2C master's USER_CTRL
    first = next(s for s in program if s.mag)
    assert (first.reg, first.value) == (R.I2C_SLV4_CTRL, 0x00)
    return BringUpSequencer(program, accepted_who_am_i=config.accepted_who_am_i,
                            poll_cycles=50)


def run(dut, chip, body):
    model = RegisterPortModel(dut.port, chip.answer)
    orig = model.cycle

    async def cycle(ctx):
        await orig(ctx)
        if model.writes and model.writes[-1][1] == R.I2C_SLV4_REG:
            chip.slv4_reg = model.writes[-1][2]
    model.cycle = cycle

    async def testbench(ctx):
        await body(ctx, model)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    check_stream_rules(sim, dut.port.cmd, "commands")
    sim.run()
    return model


def test_program_restart_and_magnetometer_again():
    config = MPU9250Config()
    dut = make(config)
    seen = {}
    writes = expected_writes(config)
    mag_part = writes[writes.index((0x34, 0x00)):-2]    # from SLV4 off to SLV0

    async def body(ctx, model):
        pulses = []

        async def watch(n):
            for _ in range(n):
                await model.cycle(ctx)
                pulses.append((ctx.get(dut.started), ctx.get(dut.restarted)))
        await model.until(ctx, lambda: ctx.get(dut.streaming))
        seen["writes"] = [(r, v) for _, r, v in model.writes]
        seen["status"] = (ctx.get(dut.mag_ok), ctx.get(dut.who_am_i), ctx.get(dut.restarts),
                          [ctx.get(dut.asa[i]) for i in range(3)])
        # the magnetometer's part again: mag_ok drops at once, the part runs, samples go on
        model.writes.clear()
        ctx.set(dut.mag_lost, 1)
        await model.cycle(ctx)
        ctx.set(dut.mag_lost, 0)
        seen["during"] = (ctx.get(dut.mag_ok), ctx.get(dut.mag_setup), ctx.get(dut.streaming))
        await model.until(ctx, lambda: not ctx.get(dut.mag_setup))
        seen["again"] = [(r, v) for _, r, v in model.writes]
        seen["after"] = (ctx.get(dut.mag_ok), ctx.get(dut.streaming), ctx.get(dut.restarts))
        # a restart asked for: from the start, counted
        model.writes.clear()
        ctx.set(dut.restart, 1)
        await watch(1)
        ctx.set(dut.restart, 0)
        await watch(3)
        seen["restarting"] = (ctx.get(dut.streaming), ctx.get(dut.restarts))
        while not ctx.get(dut.streaming):
            await watch(1)
        seen["pulses"] = (sum(p[0] for p in pulses), sum(p[1] for p in pulses))
        seen["rewrites"] = [(r, v) for _, r, v in model.writes]
    run(dut, Chip(), body)
    assert seen["writes"] == expected_writes(config)
    assert seen["status"] == (1, 0x71, 0, [0x80, 0x81, 0x82])
    assert seen["during"] == (0, 1, 1)
    # the magnetometer's part alone: the INT set-up after it is bring-up's (an MPU9250 reset
    # meanwhile leaves INT off, for the reader's time-out to find)
    assert seen["again"] == mag_part
    assert seen["after"] == (1, 1, 0)
    assert seen["restarting"] == (0, 1)
    assert seen["pulses"] == (1, 1)
    assert seen["rewrites"] == expected_writes(config)


def test_wrong_who_am_i_restarts_and_wrong_wia_skips_the_magnetometer():
    dut = make()
    seen = {}

    async def body(ctx, model):
        await model.until(ctx, lambda: ctx.get(dut.restarts) >= 2)
        seen["bad"] = (ctx.get(dut.whoami_error), ctx.get(dut.who_am_i), ctx.get(dut.streaming))
    run(dut, Chip(who_am_i=0x68), body)
    assert seen["bad"] == (1, 0x68, 0)

    dut = make()

    async def body2(ctx, model):
        await model.until(ctx, lambda: ctx.get(dut.streaming))
        seen["wia"] = (ctx.get(dut.mag_ok), ctx.get(dut.mag_wia_error), ctx.get(dut.mag_absent),
                       ctx.get(dut.restarts))
    run(dut, Chip(wia=0x00), body2)
    assert seen["wia"] == (0, 1, 0, 0)


def test_waits_counted_in_ticks_last_their_cycles():
    """With ``tick_cycles`` > 1 the timer counts ticks (a pulse every so many cycles, at any
    phase): a WAIT lasts at least its cycles and at most two ticks more than counted in
    cycles (``tick_cycles`` 1, exact)."""
    from mpu9250_ahrs.hdl.sensor.bring_up_sequencer import Op, Step
    wait = 37

    def streaming_after(tick_cycles, phase=0):
        program = [Step(Op.WAIT, wait=wait), Step(Op.CHECK, reg=R.WHO_AM_I, check="who_am_i"),
                   Step(Op.STREAM)]
        dut = BringUpSequencer(program, accepted_who_am_i=(0x71,), poll_cycles=50,
                               tick_cycles=tick_cycles)
        seen = []

        async def body(ctx, model):
            for cycle in range(200):
                ctx.set(dut.tick, (cycle + phase) % tick_cycles == 0)
                if ctx.get(dut.streaming):
                    seen.append(cycle)
                    return
                await model.cycle(ctx)
        run(dut, Chip(), body)
        return seen[0]

    exact = streaming_after(1)
    for phase in range(4):
        assert exact <= streaming_after(4, phase) <= exact + 2 * 4


@pytest.mark.parametrize("odr", [1000, 8000])
def test_magnetometer_transfers_keep_slv0_pacing(odr):
    """Every SLV4 transfer writes SLV4_CTRL with I2C_MST_DLY, the pacing of SLV0's reads above
    1 kHz (every ``aux_every``-th sample). At 8 kHz a set-up again while streaming cleared it:
    SLV0's reads then ran at every sample, each SLV4 transfer outlasted its poll, and a
    magnetometer lost, reset or stale never came back (``tests/sim/test_faults.py``)."""
    config = MPU9250Config.for_odr(odr)
    program = bring_up_program(config, 3, 3, 2, SelfTestWaits(settle=3, interval=2, mag=2))
    ctrl = [s.value for s in program if s.op == Op.WRITE and s.reg == R.I2C_SLV4_CTRL]
    assert len(ctrl) > 5
    assert all(v & R.I2C_SLV4_MST_DLY == config.aux_every - 1 for v in ctrl)
