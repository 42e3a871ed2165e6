"""Bit-exact fixed-point golden models: what the gateware will compute, in integers.

Written directly from the formats in ``reference/FIXED_POINT.md`` (not by interpreting any
gateware); every rounding, saturation and iteration count is here and there. Python integers
model the hardware registers; widths are checked with ``_fits`` where a register ends.

Primitives
    ``rshift_round(x, n)``: x / 2ⁿ rounded half up (add 2ⁿ⁻¹, arithmetic shift right).
    ``sat(x, bits)``: clamp to a signed ``bits``-bit range.
    ``wrap32(x)``: two's-complement wrap to 32 bits (angles in BAM32).
    ``div_trunc(num, den, frac)``: (num·2^frac)/den truncated towards zero (restoring divider).
    ``cordic_vector(x, y)``: atan2(y, x) in BAM32 and √(x²+y²)·K, ``CORDIC_ITERATIONS`` steps.
    ``cordic_rotate(angle)``: (cos, sin) of a BAM32 angle in Q1.30.

Filters (inputs are raw sensor counts, body axes; magnetometer already mapped from AK8963 axes)
    ``kalman_fixed``: the per-axis Kalman filter with body rates (the published form).
    ``complementary_fixed``: the complementary filter with body rates.
"""

import math
from dataclasses import dataclass

import numpy as np


__all__ = ["BAM_BITS", "CORDIC_ITERATIONS", "ATAN_TABLE", "CORDIC_GAIN", "rshift_round", "sat",
           "wrap32", "div_trunc", "cordic_vector", "cordic_rotate", "bam_to_deg", "deg_to_bam",
           "KalmanFixedConfig", "kalman_fixed", "complementary_fixed"]

BAM_BITS = 32                     # angles: signed 32-bit, 2³² = 360°, 1 LSB = 8.38e-8°
CORDIC_ITERATIONS = 24
# atan(2⁻ⁱ) in BAM32, rounded to nearest: the ROM of the CORDIC.
ATAN_TABLE = tuple(int(round(math.atan(2.0 ** -i) / (2 * math.pi) * 2 ** 32))
                   for i in range(CORDIC_ITERATIONS))
CORDIC_GAIN = math.prod(math.sqrt(1 + 2.0 ** (-2 * i)) for i in range(CORDIC_ITERATIONS))
Q30 = 1 << 30
# 1/K in Q1.30 (rounded): rotation mode starts from (1/K, 0) so cos/sin come out unscaled;
# vectoring magnitudes are multiplied by it when the true length is needed.
INV_GAIN_Q30 = int(round(Q30 / CORDIC_GAIN))


def rshift_round(x, n):
    return (x + (1 << (n - 1))) >> n if n > 0 else x


def sat(x, bits):
    hi = (1 << (bits - 1)) - 1
    return max(-hi - 1, min(hi, x))


def wrap32(x):
    return ((x + (1 << 31)) & 0xFFFFFFFF) - (1 << 31)


def div_trunc(num, den, frac):
    """(num · 2^frac) / den, truncated towards zero; den > 0."""
    if den <= 0:
        raise ZeroDivisionError("div_trunc needs a positive denominator")
    q = (abs(num) << frac) // den
    return -q if num < 0 else q


def bam_to_deg(a):
    return np.asarray(a, float) * (360.0 / 2 ** 32)


def deg_to_bam(d):
    return wrap32(int(round(d / 360.0 * 2 ** 32)))


def cordic_vector(x, y):
    """Vectoring CORDIC: (atan2(y, x) in BAM32, magnitude · K). Inputs are integers of up to 30
    bits; the vector is first turned into the right half-plane (±180° as needed)."""
    if x == 0 and y == 0:
        return 0, 0                              # zero vector: angle 0 by definition
    # Left half-plane: turn the vector by 180°; adding 2³¹ (180°) and wrapping gives the angle.
    angle = 0
    if x < 0:
        x, y, angle = -x, -y, 1 << 31
    for i in range(CORDIC_ITERATIONS):
        if y > 0:
            x, y = x + (y >> i), y - (x >> i)
            angle += ATAN_TABLE[i]
        else:
            x, y = x - (y >> i), y + (x >> i)
            angle -= ATAN_TABLE[i]
    return wrap32(angle), x


