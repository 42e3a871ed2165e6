"""The microcode, run instruction by instruction in Python, against the reference
(``EngineModel``): a fast check of the programs' logic on many samples (the gateware tests then
check the datapath)."""

import numpy as np

from mpu9250_ahrs.hdl.engine.attitude_isa import ROM_DEPTH, Flag
from mpu9250_ahrs.hdl.engine.attitude_program import build_program
from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_NAMES
from mpu9250_ahrs.hdl.contract.numeric_contract import CalibrationFixed
from mpu9250_ahrs.reference.engine_model import RESULT_FLAGS, EngineModel
from mpu9250_ahrs.reference.frames import body_to_mag
from mpu9250_ahrs.sim.models.attitude_isa_model import AttitudeISAModel
from mpu9250_ahrs.sim.models.motion import SensorModel, concat, static, turn


def run_both(g, a, m, valid, select, *, asa=(128, 128, 128), **model):
    """Every sample through the reference and the ISA model; returns the reference's results
    after checking that every field agrees."""
    ref = EngineModel(filter=select[0], **model)
    isa = AttitudeISAModel(ref.reg, filter=select[0])
    results = []
    for k in range(len(g)):
        ref.select(select[k])
        isa.select(select[k])
        want = ref.sample(g[k], a[k], m[k], valid[k], asa)
        flags, saturated, _ = isa.sample(g[k], a[k], m[k], valid[k], asa)
        quat, angles, bias = isa.outputs()
        got = {"quat": quat, "angles": angles, "bias": bias, "saturated": saturated,
               "filter": isa.filter, **{f: Flag[f.upper()] in flags for f in RESULT_FLAGS}}
        assert got == want, f"sample {k} ({select[k]})"
        results.append(want)
    return results


def test_microcode_matches_reference_on_random_samples():
    """Random raw samples and calibration, the registry's filters taking turns (each switch
    makes the next sample a first one)."""
    rng = np.random.default_rng(1)
    n = 400
    g = rng.integers(-3000, 3000, (n, 3)).tolist()
    a = rng.integers(-32768, 32768, (n, 3))
    m = rng.integers(-2000, 2000, (n, 3))
    a[50:60] = 0
    m[70:80] = 0
    valid = (rng.random(n) > 0.2).tolist()
    cal = CalibrationFixed(gyro_offset=(3, -5, 7), accel_offset=(100, -50, 20),
                           accel_scale=(16000, 16500, 16384), hard_iron=(30, -40, 50),
                           soft_iron=(16000, 200, -100, 200, 16800, 50, -100, 50, 16300))
    names = ("flagship", *(name for name in FILTER_NAMES if name != "flagship"))
    select = [names[(k // 47) % len(names)] for k in range(n)]
    run_both(g, a.tolist(), m.tolist(), valid, select, asa=(170, 180, 160), cal=cal)


def test_flagship_rest_gates_and_new_reference():
    """Rest (bias learnt), a turn, then a magnet: the field is rejected as disturbed and, once
    it has stayed steady for K_NEW samples, adopted as the new reference; all bit for bit."""
    sensor = SensorModel(gyro_noise=np.radians(0.05), accel_noise=0.02, mag_noise=0.3,
                         gyro_bias=np.radians([0.3, -0.2, 0.1]), seed=4)
    traj = concat(static((20, -10, 30), 0.6), turn((0, 0, 1), 40, 0.3, start_deg=(20, -10, 30)),
                  static((20, -10, 70), 1.6))
    gc, ac, mc = sensor.counts(traj)
    mc = mc.astype(float)
    mc[100:] *= 1.35                                  # a magnet from sample 100 on
    mk = body_to_mag(np.round(mc).astype(int))
    n = len(gc)
    short = {"K_REST": 20, "K_REF": 30, "K_FAST": 40, "K_NEW": 60}
    out = run_both(gc.tolist(), ac.tolist(), mk.tolist(), [True] * n, ["flagship"] * n,
                   registers=short)
    seen = {f: [k for k, r in enumerate(out) if r[f]] for f in RESULT_FLAGS}
    assert seen["at_rest"] and seen["bias_updated"] == seen["at_rest"]
    assert seen["mag_disturbed"] and seen["mag_disturbed"][0] >= 100
    new_refs = seen["mag_new_ref"]
    assert new_refs[0] < 100 and 160 in new_refs, new_refs      # learnt; adopted after K_NEW
    assert any(k > new_refs[-1] for k in seen["mag_used"])            # used again after


def test_program_fits_the_rom_and_has_entries():
    program, entry = build_program()
    assert len(program) <= ROM_DEPTH and entry["init"] == 0 and entry["sample"] > 0


def test_the_field_is_read_only_after_one_sync():
    """The early start (``attitude_isa``): the model holds the field's registers (MRAW, M,
    MAG_OK) at None until the run's SYNC, so a program that reads them sooner, passes no SYNC
    or two, fails; the assembler refuses a MAG_INVALID decided in the words the engine's
    fetch reads while SYNC waits."""
    import pytest
    from mpu9250_ahrs.hdl.engine.attitude_isa import SYNC_SHADOW, Assembler, Cond
    from mpu9250_ahrs.hdl.engine.register_map import REGS as r

    def program(body):
        asm = Assembler()
        asm.label("init")
        asm.end()
        asm.label("sample")
        body(asm)
        asm.end()
        return asm.resolve(), {"init": asm.labels["init"], "sample": asm.labels["sample"]}

    def run(body):
        isa = AttitudeISAModel(EngineModel().reg)
        isa.program, isa.entry = program(body)
        return isa.sample([1, 2, 3], [4, 5, 6], [7, 8, 9])

    run(lambda asm: (asm.sync(), asm.add(r["QOUT0"], r["MRAW0"], r["MRAW1"])))
    for wrong in (lambda asm: asm.add(r["QOUT0"], r["MRAW0"], r["ZERO"]),      # before
                  lambda asm: asm.br("x", Cond.A_ZERO, a=r["MAG_OK"]) or asm.label("x"),
                  lambda asm: asm.nop(),                                     # none
                  lambda asm: (asm.sync(), asm.sync())):                     # two
        with pytest.raises((RuntimeError, TypeError)):
            run(wrong)

    def shadowed(gap):
        def body(asm):
            asm.sync()
            for _ in range(gap):
                asm.add(r["QOUT0"], r["ZERO"], r["ZERO"])
            asm.br("x", Cond.MAG_INVALID)
            asm.label("x")
        return body
    program(shadowed(SYNC_SHADOW + 1))
    with pytest.raises(ValueError, match="MAG_INVALID"):
        program(shadowed(SYNC_SHADOW - 2))
