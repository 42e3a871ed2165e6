"""Attitude engine (gateware) against the fixed-point reference, bit for bit.

Every output of every sample: angles, bias, and the acc_used / mag_used / saturated flags.
A mismatch names the first differing sample and field.
"""

import glob
import pathlib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from mpu9250_ahrs.hdl.engine.attitude_engine import PEEKED, WORST_UPDATE_CYCLES, AttitudeEngine
from mpu9250_ahrs.hdl.engine.register_map import CONFIG_REGS, CONTROL_ADDR, REGS, control_word
from mpu9250_ahrs.hdl.contract.numeric_contract import CalibrationFixed, KalmanFixedConfig
from mpu9250_ahrs.reference.fixed_point import bam_to_deg
from mpu9250_ahrs.reference.engine_model import attitude_fixed
from mpu9250_ahrs.reference.frames import body_to_mag
from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_NAMES
from mpu9250_ahrs.reference.kalman import KalmanParams, kalman_filter
from mpu9250_ahrs.sim.scenarios.attitude_bench import first_mismatch, random_inputs, run_engine
from mpu9250_ahrs.sim.models.motion import SensorModel, concat, static, turntable
from mpu9250_ahrs.reference.recording import load_broad, quantise
from mpu9250_ahrs.sim.bench.streams import stream_put

from .start_done import run_unit


REG_NAMES = {addr: name for name, addr in CONFIG_REGS.items()}


def check(gyro, accel, mag_ak, mag_valid=None, *, config=KalmanFixedConfig(), cal=None,
          asa=(128, 128, 128), writes=None, select="kalman", resets=(), vcd=None):
    """Engine and reference on the same samples; ``writes`` as for ``run_engine`` (the
    reference gets the register-file writes; the filter select and resets are ``select`` and
    ``resets``)."""
    cal = CalibrationFixed() if cal is None else cal
    dut = AttitudeEngine(config, cal, filter=select if isinstance(select, str) else select[0])
    run = run_engine(dut, gyro, accel, mag_ak, mag_valid, asa=asa, writes=writes, vcd=vcd)
    ref_writes = {k: {REG_NAMES[a]: v for a, v in w if a != CONTROL_ADDR}
                  for k, w in (writes or {}).items()}
    ref = attitude_fixed(gyro, accel, mag_ak, mag_valid, asa=asa, cal=cal, config=config,
                         select=select, resets=resets, writes=ref_writes)
    mismatch = first_mismatch(run, ref)
    assert mismatch is None, mismatch
    return run, ref


def angle_diff(a, b):
    return np.abs((np.asarray(a) - np.asarray(b) + 180) % 360 - 180)


SENSOR = SensorModel(gyro_noise=np.radians(0.05), accel_noise=0.02, mag_noise=0.3,
                     gyro_bias=np.radians([0.3, -0.2, 0.1]), seed=3)


# -- the engine ---------------------------------------------------------------------------------

@settings(max_examples=4, deadline=None)
@given(st.integers(0, 2 ** 32 - 1))
def test_random_inputs_and_calibration(seed):
    """Amaranth's simulator against the reference on random inputs (a few; the compiled
    engine's test of the same kind runs a thousand samples a run)."""
    g, a, m, valid, cal, asa = random_inputs(seed, 6)
    check(g, a, m, valid, cal=cal, asa=asa)


def test_static_35_degree_tilt(vcd):
    """Bit for bit with the reference, and within 0.05° of the float filter (issue 5)."""
    traj = static((35, 0, 20), 0.8)
    gc, ac, mc = SENSOR.counts(traj)
    run, ref = check(gc, ac, body_to_mag(mc), vcd=vcd())
    euler, _, _ = kalman_filter(gc / 16.4, ac.astype(float), mc.astype(float), traj.dt,
                                KalmanParams(rates="body"))
    assert angle_diff(bam_to_deg(run.angles), euler).max() < 0.05
    assert angle_diff(bam_to_deg(run.angles[-1]), (35, 0, 20)).max() < 2.0


