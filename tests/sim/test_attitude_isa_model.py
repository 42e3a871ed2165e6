"""The microcode, run instruction by instruction in Python, against the reference: a fast check
of the program's logic on many samples (the gateware tests then check the datapath)."""

import numpy as np

from mpu9250_ahrs.hdl.attitude_program import build_program
from mpu9250_ahrs.reference.fixed_point import CalibrationFixed, KalmanFixedConfig, attitude_fixed
from mpu9250_ahrs.sim.attitude_isa_model import AttitudeISAModel


def test_microcode_matches_reference_on_random_samples():
    rng = np.random.default_rng(1)
    n = 400
    g = rng.integers(-3000, 3000, (n, 3))
    a = rng.integers(-32768, 32768, (n, 3))
    m = rng.integers(-2000, 2000, (n, 3))
    a[50:60] = 0
    m[70:80] = 0
    valid = rng.random(n) > 0.2
    cal = CalibrationFixed(gyro_offset=(3, -5, 7), accel_offset=(100, -50, 20),
                           accel_scale=(16000, 16500, 16384), hard_iron=(30, -40, 50),
                           soft_iron=(16000, 200, -100, 200, 16800, 50, -100, 50, 16300))
    asa = (170, 180, 160)
    select = np.where((np.arange(n) // 97) % 2 == 1, "complementary", "kalman")
    ref = attitude_fixed(g, a, m, valid, asa=asa, cal=cal, select=select)
    model = AttitudeISAModel(KalmanFixedConfig(), cal)
    for k in range(n):
        model.complementary = select[k] == "complementary"
        flags, saturated, _ = model.sample(g[k], a[k], m[k], valid[k], asa)
        theta, bias = model.outputs()
        assert (theta, bias) == (ref.angles[k].tolist(), ref.bias[k].tolist()), f"sample {k}"
        assert ((0 in flags), (1 in flags), saturated) == \
            (ref.acc_used[k], ref.mag_used[k], ref.saturated[k]), f"sample {k} flags"


def test_program_fits_the_rom_and_has_entries():
    program, entry = build_program()
    assert len(program) <= 512 and entry["init"] == 0 and entry["sample"] > 0
