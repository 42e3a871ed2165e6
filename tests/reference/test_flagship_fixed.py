"""The fixed-point flagship against the float flagship: simulated motion at any attitude, a
recorded stretch, full-scale and zero inputs."""

import glob
import pathlib

import numpy as np
import pytest

from mpu9250_ahrs.reference.flagship import flagship_filter
from mpu9250_ahrs.reference.flagship_fixed import (FlagshipFixedConfig, flagship_fixed,
                                                   q30_to_float)
from mpu9250_ahrs.reference.frames import orientation_errors
from mpu9250_ahrs.sim.motion import SensorModel, concat, random_motion, static, turn, turntable
from mpu9250_ahrs.reference.recording import Scales, load_broad, quantise, to_units

SCALES = Scales()
SENSOR = SensorModel(gyro_noise=np.radians(0.05), accel_noise=0.02, mag_noise=0.3,
                     gyro_bias=np.radians([0.2, -0.1, 0.15]), seed=5)


def difference_deg(gc, ac, mc, dt):
    """(RMS, max) angle between the fixed and the float flagship, and the fixed quaternions."""
    qf = flagship_filter(*to_units(gc, ac, mc, SCALES), dt)
    qi, _ = flagship_fixed(gc, ac, mc, FlagshipFixedConfig(dt, SCALES.gyro_lsb_per_rad,
                                                           SCALES.accel_lsb_per_ms2))
    qx = q30_to_float(qi)
    d = np.degrees(orientation_errors(qx, qf)[:, 0])
    return float(np.sqrt(np.mean(d ** 2))), float(d.max()), qx


def test_simulated_motion_at_any_attitude():
    """Rest, a turn through 90° pitch, a heading turn across ±180°, random motion."""
    traj = concat(static((35, 0, 20), 5), turn((0, 1, 0), 120, 3, start_deg=(35, 0, 20)),
                  static((0, 0, 170), 3), turntable((0, 0, 1), 60, 2, start_deg=(0, 0, 170)),
                  random_motion(10, seed=2, max_rate_dps=300, max_acc=2))
    rms, peak, qx = difference_deg(*SENSOR.counts(traj), traj.dt)
    assert rms < 0.02 and peak < 0.1, (rms, peak)
    # and it tracks the truth (bias estimated at the first rest)
    e = np.degrees(orientation_errors(qx, traj.q)[:, 0])
    assert e[400:500].mean() < 1.0


def test_full_scale_and_zero_inputs():
    n = 300
    g = np.tile([32767, -32768, 32767], (n, 1))
    a = np.tile([-32768, 32767, -32768], (n, 1))
    m = np.tile([32760, -32760, 32760], (n, 1))
    a[100:150] = 0
    m[200:250] = 0
    q, b = flagship_fixed(g, a, m, FlagshipFixedConfig(0.01, SCALES.gyro_lsb_per_rad,
                                                       SCALES.accel_lsb_per_ms2))
    norms = np.linalg.norm(q30_to_float(q), axis=1)
    assert np.all(np.abs(norms - 1) < 1e-3)                   # stays a rotation


RECORDINGS = sorted(glob.glob("../shared/data/broad/*.hdf5")) or sorted(glob.glob(
    str(pathlib.Path(__file__).resolve().parents[3] / "shared/data/broad/*.hdf5")))


@pytest.mark.skipif(not RECORDINGS, reason="shared/data/broad not beside the checkout")
def test_recorded_stretch():
    rec = load_broad(RECORDINGS[1])
    gc, ac, mc = quantise(rec.gyr[:8000], rec.acc[:8000], rec.mag[:8000], SCALES)
    rms, peak, _ = difference_deg(gc, ac, mc, rec.dt)
    assert rms < 0.02 and peak < 0.05, (rms, peak)