def test_heading_across_180_and_complementary_switch():
    """A yaw turn through ±180°, Kalman then complementary (switched at run time)."""
    traj = turntable((0, 0, 1), 200, 0.4, start_deg=(10, -5, 165))
    gc, ac, mc = SENSOR.counts(traj)
    n = len(gc)
    select = ["kalman"] * (n // 2) + ["complementary"] * (n - n // 2)
    writes = {n // 2: [(CONTROL_ADDR, control_word("complementary"))]}
    run, _ = check(gc, ac, body_to_mag(mc), writes=writes, select=select)
    yaw = bam_to_deg(run.angles[:, 2])
    assert yaw.max() > 170 and yaw.min() < -170                  # it did cross the wrap
    assert run.filter[0] == 0 and run.filter[-1] == 1


@pytest.mark.parametrize("filter", ["kalman", "flagship"])
@pytest.mark.parametrize("euler", [(0, 90, 0), (0, -90, 30), (30, 89.9, 0)])
def test_pitch_at_90_degrees(euler, filter):
    gc, ac, mc = SENSOR.counts(static(euler, 0.06))
    run, _ = check(gc, ac, body_to_mag(mc), select=filter)
    if filter == "flagship":              # no gimbal lock: the quaternion is the pose
        from mpu9250_ahrs.reference.flagship_fixed import q30_to_float
        from mpu9250_ahrs.reference.frames import euler_to_quat, orientation_errors
        err = orientation_errors(q30_to_float(run.quat[-1]), euler_to_quat(np.radians(euler)))
        assert np.degrees(err[0]) < 1.5


def test_flagship_static_tilt_and_angles():
    """The flagship's first results: tilt from the first sample, heading from the first field,
    the angles derived from its quaternion."""
    traj = static((35, -12, 20), 0.08)
    gc, ac, mc = SENSOR.counts(traj)
    run, _ = check(gc, ac, body_to_mag(mc), select="flagship")
    assert angle_diff(bam_to_deg(run.angles[-1]), (35, -12, 20)).max() < 1.0
    assert run.acc_used.all() and run.mag_used.all() and (run.filter == 2).all()
    assert run.mag_new_ref.sum() == 0 and not run.saturated.any()


def test_madgwick_aligns_then_holds_a_static_pose():
    """Madgwick's first result: aligned from the first sample's tilt and heading, then held by
    its gradient steps; the angles derived from its quaternion."""
    traj = static((35, -12, 20), 0.08)
    gc, ac, mc = SENSOR.counts(traj)
    run, _ = check(gc, ac, body_to_mag(mc), select="madgwick")
    error = angle_diff(bam_to_deg(run.angles), (35, -12, 20))
    assert error[:, :2].max() < 0.5 and error[:, 2].max() < 1.5       # one noisy field
    assert run.acc_used.all() and run.mag_used.all() and (run.filter == 3).all()
    assert not run.saturated.any() and not run.bias_updated.any()


@pytest.mark.parametrize("filter", ["kalman", "flagship", "madgwick"])
def test_full_scale_zero_vectors_and_invalid_field(filter):
    n = 8
    g = np.tile([32767, -32768, 32767], (n, 1))
    a = np.tile([-32768, 32767, -32768], (n, 1))
    m = np.tile([32767, -32768, 32767], (n, 1))
    a[2] = 0                                   # free fall: no tilt update
    m[4] = 0                                   # zero field: no yaw update
    valid = np.ones(n, bool)
    valid[6] = False                           # no new magnetometer data
    cal = CalibrationFixed(accel_scale=(32767, 32767, 32767))        # ~2.0: saturates 16 bits
    run, ref = check(g, a, m, valid, cal=cal, asa=(255, 0, 255), select=filter)
    assert not run.acc_used[2] and not run.mag_used[4] and not run.mag_used[6]
    assert run.acc_used[3] and run.saturated.any()


def test_coefficient_extremes_and_reset():
    """R ≤ 0 (gain 0, flagged), huge Q (covariance saturates), a = 0 and 1, and a filter
    reset through the control register."""
    traj = static((20, 10, -40), 0.12)
    gc, ac, mc = SENSOR.counts(traj)
    mc = body_to_mag(mc)
    big = 2 ** 31 - 1
    writes = {0: [(CONFIG_REGS["R"], -(2 ** 31))],
              3: [(CONFIG_REGS["R"], 2 << 24), (CONFIG_REGS["Q_ANGLE"], big),
                  (CONFIG_REGS["Q_BIAS"], big)],
              6: [(CONTROL_ADDR, control_word("kalman", reset=True)),
                  (CONFIG_REGS["Q_ANGLE"], 1 << 20),
                  (CONFIG_REGS["Q_BIAS"], 1 << 20), (CONFIG_REGS["ONE_MINUS_A"], 0)],
              9: [(CONTROL_ADDR, control_word("complementary"))],
              10: [(CONFIG_REGS["ONE_MINUS_A"], 1 << 24)]}
    n = len(gc)
    run, _ = check(gc, ac, mc, writes=writes, select=["kalman"] * 9 + ["complementary"] * (n - 9),
                   resets={6})
    assert run.saturated[0] and run.saturated[3]         # R < 0; covariance clamped
    assert not run.saturated[7]                          # after the reset


RECORDINGS = sorted(glob.glob("../shared/data/broad/*.hdf5")) or sorted(glob.glob(
    str(pathlib.Path(__file__).resolve().parents[3] / "shared/data/broad/*.hdf5")))


@pytest.mark.skipif(not RECORDINGS, reason="shared/data/broad not beside the checkout")
def test_recorded_stretch():
    rec = load_broad(RECORDINGS[-1])
    start = 3000                                     # into the movement
    gc, ac, mc = quantise(*(x[start:start + 40] for x in (rec.gyr, rec.acc, rec.mag)))
    dt = rec.dt
    check(gc, ac, body_to_mag(mc), config=KalmanFixedConfig(dt=dt))


def test_register_read_back():
    """Writes, the control register and the filter state read back through ``cfg_read``."""
    dut = AttitudeEngine()
    got = {}

    async def read(ctx, addr):
        await stream_put(ctx, dut.cfg_read, addr)
        ctx.set(dut.cfg_read_data.ready, 1)
        *_, data = await ctx.tick().sample(dut.cfg_read_data.payload).until(
            dut.cfg_read_data.valid)
        ctx.set(dut.cfg_read_data.ready, 0)
        return data

    async def testbench(ctx):
        while ctx.get(dut.busy) or ctx.get(dut.cfg.ready) == 0:
            await ctx.tick()
        got["R"] = await read(ctx, CONFIG_REGS["R"])
        for addr, value in ((CONFIG_REGS["R"], 12345),
                            (CONTROL_ADDR, control_word("complementary"))):
            await stream_put(ctx, dut.cfg, {"addr": addr, "data": value})
        got["R2"] = await read(ctx, CONFIG_REGS["R"])
        got["control"] = await read(ctx, CONTROL_ADDR)
        got["p00"] = await read(ctx, REGS["P0_00"])
    run_unit(dut, testbench)
    assert got == {"R": KalmanFixedConfig().registers()["R"], "R2": 12345, "control": 1,
                   "p00": KalmanFixedConfig().registers()["P0"]}


def test_result_holds_still_through_a_reset_and_state_writes():
    """A result that is valid and not taken keeps its payload while the host resets the filter
    (the reset waits until the result is taken) and writes filter state (refused, counted)."""
    dut = AttitudeEngine()
    seen = {}

    async def testbench(ctx):
        sample = {"gyro": [100, -50, 20], "accel": [0, 0, 2048], "mag": [300, 0, -400],
                  "counter": 7, "flags": {"mag_valid": 1}}
        await stream_put(ctx, dut.samples, sample)
        while not ctx.get(dut.results.valid):
            await ctx.tick()
        first = ctx.get(dut.results.payload.as_value())
        await stream_put(ctx, dut.cfg, {"addr": CONTROL_ADDR,
                                        "data": control_word("flagship", reset=True)})
        for addr in (REGS["THETA0"], REGS["QOUT0"], REGS["BIAS1"], CONFIG_REGS["ZERO"]):
            await stream_put(ctx, dut.cfg, {"addr": addr, "data": 0x1234})
        for _ in range(800):                      # longer than any reset program
            assert ctx.get(dut.results.valid)
            assert ctx.get(dut.results.payload.as_value()) == first
            await ctx.tick()
        seen["refused"] = ctx.get(dut.cfg_refused)
        ctx.set(dut.results.ready, 1)
        await ctx.tick()
        ctx.set(dut.results.ready, 0)
        await ctx.tick()
        seen["busy_after_take"] = ctx.get(dut.busy)
    run_unit(dut, testbench)
    assert seen == {"refused": 4, "busy_after_take": 1}


@pytest.mark.parametrize("select", FILTER_NAMES)
def test_peek_reads_the_offered_result(select):
    """``peek_data`` gives the offered result's quaternion, angles and bias (``PEEKED``), the
    cycle after ``peek_en``, equal to the payload's: the framer copies them from there. Also
    after the host's (refused) writes to the filter state while the result waits."""
    dut = AttitudeEngine(filter=select)
    checked = []

    async def peek_all(ctx):
        result = ctx.get(dut.results.payload)
        words = [*result.quat, *result.angles, *result.bias]
        for k in range(len(PEEKED)):
            ctx.set(dut.peek_en, 1)
            ctx.set(dut.peek_index, k)
            await ctx.tick()
            ctx.set(dut.peek_en, 0)
            assert ctx.get(dut.peek_data) == words[k], (select, PEEKED[k])
            checked.append(k)

    async def testbench(ctx):
        for n in range(2):
            sample = {"gyro": [100 * n + 7, -50, 20], "accel": [30, -20, 2048],
                      "mag": [300, 40, -400], "counter": n, "flags": {"mag_valid": 1}}
            await stream_put(ctx, dut.samples, sample)
            while not ctx.get(dut.results.valid):
                await ctx.tick()
            await peek_all(ctx)
            for addr in (REGS["THETA0"], REGS["QOUT0"], REGS["BIAS1"]):
                await stream_put(ctx, dut.cfg, {"addr": addr, "data": 0x1234})
            await peek_all(ctx)
            ctx.set(dut.results.ready, 1)
            await ctx.tick()
            ctx.set(dut.results.ready, 0)
    run_unit(dut, testbench)
    assert len(checked) == 4 * len(PEEKED)


def test_simulate_verb_with_pose_and_attitude(capsys):
    """``simulate --pose --attitude``: the co-simulated samples through the engine converge to
    the pose (roll and pitch from the accelerometer within a few samples). The telemetry
    divider is the one for the simulated sample period (a fifth of the real one): the UART
    carries every due result but, at most, the one the first frame is still on the wire for
    (with the real period's divider, 1, most were not: 24 of 30 in a run of 30)."""
    import json
    from mpu9250_ahrs.cli import main
    assert main(["simulate", "--samples", "12", "--pose", "30,-10,45", "--attitude",
                 "--no-self-test"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = [json.loads(line) for line in lines if "roll_pitch_yaw_deg" in line]
    assert len(rows) == 12 and not any(r["saturated"] for r in rows)
    roll, pitch, _ = rows[-1]["roll_pitch_yaw_deg"]
    assert abs(roll - 30) < 1.5 and abs(pitch + 10) < 1.5
    summary = json.loads(lines[-1])
    assert summary["samples_filtered"] == 12 and summary["samples_lost"] == 0
    assert summary["saturated_results"] == 0 and summary["clock_hz"] == 48e6
    assert 10 < summary["latency_us"]["drdy_to_attitude"] < 60
    assert summary["telemetry_divider"] == 5 and summary["results_not_sent"] <= 1


@pytest.mark.parametrize("select", FILTER_NAMES)
def test_skipped_samples_integrate_the_elapsed_time(select):
    """A turn at a steady rate, no field, with samples missing (``Sample.skipped`` on the next
    one): the
    engine equals the reference bit for bit, and the attitude has turned by the whole elapsed
    time: at the end it is much closer to the run that saw every sample than integrating one
    period per sample leaves it."""
    traj = turntable((0, 0, 1), rate_dps=90.0, duration=0.4, start_deg=(0, 0, 10))
    gc, ac, mc = SensorModel(seed=5).counts(traj)
    mk = body_to_mag(mc)
    n = len(gc)
    keep = [k for k in range(n) if not 6 <= k % 10 <= 8]       # three of every ten missing
    skipped = [0] + [b - a - 1 for a, b in zip(keep, keep[1:])]
    off = np.zeros(len(keep), bool)          # no heading measurement: yaw is the gyro's alone
    run = run_engine(AttitudeEngine(filter=select), gc[keep], ac[keep], mk[keep], off,
                     skipped=skipped)
    ref = attitude_fixed(gc[keep], ac[keep], mk[keep], off, select=select, skipped=skipped)
    assert first_mismatch(run, ref) is None, first_mismatch(run, ref)
    from mpu9250_ahrs.reference.fixed_point import bam_to_deg
    full = attitude_fixed(gc, ac, mk, np.zeros(n, bool), select=select)
    naive = attitude_fixed(gc[keep], ac[keep], mk[keep], off, select=select)  # one period each
    yaw_full = bam_to_deg(full.angles[keep[-1]][2])
    gap_error = angle_diff(bam_to_deg(ref.angles[-1][2]), yaw_full)
    naive_error = angle_diff(bam_to_deg(naive.angles[-1][2]), yaw_full)
    assert naive_error > 5 and gap_error < 0.25 * naive_error, (gap_error, naive_error)


@pytest.mark.parametrize("select", ["kalman", "complementary"])
def test_euler_rate_prediction_bit_exact(select):
    """``EULER_RATES`` (the per-axis filters' Euler-angle-rate prediction) on tumbling motion
    and through ±90° pitch (cos θ held at its minimum): engine = reference, every field."""
    from mpu9250_ahrs.sim.models.motion import random_motion
    traj = concat(turntable((0, 1, 0), rate_dps=400.0, duration=0.3),
                  random_motion(0.25, seed=4))
    gc, ac, mc = SENSOR.counts(traj)
    ac[:30] = 0                 # no tilt measurement during the turn: pitch passes 90°
    run, ref = check(gc, ac, body_to_mag(mc), config=KalmanFixedConfig(euler_rates=True),
                     select=select)
    pitch = np.abs(np.degrees(np.asarray(ref.angles)[:, 1] * 2.0 ** -32 * 2 * np.pi))
    assert pitch.max() > 85
    assert max(run.cycles) <= WORST_UPDATE_CYCLES


def test_longest_updates_within_the_bound():
    """The longest updates: the Kalman filter with Euler-angle rates and every measurement taken
    (tilt and heading: the accelerometer and a valid field on every sample), its first update
    after a reset its longest; and the first updates of the flagship and Madgwick's filter
    (their longest here): each within ``WORST_UPDATE_CYCLES``, bit for bit."""
    from mpu9250_ahrs.sim.models.motion import random_motion
    traj = concat(turntable((0, 1, 0), rate_dps=400.0, duration=0.05),
                  random_motion(0.05, seed=4))
    gc, ac, mc = SENSOR.counts(traj)
    run, _ = check(gc, ac, body_to_mag(mc), config=KalmanFixedConfig(euler_rates=True))
    cycles = list(run.cycles)
    assert max(cycles) == cycles[0] <= WORST_UPDATE_CYCLES
    firsts = {}
    for select in ("flagship", "madgwick"):
        run, _ = check(gc[:3], ac[:3], body_to_mag(mc[:3]), select=select)
        firsts[select] = run.cycles[0]
        assert max(run.cycles) == run.cycles[0]
    assert max(firsts.values()) <= WORST_UPDATE_CYCLES


def test_euler_rates_follow_a_coning_motion_better():
    """Tilted 45° in roll, turning about the vertical: body rates put the turn partly on the
    pitch axis; Euler-angle rates keep roll and pitch where they are (float, no measurement)."""
    from mpu9250_ahrs.reference.engine_model import EngineModel
    n, dt = 200, 0.01
    rate = np.radians(90.0)
    # the vertical turn in body axes at roll 45°: ω_body = (0, sin φ, cos φ)·ψ̇
    gyro = np.tile(np.round(np.degrees([0, np.sin(np.pi / 4) * rate, np.cos(np.pi / 4) * rate])
                            * 16.4), (n, 1)).astype(int)
    zero = np.zeros((n, 3), int)
    out = {}
    for euler in (False, True):
        model = EngineModel(KalmanFixedConfig(dt=dt, euler_rates=euler), filter="complementary")
        model.kf.theta[0] = 1 << 29                                 # start at roll 45°
        for k in range(n):
            r = model.sample(gyro[k], zero[k], zero[k], False)
        out[euler] = np.degrees(np.asarray(r["angles"]) * 2.0 ** -32 * 2 * np.pi)
    assert abs(out[True][0] - 45) < 1 and abs(out[True][1]) < 1
    assert abs(out[False][1]) > 10


def _against_the_model(program, entry):
    """One sample through ``program`` on the engine and on the instruction model: (the
    engine's run, the model's (quaternion, angles, bias)), asserted equal, bit for bit."""
    from mpu9250_ahrs.reference.engine_model import EngineModel
    from mpu9250_ahrs.sim.models.attitude_isa_model import AttitudeISAModel

    gyro, accel, mag_ak = ([[1200, -3400, 50]], [[0, 0, 8192]], [[10, 20, 30]])
    run = run_engine(AttitudeEngine(program=(program, entry)), gyro, accel, mag_ak)
    model = AttitudeISAModel(EngineModel().reg)
    model.program, model.entry = program, entry
    model.sample(gyro[0], accel[0], mag_ak[0])
    outputs = tuple(model.outputs())
    assert (run.quat[0].tolist(), run.angles[0].tolist(), run.bias[0].tolist()) == outputs
    return run, outputs


def _b_read_program():
    """A program whose instructions read as ``b`` the register written as they go on (the
    engine forwards ``a`` only): an ADD (its operands swapped), a SUB, a DIV and a VEC (a NOP
    before each), the square of a MUL's result three MULs on (a NOP, and the chain of MULs
    broken), and an ADD that reads it as both (a NOP). The results are written to the
    result's quaternion, angles and bias words."""
    from mpu9250_ahrs.hdl.engine.attitude_isa import Q14, Assembler
    asm, r = Assembler(), REGS
    g0, g1, g2 = r["GRAW0"], r["GRAW1"], r["GRAW2"]
    q = [r[f"QOUT{k}"] for k in range(4)]
    th = [r[f"THETA{k}"] for k in range(3)]
    bias = [r[f"BIAS{k}"] for k in range(3)]
    asm.label("init")
    asm.end()
    asm.label("sample")
    asm.add(q[0], g0, g1)
    asm.add(q[1], g2, q[0])                     # swapped
    asm.sub(q[2], g0, q[1])                     # a NOP before
    asm.div(q[3], g0, q[2])                     # a NOP before
    asm.mul(th[0], g0, g1, Q14)
    asm.mul(th[1], g1, g2, Q14)
    asm.mul(th[2], g0, g2, Q14)
    asm.mul(bias[0], th[0], th[0], Q14)         # th[0] lands as it goes on: a NOP before
    asm.add(bias[1], bias[0], bias[0])          # both operands: a NOP before
    asm.vec(th[0], g2, bias[1])                 # a NOP before; writes THETA0 and THETA1
    asm.sync()                                  # a sample's run passes one (the early start)
    asm.end()
    return asm.resolve(), {"init": asm.labels["init"], "sample": asm.labels["sample"]}


def test_b_operand_is_not_forwarded():
    """The engine forwards a result into the next instruction's ``a`` operand only: the
    assembler swaps an ADD's or MUL's operands, or puts a NOP before an instruction that would
    read it as ``b`` (``attitude_isa``). The program of ``_b_read_program`` against the
    instruction model, bit for bit."""
    from mpu9250_ahrs.hdl.engine.attitude_isa import Op

    program, entry = _b_read_program()
    body = [ins.op for ins in program[entry["sample"]:]]
    assert body.count(Op.NOP) == 5
    swapped = program[entry["sample"] + 1]
    assert (swapped.op, swapped.a, swapped.b) == (Op.ADD, REGS["QOUT0"], REGS["GRAW2"])
    _, (quat, angles, bias) = _against_the_model(program, entry)
    assert len({*quat, *angles, *bias}) > 6            # results, not zeros


# a chain of operations for ``test_background_units``: (op, shadow) with op "vec", "short"
# (an 8-iteration VEC), "rot" or "div", and the instructions between a background start and
# its collect: that many ADDs, or (op2, n): a blocking operation of the other unit ("vec" or
# "div") and n ADDs. Each takes its operands from the one before, so a result collected
# early changes every later one
BACKGROUND_CHAIN = [("vec", 0), ("rot", 1), ("short", 7), ("short", 9), ("vec", 15),
                    ("rot", 15), ("vec", 16), ("rot", 17), ("vec", 20), ("div", 0),
                    ("div", 31), ("div", 32), ("div", 40), ("div", ("vec", 5)),
                    ("vec", ("div", 0)), ("rot", 3)]
# the cycles of work between a start and its collect that cost nothing: the unit's wait
FREE_CYCLES = {"vec": 16, "rot": 15, "short": 8, "div": 32}
BLOCKING_CYCLES = {"vec": 19, "div": 34}


def _background_program(go_on):
    """A program of ``BACKGROUND_CHAIN`` (its operations started in the background, or each
    blocking with its shadow's instructions after it: the same results), the results written
    round the result's quaternion, angles and bias words; BIAS2 counts the ADDs."""
    from mpu9250_ahrs.hdl.engine.attitude_isa import Assembler
    from mpu9250_ahrs.hdl.engine.register_map import TEMPS
    asm, r = Assembler(scratch_pool=tuple(TEMPS)), REGS
    asm.label("init")
    asm.end()
    asm.label("sample")
    asm.add(r["BIAS2"], r["ZERO"], r["ZERO"])
    pairs = ["QOUT0", "QOUT2", "THETA0", "BIAS0"]
    x, y = r["GRAW0"], r["GRAW1"]
    spare = r["GRAW2"]                  # the shadow's own operation writes its pair here
    for k, (op, shadow) in enumerate(BACKGROUND_CHAIN):
        d = r[pairs[k % len(pairs)]]
        {"rot": lambda: asm.rot(d, x, go_on=go_on),
         "div": lambda: asm.div(d, x, y, go_on=go_on)}.get(
            op, lambda: asm.vec(d, x, y, short=op == "short", go_on=go_on))()
        other, adds = shadow if isinstance(shadow, tuple) else (None, shadow)
        if other == "vec":
            asm.vec(spare, x, y)
        elif other == "div":
            asm.div(spare, x, y)
        for _ in range(adds):
            asm.add(r["BIAS2"], r["BIAS2"], r["INT1"])
        if go_on:
            asm.collect("divider" if op == "div" else "cordic")
        x, y = d, d + 1
    asm.sync()                                  # a sample's run passes one (the early start)
    asm.end()
    return asm.resolve(), {"init": asm.labels["init"], "sample": asm.labels["sample"]}


def test_background_units():
    """VEC, ROT and DIV started in the background (``attitude_isa``) against the instruction
    model running the same program, bit for bit, and against the same chain made blocking: a
    collect that comes before its unit is done waits for it (at once, after one instruction,
    after all but one of its cycles), one that comes after does not, and the other unit may
    work meanwhile; each saves the cycles of the work between, up to its unit's wait."""
    runs = {}
    for go_on in (False, True):
        runs[go_on], (quat, angles, bias) = _against_the_model(*_background_program(go_on))
    adds = [s if isinstance(s, int) else s[1] for _, s in BACKGROUND_CHAIN]
    assert bias[2] == sum(adds)                                        # INT1 is 1
    shadows = [s if isinstance(s, int) else BLOCKING_CYCLES[s[0]] + s[1]
               for _, s in BACKGROUND_CHAIN]
    saved = sum(min(cycles, FREE_CYCLES[op])
                for (op, _), cycles in zip(BACKGROUND_CHAIN, shadows))
    assert runs[False].cycles[0] - runs[True].cycles[0] == saved
