"""Testbench helpers for the engine's start/done units (CORDIC, divider)."""

from amaranth.sim import Simulator


__all__ = ["run_unit", "operate"]


def run_unit(dut, testbench):
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    sim.run()


async def operate(ctx, dut, **inputs):
    """Set the inputs, pulse ``start``, wait for ``done``."""
    for name, value in inputs.items():
        ctx.set(getattr(dut, name), value)
    ctx.set(dut.start, 1)
    await ctx.tick()
    ctx.set(dut.start, 0)
    await ctx.tick().until(dut.done)