def cordic_rotate(angle):
    """(cos, sin) of a BAM32 angle, Q1.30, by rotation-mode CORDIC from (1/K, 0)."""
    angle = wrap32(angle)
    flip = False
    if angle > (1 << 30) or angle < -(1 << 30):          # beyond ±90°: rotate by 180° first
        angle = wrap32(angle + (1 << 31))
        flip = True
    x, y, z = INV_GAIN_Q30, 0, angle
    for i in range(CORDIC_ITERATIONS):
        if z >= 0:
            x, y, z = x - (y >> i), y + (x >> i), z - ATAN_TABLE[i]
        else:
            x, y, z = x + (y >> i), y - (x >> i), z + ATAN_TABLE[i]
    return (-x, -y) if flip else (x, y)


# -- filters -----------------------------------------------------------------------------------

@dataclass(frozen=True)
class KalmanFixedConfig:
    """Run-time registers of the per-axis Kalman filter (values in real units; ``registers``
    gives their integer encodings, see FIXED_POINT.md)."""
    dt: float = 0.01
    gyro_lsb_per_dps: float = 16.4
    q_angle: float = 0.2         # deg²
    q_bias: float = 0.1          # (deg/s)²
    r: float = 2.0               # deg²
    p0: float = 1.0

    def registers(self):
        q24 = 1 << 24
        return {
            # BAM per (count·step), Q16: Δθ = (ω_counts · RATE) >> 16, for the sum of two
            # samples (the trapezoidal average's /2 is folded in).
            "RATE": int(round(self.dt * 2 ** 32 / (360.0 * self.gyro_lsb_per_dps) / 2 * 2 ** 16)),
            "T": int(round(self.dt * q24)),                          # Q0.24 seconds
            "Q_ANGLE": int(round(self.q_angle * q24)),               # Q8.24 deg²
            "Q_BIAS": int(round(self.q_bias * q24)),                 # Q8.24 (deg/s)²
            "R": int(round(self.r * q24)),                           # Q8.24 deg²
            "P0": int(round(self.p0 * q24)),
            # counts per BAM-degree product: Δb_counts(Q16) = (K1 · y_BAM · BIAS_SCALE) >> …
            "BIAS_SCALE": int(round(360.0 / 2 ** 32 * self.gyro_lsb_per_dps * 2 ** 40)),
        }


def _tilt(ax, ay, az):
    """(roll, pitch) BAM32 from accelerometer counts: atan2(ay, az), atan2(−ax, √(ay²+az²))."""
    roll, mag_k = cordic_vector(az << 8, ay << 8)
    horiz = rshift_round(mag_k * INV_GAIN_Q30, 30)       # √(ay²+az²)·2⁸, K removed
    pitch, _ = cordic_vector(horiz, -ax << 8)
    return roll, pitch


def _heading(mx, my, mz, roll, pitch):
    """Tilt-compensated heading, BAM32, from body-frame field counts and the filter's tilt."""
    cr, sr = cordic_rotate(roll)
    cp, sp = cordic_rotate(pitch)
    # products of Q1.30 trig values with 16-bit counts: keep 12 fractional bits (counts · 2¹²,
    # at most 30 bits for the three-term sum, so the CORDIC's growth fits 32)
    hx = rshift_round(cp * mx + rshift_round(sp * sr, 30) * my + rshift_round(sp * cr, 30) * mz, 18)
    hy = rshift_round(cr * my - sr * mz, 18)
    angle, _ = cordic_vector(hy, hx)              # atan2(hx, hy): East of North is positive
    return angle


