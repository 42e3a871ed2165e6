"""Soak of the per-axis filters at the sensor's own rates: the fixed-point Kalman filter (the
engine's, bit for bit) against the float filter over a long synthetic motion.

    python -m mpu9250_ahrs.reference.soak --rate 1000 --samples 1000000
    python -m mpu9250_ahrs.reference.soak --rate 8000 --samples 1000000

The coefficients are ``FilterRates`` (physical units) converted at the rate, as ``build`` does.
The motion: roll and pitch wander within about ±50°, yaw turns through every heading, with a
drifting gyro bias and sensor noise, quantised to MPU9250/AK8963 counts (±2000 °/s, ±16 g);
the field is new at the AK8963's 100 Hz. Prints one JSON line: samples, results with
``saturated``, the largest and RMS angle difference fixed − float (degrees, each axis, every
sample), and the time taken. A benchmark, not a test: ``tests/reference`` runs a short one.
"""

import argparse
import json
import sys
import time

import numpy as np

from .entry_point import count, positive, run_main
from ..hdl.contract.numeric_contract import FilterRates
from .fixed_point import Status, _KalmanFixed, bam_to_deg
from .kalman import KalmanParams, kalman_filter


__all__ = ["synthetic_motion", "soak"]

GYRO_LSB_PER_DPS = 16.4             # ±2000 °/s
ACCEL_LSB_PER_G = 2048.0            # ±16 g
MAG_UT_PER_LSB = 0.15


def synthetic_motion(n, rate, seed=0, *, with_up=False):
    """(gyro counts, accel counts, mag counts (body axes), mag_valid) for ``n`` samples; with
    ``with_up`` also the true "up" direction in body axes per sample (N, 3), unit vectors."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    # Euler angles as sums of slow sinusoids with random phases
    def wander(amp, periods):
        phases = rng.uniform(0, 2 * np.pi, len(periods))
        return sum(amp / len(periods) * np.sin(2 * np.pi * t / p + ph)
                   for p, ph in zip(periods, phases))
    roll = np.radians(wander(50.0, (7.0, 23.0, 61.0)))
    pitch = np.radians(wander(45.0, (11.0, 29.0, 83.0)))
    yaw = np.radians(wander(300.0, (37.0, 97.0)))
    d = [np.gradient(a, 1 / rate) for a in (roll, pitch, yaw)]
    sr, cr, sp, cp = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch)
    # body rates from Euler rates (ZYX)
    wx = d[0] - sp * d[2]
    wy = cr * d[1] + sr * cp * d[2]
    wz = -sr * d[1] + cr * cp * d[2]
    bias = np.cumsum(rng.normal(0, 0.002, (n, 3)), axis=0) / np.sqrt(rate) + 0.5   # °/s
    gyro_dps = np.degrees(np.stack([wx, wy, wz], 1)) + bias + rng.normal(0, 0.1, (n, 3))
    # specific force at rest: gravity in body axes (g), plus noise
    acc = np.stack([-sp, sr * cp, cr * cp], 1) + rng.normal(0, 0.01, (n, 3))
    # Earth's field (µT: north 20, down 45) rotated into body axes
    sy, cy = np.sin(yaw), np.cos(yaw)
    north, down = 20.0, 45.0
    # world (x north, y east, z down) -> body: R = Rx(roll)ᵀ Ry(pitch)ᵀ Rz(yaw)ᵀ
    bx = cp * cy * north - sp * down
    by = (sr * sp * cy - cr * sy) * north + sr * cp * down
    bz = (cr * sp * cy + sr * sy) * north + cr * cp * down
    mag = np.stack([bx, by, bz], 1) + rng.normal(0, 0.3, (n, 3))
    gc = np.clip(np.round(gyro_dps * GYRO_LSB_PER_DPS), -32768, 32767).astype(np.int64)
    ac = np.clip(np.round(acc * ACCEL_LSB_PER_G), -32768, 32767).astype(np.int64)
    mc = np.clip(np.round(mag / MAG_UT_PER_LSB), -32768, 32767).astype(np.int64)
    every = max(1, int(round(rate / 100)))
    mag_valid = (np.arange(n) % every) == 0
    if with_up:
        return gc, ac, mc, mag_valid, np.stack([-sp, sr * cp, cr * cp], 1)
    return gc, ac, mc, mag_valid


def soak(n, rate, rates=FilterRates(), seed=0):
    """Run both filters over ``synthetic_motion``; a dict of figures."""
    gc, ac, mc, mag_valid = synthetic_motion(n, rate, seed)
    config = rates.at(1 / rate, GYRO_LSB_PER_DPS)
    start = time.perf_counter()
    kf = _KalmanFixed(config)
    fixed = np.empty((n, 3))
    saturated = 0
    gl, al, ml, vl = gc.tolist(), ac.tolist(), mc.tolist(), mag_valid.tolist()
    import sys
    from tqdm import tqdm
    # progress on stderr, on a terminal only: 10^6 samples take a minute or two
    for k in tqdm(range(n), desc="soak (integer filter)", unit="sample", file=sys.stderr,
                  leave=False, disable=not sys.stderr.isatty(), mininterval=0.5,
                  miniters=10_000):
        st = Status()
        kf.step(gl[k], al[k], ml[k], vl[k], st)
        saturated += bool(st.saturated)
        fixed[k] = kf.theta
    fixed_s = time.perf_counter() - start
    fixed = (bam_to_deg(fixed) + 180.0) % 360.0 - 180.0
    params = KalmanParams(q_angle=config.q_angle, q_bias=config.q_bias, r=config.r,
                          p0=config.p0)
    start = time.perf_counter()
    euler = kalman_filter(gc / GYRO_LSB_PER_DPS, ac / ACCEL_LSB_PER_G, mc * MAG_UT_PER_LSB,
                          1 / rate, params, mag_valid=mag_valid)[0]
    float_s = time.perf_counter() - start
    diff = np.abs((fixed - euler + 180.0) % 360.0 - 180.0)
    return {"rate_hz": rate, "samples": n, "saturated_results": saturated,
            "max_diff_deg": [round(float(v), 5) for v in diff.max(0)],
            "rms_diff_deg": [round(float(v), 5) for v in np.sqrt((diff ** 2).mean(0))],
            "worst_sample": int(diff.max(1).argmax()),
            "registers": config.registers(), "fixed_s": round(fixed_s, 1),
            "float_s": round(float_s, 1)}


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m mpu9250_ahrs.reference.soak",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("--rate", type=positive, default=1000.0, help="sample rate, Hz (1000)")
    p.add_argument("--samples", type=count, default=1_000_000, help="samples (10⁶)")
    p.add_argument("--seed", type=int, default=0, help="the simulated motion's seed (0)")
    args = p.parse_args(argv)
    result = soak(args.samples, args.rate, seed=args.seed)
    print(json.dumps(result))
    return 0 if result["saturated_results"] == 0 and max(result["max_diff_deg"]) <= 0.05 else 1


if __name__ == "__main__":
    sys.exit(run_main("python -m mpu9250_ahrs.reference.soak", main))
