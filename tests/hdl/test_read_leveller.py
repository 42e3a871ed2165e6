"""The read leveller (issue #58) on the SPI register port and controller, against the MPU9250
model: it trains on parts whose eye is wide enough wherever their round trip puts it, and
stays at the safe rate on one whose edges spread too far."""

import pytest
from amaranth import Module
from amaranth.lib.wiring import connect
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.contract import mpu9250_regs as R
from mpu9250_ahrs.hdl.sensor.read_leveller import LEVEL_BYTES, ReadLeveller
from mpu9250_ahrs.hdl.sensor.register_port import SPIRegisterPort
from mpu9250_ahrs.hdl.sensor.spi_controller import SPIController, SPITiming
from mpu9250_ahrs.sim.bench.harness import CosimHarness, attach_mpu9250
from mpu9250_ahrs.sim.models.mpu9250_model import MPU9250Model, MPU9250Timing

CLK = 48e6
PATTERN = [0x71, 0xA5, 0x3C, 0x96, 0x0F, 0xE1]


def _level(part, pattern=PATTERN, drifts=()):
    """Runs one scan against a model of ``part``, then a check of its guard delays after each
    drift in ``drifts`` (s, the model's ``sdo_drift_s``); returns the leveller's outputs (and
    ``checks``: each check's ``check_failed``)."""
    timing = SPITiming.for_clock(CLK).with_trained(CLK)
    m = Module()
    m.submodules.leveller = leveller = ReadLeveller(max_sample_delay=timing.max_sample_delay)
    m.submodules.port = port = SPIRegisterPort()
    m.submodules.spi = spi = SPIController(timing)
    connect(m, leveller.port, port.port)
    connect(m, port.spi_o, spi.i_stream)
    connect(m, spi.o_stream, port.spi_i)
    m.d.comb += spi.sample_delay.eq(leveller.sample_delay)
    # asleep: the part does not sample, so the accelerometer's registers keep the pattern
    model = MPU9250Model(timing=part, sleep_after_reset=True)
    assert len(pattern) == LEVEL_BYTES
    model.regs[R.ACCEL_XOUT_H:R.ACCEL_XOUT_H + LEVEL_BYTES] = bytes(pattern)
    seen = {}

    async def bench(ctx):
        await ctx.tick().repeat(200)
        ctx.set(leveller.start, 1)
        await ctx.tick()
        ctx.set(leveller.start, 0)
        assert ctx.get(leveller.busy)
        await ctx.tick().until(leveller.done)
        for name in ("trained", "first", "last", "sample_delay", "busy", "centre"):
            seen[name] = ctx.get(getattr(leveller, name))
        seen["checks"] = []
        for drift in drifts:
            model.sdo_drift_s = drift
            ctx.set(leveller.check, 1)
            await ctx.tick()
            ctx.set(leveller.check, 0)
            assert ctx.get(leveller.busy)
            await ctx.tick().until(leveller.done)
            seen["checks"].append(ctx.get(leveller.check_failed))

    harness = CosimHarness(m, spi=spi.pins)     # the model on the pins as in the co-simulations
    sim = Simulator(harness)
    sim.add_clock(1 / CLK)
    attach_mpu9250(sim, model, harness, CLK)
    sim.add_testbench(bench)
    sim.run()
    assert model.violations == [], model.violations
    return seen


@pytest.mark.parametrize("sdo_ns,board_ns,window", [(15, 14, (0, 3)), (100, 14, (4, 7))])
def test_it_trains_in_the_middle_of_the_eye(sdo_ns, board_ns, window):
    part = MPU9250Timing(startup_s=1e-6, reset_s=1e-6, sdo_delay_s=sdo_ns * 1e-9,
                         board_delay_s=board_ns * 1e-9, sdo_jitter_s=2e-9)
    seen = _level(part)
    assert not seen["busy"] and seen["trained"], seen
    assert (seen["first"], seen["last"]) == window
    assert seen["centre"] == (window[0] + window[1]) // 2


def test_bytes_without_a_pattern_train_nothing():
    """A part whose accelerometer reads 0 (at rest on its side, or not sampling yet): a
    shifted read of zeros is zeros, so no tap proves anything: not trained."""
    part = MPU9250Timing(startup_s=1e-6, reset_s=1e-6, sdo_delay_s=15e-9)
    seen = _level(part, pattern=[0] * LEVEL_BYTES)
    assert not seen["trained"] and seen["first"] > seen["last"], seen


def test_it_stays_at_the_safe_rate_without_an_eye():
    """A part at 100 ns whose edges spread ±35 ns: no run of three delays reads right every
    time: not trained (and the delay chosen 0)."""
    part = MPU9250Timing(startup_s=1e-6, reset_s=1e-6, sdo_delay_s=65e-9, sdo_jitter_s=35e-9,
                         board_delay_s=14e-9)
    seen = _level(part)
    assert not seen["trained"] and seen["centre"] == 0, seen
    assert seen["last"] - seen["first"] + 1 < 3, seen


def test_the_guards_pass_until_the_eye_moves_by_the_margin():
    """The checks after training (``ReadLeveller.check``: one pair at each guard delay, a
    cycle either side of the centre): they pass where the part was trained and after a drift
    of less than the margin; a drift of two cycles (42 ns) either way puts a guard outside the
    eye, while the centre still reads right: the driver falls back before a bit is wrong."""
    part = MPU9250Timing(startup_s=1e-6, reset_s=1e-6, sdo_delay_s=50e-9,
                         board_delay_s=14e-9, sdo_jitter_s=2e-9)
    seen = _level(part, drifts=(0, 5e-9, 42e-9, 0, -42e-9))
    assert seen["trained"] and seen["centre"] == (seen["first"] + seen["last"]) // 2, seen
    assert seen["checks"] == [0, 0, 1, 0, 1], seen
