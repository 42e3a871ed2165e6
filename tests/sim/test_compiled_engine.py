"""The engine's Verilog in Verilator: the same results and cycle counts as Amaranth's simulator,
and whole recordings bit for bit with the fixed-point model, for each filter.

Needs verilator and g++ (``apt-get install verilator g++``): skipped without them on a developer
machine, a failure in CI. The compiled model is cached (``sim/compiled_engine.py``), so only the
first run after a design change pays the build (about 15 s)."""

import glob
import pathlib

import numpy as np
import pytest

from mpu9250_ahrs.hdl.attitude_engine import WORST_UPDATE_CYCLES, AttitudeEngine
from mpu9250_ahrs.hdl.attitude_program import (CONFIG_REGS, CONTROL_ADDR, FILTER_CODES,
                                               control_word)
from mpu9250_ahrs.reference.fixed_point import FILTERS, attitude_fixed
from mpu9250_ahrs.reference.frames import body_to_mag
from mpu9250_ahrs.sim.attitude_bench import RESULT_FIELDS, first_mismatch, run_engine
from mpu9250_ahrs.sim.compiled_engine import CompiledEngine, replay_gateware
from mpu9250_ahrs.sim.motion import SensorModel, concat, random_motion, static
from mpu9250_ahrs.sim.recording import Scales, load_broad, quantise

from tests.conftest import require_tool


@pytest.fixture(scope="module")
def compiled():
    require_tool("verilator", "apt-get install verilator")
    require_tool("g++", "apt-get install g++")
    return CompiledEngine(AttitudeEngine)


def test_compiled_equals_pysim_across_reset_and_switches(compiled):
    """Flagship, a switch to Kalman, a register write, a filter reset into complementary, the
    flagship again: every field and every cycle count agree."""
    sensor = SensorModel(gyro_noise=np.radians(0.05), accel_noise=0.02, mag_noise=0.3, seed=8)
    traj = concat(static((10, 50, -120), 0.08), random_motion(0.14, seed=3))
    gc, ac, mc = sensor.counts(traj)
    mk = body_to_mag(mc)
    valid = np.arange(len(gc)) % 3 != 1
    writes = {6: [(CONTROL_ADDR, control_word("kalman"))],
              10: [(CONFIG_REGS["R"], 3 << 24)],
              13: [(CONTROL_ADDR, control_word("complementary", reset=True))],
              17: [(CONTROL_ADDR, control_word("flagship"))]}
    pysim = run_engine(AttitudeEngine(), gc, ac, mk, valid, writes=writes, asa=(150, 120, 200))
    fast = compiled.run(gc, ac, mk, valid, writes=writes, asa=(150, 120, 200))
    for name in RESULT_FIELDS + ("counter", "cycles"):
        assert np.array_equal(np.asarray(getattr(pysim, name)),
                              np.asarray(getattr(fast, name))), name
    assert max(fast.cycles) <= WORST_UPDATE_CYCLES      # first updates after resets included
    select = ["flagship"] * 6 + ["kalman"] * 7 + ["complementary"] * 4
    select += ["flagship"] * (len(gc) - len(select))
    ref = attitude_fixed(gc, ac, mk, valid, asa=(150, 120, 200), select=select,
                         writes={10: {"R": 3 << 24}}, resets={13})
    assert first_mismatch(fast, ref) is None, first_mismatch(fast, ref)
    assert list(fast.filter) == [FILTER_CODES[f] for f in select]


def test_filter_codes_agree_with_the_reference():
    assert [FILTER_CODES[name] for name in FILTERS] == list(range(len(FILTERS)))


RECORDINGS = sorted(glob.glob("../shared/data/broad/*.hdf5")) or sorted(glob.glob(
    str(pathlib.Path(__file__).resolve().parents[3] / "shared/data/broad/*.hdf5")))


@pytest.mark.skipif(not RECORDINGS, reason="shared/data/broad not beside the checkout")
@pytest.mark.parametrize("filter", ["flagship", "kalman", "complementary"])
def test_whole_recording_bit_exact(compiled, filter):
    """Every sample of the shortest shared recording (trial 33, a magnet attached: the
    flagship's gates at work) through the compiled gateware, equal to the fixed-point model."""
    path = min(RECORDINGS, key=lambda p: len(load_broad(p).gyr))
    rec = load_broad(path)
    scales = Scales()
    counts = quantise(rec.gyr, rec.acc, rec.mag, scales)
    run, ref, _ = replay_gateware(filter, *counts, rec.dt, engine=compiled,
                                  gyro_lsb_per_dps=scales.gyro_lsb_per_dps,
                                  accel_lsb_per_ms2=scales.accel_lsb_per_ms2)
    assert len(run.angles) == len(rec.gyr) > 40_000
    mismatch = first_mismatch(run, ref)
    assert mismatch is None, mismatch
    # the bound ``build``'s rate check and ``report``'s max_sample_rate_hz rely on
    assert max(run.cycles) <= WORST_UPDATE_CYCLES
    if filter == "flagship":
        for flag in ("at_rest", "mag_disturbed", "mag_new_ref", "acc_used", "mag_used"):
            assert getattr(run, flag).any(), flag
