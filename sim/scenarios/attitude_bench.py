"""Drive the attitude engine in Amaranth's simulator and compare it with the reference.

``run_engine`` feeds raw samples (and optional register writes before chosen samples) to an
``AttitudeEngine`` and returns its results and the cycles each update took;
``first_mismatch`` compares them with ``reference.engine_model.attitude_fixed`` field by field
and describes the first difference (``None`` when all match).
"""

from contextlib import nullcontext
from dataclasses import dataclass, field

import numpy as np
from amaranth.sim import Simulator

from ...reference.engine_model import RESULT_FIELDS, RESULT_FLAGS
from ..bench.streams import Monitored, stream_put


__all__ = ["EngineRun", "RESULT_FIELDS", "run_engine", "first_mismatch", "random_inputs"]


@dataclass
class EngineRun:
    quat: np.ndarray
    angles: np.ndarray
    bias: np.ndarray
    acc_used: np.ndarray
    mag_used: np.ndarray
    mag_disturbed: np.ndarray
    mag_new_ref: np.ndarray
    at_rest: np.ndarray
    bias_updated: np.ndarray
    saturated: np.ndarray
    filter: np.ndarray
    counter: np.ndarray
    cycles: list = field(default_factory=list)      # sample valid -> result valid, per sample

    @classmethod
    def from_results(cls, rows, cycles=()):
        """From ``Attitude`` payloads (simulator values or decoded dicts)."""
        get = lambda r, name: r[name] if isinstance(r, dict) else getattr(r, name)
        vec = lambda name, n: np.array([[get(r, name)[i] for i in range(n)] for r in rows],
                                       np.int64).reshape(len(rows), n)
        flag = lambda name: np.array([get(get(r, "flags"), name) for r in rows], np.int64)
        return cls(quat=vec("quat", 4), angles=vec("angles", 3), bias=vec("bias", 3),
                   **{name: flag(name).astype(bool) for name in (*RESULT_FLAGS, "saturated")},
                   filter=flag("filter"), counter=np.array([get(r, "counter") for r in rows]),
                   cycles=list(cycles))


def run_engine(dut, gyro, accel, mag_ak, mag_valid=None, *, asa=(128, 128, 128),
               writes=None, skipped=None, vcd=None, gtkw=None):
    """``writes``: {sample index: [(addr, value), ...]} applied (while idle) before that sample,
    e.g. ``(CONTROL_ADDR, control_word("complementary"))``; ``skipped``: per sample, the
    samples the sensor made before it that were never read (``Sample.skipped``; 0 if None)."""
    n = len(gyro)
    skipped = np.zeros(n, int) if skipped is None else np.asarray(skipped, int)
    valid = np.ones(n, bool) if mag_valid is None else np.asarray(mag_valid, bool)
    writes = writes or {}
    rows = []
    cycles = []

    async def testbench(ctx):
        for i in range(3):
            ctx.set(dut.asa[i], int(asa[i]))
        # the start-up INIT program begins on the first edge: let it, then wait it out below
        await ctx.tick()
        for k in range(n):
            for addr, value in writes.get(k, ()):
                await stream_put(ctx, dut.cfg, {"addr": addr, "data": int(value)})
            ctx.set(dut.samples.payload, {
                "gyro": [int(v) for v in gyro[k]], "accel": [int(v) for v in accel[k]],
                "mag": [int(v) for v in mag_ak[k]], "temp": 0, "counter": k % (1 << 32),
                "skipped": int(skipped[k]),
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
        top.check(ctx)

    top = Monitored(dut, {"samples": dut.samples, "cfg": dut.cfg, "results": dut.results})
    sim = Simulator(top)
    sim.add_clock(1e-6)
    sim.add_testbench(testbench)
    if vcd and gtkw is None:
        from ..bench.waveforms import gtkw_beside
        gtkw = gtkw_beside(vcd)
    traces = [dut.samples.valid, dut.samples.ready, dut.busy, dut.results.valid,
              dut.results.payload.quat, dut.results.payload.angles, dut.results.payload.bias,
              dut.results.payload.flags]
    with sim.write_vcd(vcd, gtkw, traces=traces) if vcd else nullcontext():
        sim.run()
    return EngineRun.from_results(rows, cycles)


def first_mismatch(run, ref):
    """Text naming the first sample and field where the engine and the reference differ
    (``None`` when every field of every sample agrees). A vectorised scan, so that it is quick
    on whole recordings."""
    n = len(ref.angles)
    if len(run.angles) != n:
        return f"{len(run.angles)} results from the gateware, {n} from the reference"
    first = None
    for name in RESULT_FIELDS:
        got, want = np.asarray(getattr(run, name)), np.asarray(getattr(ref, name))
        bad = (got != want).reshape(n, -1).any(axis=1)
        if bad.any():
            k = int(np.argmax(bad))
            if first is None or k < first[0]:
                first = (k, name, got[k], want[k])
    if first is None:
        return None
    k, name, got, want = first
    return (f"sample {k}: {name} gateware {np.asarray(got).tolist()} "
            f"!= reference {np.asarray(want).tolist()}")


def random_inputs(seed, n):
    """``n`` random raw samples for the engine's tests, with the corner cases a recording
    rarely has: any gyro and accelerometer count, zero accelerometer and field vectors (a
    fifth each), missing fields (``mag_valid`` 0 for about 30 %), and a random calibration and
    ASA. Returns (gyro, accel, mag_ak, mag_valid, CalibrationFixed, asa)."""
    from ...hdl.contract.numeric_contract import CalibrationFixed
    rng = np.random.default_rng(seed)
    g = rng.integers(-32768, 32768, (n, 3))
    a = rng.integers(-32768, 32768, (n, 3))
    m = rng.integers(-4000, 4000, (n, 3))
    a[rng.random(n) < 0.2] = 0
    m[rng.random(n) < 0.2] = 0
    valid = rng.random(n) > 0.3
    cal = CalibrationFixed(gyro_offset=tuple(rng.integers(-300, 300, 3).tolist()),
                           accel_offset=tuple(rng.integers(-2000, 2000, 3).tolist()),
                           accel_scale=tuple(rng.integers(12000, 20000, 3).tolist()),
                           hard_iron=tuple(rng.integers(-500, 500, 3).tolist()),
                           soft_iron=tuple(rng.integers(-3000, 20000, 9).tolist()))
    return g, a, m, valid, cal, tuple(rng.integers(0, 256, 3).tolist())
