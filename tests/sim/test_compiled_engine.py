"""The engine's Verilog in Verilator: the same results and cycle counts as Amaranth's simulator,
and whole recordings bit for bit with the fixed-point model, for each filter.

Needs verilator and g++ (``apt-get install verilator g++``): skipped without them on a developer
machine, a failure in CI. The compiled model is cached (``sim/scenarios/compiled_engine.py``), so only the
first run after a design change pays the build (about 15 s)."""

import glob
import pathlib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mpu9250_ahrs.hdl.engine.attitude_engine import WORST_UPDATE_CYCLES, AttitudeEngine
from mpu9250_ahrs.hdl.engine.register_map import CONFIG_REGS, CONTROL_ADDR, control_word
from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_CODES
from mpu9250_ahrs.reference.engine_model import FILTERS, attitude_fixed
from mpu9250_ahrs.reference.frames import body_to_mag
from mpu9250_ahrs.sim.scenarios.attitude_bench import RESULT_FIELDS, first_mismatch, run_engine
from mpu9250_ahrs.sim.scenarios.compiled_engine import CompiledEngine, replay_gateware
from mpu9250_ahrs.sim.models.motion import SensorModel, concat, random_motion, static
from mpu9250_ahrs.reference.recording import Scales, load_broad, quantise

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


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.sampled_from(FILTERS))
def test_random_inputs_and_calibration(compiled, seed, filter):
    """Random raw samples (zero vectors and missing fields among them), a random calibration
    and ASA, any filter: 40 examples of 25 samples (1,000 samples a run) through the compiled
    engine, bit for bit with the fixed-point model."""
    from mpu9250_ahrs.hdl.contract.numeric_contract import KalmanFixedConfig
    from mpu9250_ahrs.hdl.contract.numeric_contract import FlagshipFixedConfig
    from mpu9250_ahrs.sim.scenarios.attitude_bench import random_inputs
    from mpu9250_ahrs.sim.scenarios.compiled_engine import configuration_writes
    g, a, m, valid, cal, asa = random_inputs(seed, 25)
    kalman = KalmanFixedConfig()
    flagship = FlagshipFixedConfig.matching(kalman)
    run = compiled.run(g, a, m, valid, asa=asa,
                       writes={0: configuration_writes(filter, kalman, flagship, cal)})
    ref = attitude_fixed(g, a, m, valid, asa=asa, cal=cal, config=kalman, flagship=flagship,
                         select=filter, resets={0})
    assert first_mismatch(run, ref) is None, first_mismatch(run, ref)


def test_filter_codes_agree_with_the_reference():
    assert [FILTER_CODES[name] for name in FILTERS] == list(range(len(FILTERS)))


RECORDINGS = sorted(glob.glob("../shared/data/broad/*.hdf5")) or sorted(glob.glob(
    str(pathlib.Path(__file__).resolve().parents[3] / "shared/data/broad/*.hdf5")))


@pytest.mark.skipif(not RECORDINGS, reason="shared/data/broad not beside the checkout")
# the flagship (the reset default, the longest program) in the default run; the other
# filters, about 10 s each, in the slow step
@pytest.mark.parametrize("filter", ["flagship", *(pytest.param(name, marks=pytest.mark.slow)
                                                  for name in FILTERS if name != "flagship")])
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


def test_every_control_word_agrees_with_the_model(compiled):
    """Issue #25: every value a host can write to the control bits of the host-writable
    registers, through the compiled engine and ``EngineModel``: CONTROL (every word of bits
    3:0, reserved bits set, code 3 alone and with reset, which the gateware once took as
    Kalman while the model ran the complementary filter; it names Madgwick now) and EULER_RATES (zero, one, any
    other value), bit for bit and with the same filter in every result."""
    sensor = SensorModel(gyro_noise=np.radians(0.05), accel_noise=0.02, mag_noise=0.3, seed=5)
    traj = concat(static((20, -30, 60), 0.1), random_motion(0.5, seed=9))
    gc, ac, mc = sensor.counts(traj)
    mk = body_to_mag(mc)
    words = [3, 0x7, 1, 3, 0, 0x3 | 0x4, 0x8 | 0x3, 0xC, 2, 0x10, -1, 0x8000_0001, 0x5, 0xB,
             0x6, 0xF, 0x9, 0xA, 0xE, 0xD, 0x2, 0x4, 0x8, 0x1]
    euler = {4: 1, 9: -1, 14: 0, 16: -(1 << 31), 20: 0}
    controls = {2 + 2 * k: [w] for k, w in enumerate(words)}
    as_signed = lambda w: w - (1 << 32) if w >= 1 << 31 else w      # the port's signed 32
    writes = {k: [(CONTROL_ADDR, as_signed(w)) for w in ws] for k, ws in controls.items()}
    for k, v in euler.items():
        writes.setdefault(2 + 2 * k, []).insert(0, (CONFIG_REGS["EULER_RATES"], v))
    n = 2 + 2 * len(words) + 4
    assert len(gc) >= n
    gc, ac, mk = gc[:n], ac[:n], mk[:n]
    run = compiled.run(gc, ac, mk, writes=writes)
    ref = attitude_fixed(gc, ac, mk, select="flagship", controls=controls,
                         writes={2 + 2 * k: {"EULER_RATES": v} for k, v in euler.items()})
    assert first_mismatch(run, ref) is None, first_mismatch(run, ref)
    assert list(run.filter) == list(ref.filter)
    assert set(run.filter) == set(range(len(FILTER_CODES)))


@pytest.mark.slow
@pytest.mark.parametrize("bias_dps", [0.0, 1.0, 2.0, 3.0, 4.0, 5.0])
def test_flagship_learns_every_datasheet_bias_in_the_gateware(compiled, bias_dps):
    """Issue #60: the gateware's flagship, still then moving then still, with a gyro bias of
    0 .. 5 °/s on every axis (8.7 °/s at the datasheet's limit on all three): bit for bit
    with the model, its bias the part's within 0.1 °/s and its attitude within 0.1° at
    the end and 1° in motion (it never learnt a bias above about 1.9 °/s: 40° wrong at 5)."""
    from mpu9250_ahrs.reference.flagship_fixed import q30_to_float
    from tests.reference.test_flagship_rest import GYRO_LSB_PER_DPS, RATE, bias_scenario, errors
    traj, gc, ac, mc, bias = bias_scenario(bias_dps)
    run, ref, _ = replay_gateware("flagship", gc, ac, mc, 1 / RATE, engine=compiled)
    mismatch = first_mismatch(run, ref)
    assert mismatch is None, mismatch
    moving, end = errors(q30_to_float(run.quat), traj)
    assert end < 0.1 and moving < 1.0, (moving, end)
    learnt = np.asarray(run.bias[-1], float) / 65536 / GYRO_LSB_PER_DPS
    assert learnt == pytest.approx(bias, abs=0.1)
    assert run.at_rest.any()
