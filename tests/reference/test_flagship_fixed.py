"""The fixed-point flagship against the float flagship: simulated motion at any attitude, a
recorded stretch, full-scale and zero inputs."""

import glob
import pathlib

import numpy as np
import pytest

from mpu9250_ahrs.reference.flagship import flagship_filter
from mpu9250_ahrs.hdl.contract.numeric_contract import FlagshipFixedConfig
from mpu9250_ahrs.reference.flagship_fixed import flagship_fixed, q30_to_float
from mpu9250_ahrs.reference.frames import orientation_errors
from mpu9250_ahrs.sim.models.motion import (SensorModel, concat, random_motion, static, turn,
    turntable)
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


@pytest.mark.skipif(not RECORDINGS, reason="shared/data/broad not beside the checkout")
def test_recorded_stretch_with_the_field_at_100_hz():
    """As on the board: the AK8963's new fields at 100 Hz of the recording's time (one sample
    in about three at 286 Hz), the heading's and the reference's gains set for that period
    (``mag_dt``): the fixed flagship still follows the float one."""
    from mpu9250_ahrs.hdl.contract.numeric_contract import mag_period
    rec = load_broad(RECORDINGS[1])
    n = 8000
    gc, ac, mc = quantise(rec.gyr[:n], rec.acc[:n], rec.mag[:n], SCALES)
    valid = np.diff(np.floor(np.arange(n + 1) * rec.dt * 100)) > 0
    mag_dt = mag_period(rec.dt)
    assert mag_dt == 0.01 and 0.3 < valid.mean() < 0.4
    qf = flagship_filter(*to_units(gc, ac, mc, SCALES), rec.dt, mag_valid=valid, mag_dt=mag_dt)
    qi, _ = flagship_fixed(gc, ac, mc, FlagshipFixedConfig(rec.dt, SCALES.gyro_lsb_per_rad,
                                                           SCALES.accel_lsb_per_ms2,
                                                           mag_dt=mag_dt), mag_valid=valid)
    d = np.degrees(orientation_errors(q30_to_float(qi), qf)[:, 0])
    assert np.sqrt(np.mean(d ** 2)) < 0.02 and d.max() < 0.05


@pytest.mark.parametrize("odr, field_period", [(1000, 0.01), (8000, 0.01), (200, 0.01),
                                              (100, 0.01), (50, 0.02)])
def test_the_magnetometer_gains_follow_its_own_rate(odr, field_period):
    """Issue #26: the board's flagship registers (``default_flagship_config``) set the heading's
    and the reference's gains for the AK8963's period (10 ms), not the sample period: their
    time constants are ``tau_mag`` and ``tau_ref`` seconds at any rate (at 1 kHz they were ten
    times that). A rate slower than the AK8963's brings a new field every sample."""
    import math
    from mpu9250_ahrs.hdl.engine.attitude_engine import default_flagship_config
    from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
    from mpu9250_ahrs.hdl.contract.numeric_contract import FlagshipParams, svf_gain
    p = FlagshipParams()
    regs = default_flagship_config(MPU9250Config.for_odr(odr)).registers()
    q30 = lambda tau, t: int(round((1 - math.exp(-t / tau)) * 2 ** 30))
    assert regs["A_MAG"] == q30(p.tau_mag, field_period)
    assert regs["A_MAG_FAST"] == q30(min(p.tau_mag, 0.2), field_period)
    assert regs["A_REF"] == q30(p.tau_ref, field_period)
    # every sample: the sample period (the inclination's second-order low-pass)
    assert regs["A_ACC"] == int(round(svf_gain(p.tau_acc, 1 / odr) * 2 ** 30))
    without = default_flagship_config(MPU9250Config.for_odr(odr, magnetometer=False))
    assert without.registers()["A_MAG"] == q30(p.tau_mag, 1 / odr)