def kalman_fixed(gyr_counts, acc_counts, mag_counts, config=KalmanFixedConfig(), *,
                 mag_valid=None):
    """Per-axis Kalman filter in integers. Returns (angles BAM32 (N,3), bias Q16.16 counts
    (N,3)). Formats and steps: FIXED_POINT.md, section "Per-axis Kalman filter"."""
    reg = config.registers()
    RATE, T, QA, QB, R, BS = (reg[k] for k in ("RATE", "T", "Q_ANGLE", "Q_BIAS", "R",
                                               "BIAS_SCALE"))
    gyr = np.asarray(gyr_counts, np.int64).tolist()
    acc = np.asarray(acc_counts, np.int64).tolist()
    mag = np.asarray(mag_counts, np.int64).tolist()
    n = len(gyr)
    valid = [True] * n if mag_valid is None else [bool(v) for v in mag_valid]
    theta = [0, 0, 0]
    bias = [0, 0, 0]                              # Q16.16 gyro counts
    P = [[reg["P0"], 0, 0, reg["P0"]] for _ in range(3)]
    prev = gyr[0]
    out_theta = np.empty((n, 3), np.int64)
    out_bias = np.empty((n, 3), np.int64)
    for k in range(n):
        g = gyr[k]
        for i in range(3):
            # predict: θ += ((ω_{k−1} + ω_k)·2¹⁶ − 2b) · RATE >> 32
            u = ((prev[i] + g[i]) << 16) - 2 * bias[i]
            theta[i] = wrap32(theta[i] + rshift_round(u * RATE, 32))
            p00, p01, p10, p11 = P[i]
            tp11 = rshift_round(T * p11, 24)
            n00 = p00 - rshift_round(T * (p10 + p01), 24) + rshift_round(T * tp11, 24) + QA
            P[i] = [n00, p01 - tp11, p10 - tp11, p11 + QB]
        prev = g
        roll_m, pitch_m = _tilt(*acc[k])
        yaw_m = _heading(*mag[k], theta[0], theta[1])
        # A zero vector (free fall, a dead magnetometer) has no direction: no update.
        acc_ok = any(acc[k])
        use = (acc_ok, acc_ok, valid[k] and any(mag[k]))
        for i, z in enumerate((roll_m, pitch_m, yaw_m)):
            if not use[i]:
                continue
            p00, p01, p10, p11 = P[i]
            s = p00 + R
            k0 = div_trunc(p00, s, 24)            # Q0.24
            k1 = div_trunc(p10, s, 24)            # Q8.24, 1/s
            y = wrap32(z - theta[i])              # BAM32 innovation
            theta[i] = wrap32(theta[i] + rshift_round(k0 * y, 24))
            # bias (Q16 counts) += k1 [1/s] · y [deg] · LSB/(deg/s)
            bias[i] += rshift_round(k1 * y * BS, 48)
            P[i] = [p00 - rshift_round(k0 * p00, 24), p01 - rshift_round(k0 * p01, 24),
                    p10 - rshift_round(k1 * p00, 24), p11 - rshift_round(k1 * p01, 24)]
        out_theta[k] = theta
        out_bias[k] = bias
    return out_theta, out_bias


def complementary_fixed(gyr_counts, acc_counts, mag_counts, *, dt, a, gyro_lsb_per_dps=16.4,
                        mag_valid=None):
    """Complementary filter in integers: θ = pred + (1 − a)·wrap(meas − pred), pred = θ + ω·dt.
    ``a`` is held as A_Q24 = round((1 − a)·2²⁴). Returns angles BAM32 (N,3)."""
    one_minus_a = int(round((1 - a) * (1 << 24)))
    rate = int(round(dt * 2 ** 32 / (360.0 * gyro_lsb_per_dps) * 2 ** 16))   # BAM/count, Q16
    gyr = np.asarray(gyr_counts, np.int64).tolist()
    acc = np.asarray(acc_counts, np.int64).tolist()
    mag = np.asarray(mag_counts, np.int64).tolist()
    n = len(gyr)
    valid = [True] * n if mag_valid is None else [bool(v) for v in mag_valid]
    theta = [0, 0, 0]
    out = np.empty((n, 3), np.int64)
    for k in range(n):
        pred = [wrap32(theta[i] + rshift_round(gyr[k][i] * rate, 16)) for i in range(3)]
        roll_m, pitch_m = _tilt(*acc[k]) if any(acc[k]) else (pred[0], pred[1])
        meas = [roll_m, pitch_m,
                _heading(*mag[k], pred[0], pred[1]) if valid[k] and any(mag[k]) else pred[2]]
        theta = [wrap32(pred[i] + rshift_round(one_minus_a * wrap32(meas[i] - pred[i]), 24))
                 for i in range(3)]
        out[k] = theta
    return out
