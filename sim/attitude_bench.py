"""Drive the attitude engine in Amaranth's simulator and compare it with the reference.

``run_engine`` feeds raw samples (and optional register writes before chosen samples) to an
``AttitudeEngine`` and returns its results and the cycles each update took;
``first_mismatch`` compares them with ``reference.fixed_point.attitude_fixed`` field by field
and describes the first difference (``None`` when all match).
"""

from contextlib import nullcontext
from dataclasses import dataclass, field

import numpy as np
from amaranth.sim import Simulator

from ..hdl.attitude_program import CONTROL_ADDR
from .streams import stream_put


__all__ = ["EngineRun", "run_engine", "first_mismatch", "control_word"]


@dataclass
class EngineRun:
    angles: np.ndarray
    bias: np.ndarray
    acc_used: np.ndarray
    mag_used: np.ndarray
    saturated: np.ndarray
    complementary: np.ndarray
    counter: np.ndarray
    cycles: list = field(default_factory=list)      # sample valid -> result valid, per sample


def control_word(complementary=False, reset=False):
    return int(bool(complementary)) | (int(bool(reset)) << 1)


def run_engine(dut, gyro, accel, mag_ak, mag_valid=None, *, asa=(128, 128, 128),
               writes=None, vcd=None, gtkw=None):
    """``writes``: {sample index: [(addr, value), ...]} applied (while idle) before that sample,
    e.g. ``(CONTROL_ADDR, control_word(complementary=True))``."""
    n = len(gyro)
    valid = np.ones(n, bool) if mag_valid is None else np.asarray(mag_valid, bool)
    writes = writes or {}
    rows = []
    cycles = []

    async def testbench(ctx):
        for i in range(3):
            ctx.set(dut.asa[i], int(asa[i]))
        for k in range(n):
            for addr, value in writes.get(k, ()):
                await stream_put(ctx, dut.cfg, {"addr": addr, "data": int(value)})
            ctx.set(dut.samples.payload, {
                "gyro": [int(v) for v in gyro[k]], "accel": [int(v) for v in accel[k]],
                "mag": [int(v) for v in mag_ak[k]], "temp": 0, "counter": k % 65536,
                "flags": {"mag_valid": int(valid[k]), "data_ready": 1}})
            ctx.set(dut.samples.valid, 1)
            # wait out a filter reset (or start-up) still running before counting
            while ctx.get(dut.busy):
                await ctx.tick()
            count = 0
            while not ctx.get(dut.samples.ready):
                await ctx.tick()
                count += 1
            await ctx.tick()
            count += 1
            ctx.set(dut.samples.valid, 0)
            while not ctx.get(dut.results.valid):
                await ctx.tick()
                count += 1
            cycles.append(count)
            rows.append(ctx.get(dut.results.payload))
            ctx.set(dut.results.ready, 1)
            await ctx.tick()
            ctx.set(dut.results.ready, 0)

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    if vcd and gtkw is None:
        gtkw = str(vcd).rsplit(".", 1)[0] + ".gtkw"
    traces = [dut.samples.valid, dut.samples.ready, dut.busy, dut.results.valid,
              dut.results.payload.angles, dut.results.payload.bias, dut.results.payload.flags]
    with sim.write_vcd(vcd, gtkw, traces=traces) if vcd else nullcontext():
        sim.run()
    return EngineRun(
        angles=np.array([[r.angles[i] for i in range(3)] for r in rows], np.int64),
        bias=np.array([[r.bias[i] for i in range(3)] for r in rows], np.int64),
        acc_used=np.array([r.flags.acc_used for r in rows], bool),
        mag_used=np.array([r.flags.mag_used for r in rows], bool),
        saturated=np.array([r.flags.saturated for r in rows], bool),
        complementary=np.array([r.flags.complementary for r in rows], bool),
        counter=np.array([r.counter for r in rows]), cycles=cycles)


def first_mismatch(run, ref):
    """Text naming the first sample and field where the engine and the reference differ."""
    fields = [("angles", 3), ("bias", 3), ("acc_used", 0), ("mag_used", 0), ("saturated", 0)]
    for k in range(len(ref.angles)):
        for name, width in fields:
            got, want = getattr(run, name)[k], getattr(ref, name)[k]
            if not np.array_equal(got, want):
                return (f"sample {k}: {name} gateware {np.asarray(got).tolist()} "
                        f"!= reference {np.asarray(want).tolist()}")
    return None
