"""Bit-exact fixed-point golden models: what the gateware will compute, in integers.

Written directly from the formats in ``reference/FIXED_POINT.md`` (not by interpreting any
gateware); every rounding, saturation and iteration count is here and there. Python integers
model the hardware registers; widths are checked with ``_fits`` where a register ends.

Every value is a 32-bit signed register, every multiply a 32×32 product into a wide
accumulator, rounded and saturated back to 32 bits: the operations the shared datapath of the
gateware performs (``Status`` records whether any saturation happened).

Primitives
    ``rshift_round(x, n)``: x / 2ⁿ rounded half up (add 2ⁿ⁻¹, arithmetic shift right).
    ``sat(x, bits)``: clamp to a signed ``bits``-bit range.
    ``wrap32(x)``: two's-complement wrap to 32 bits (angles in BAM32).
    ``div_floor(num, den, frac)``: ⌊num·2^frac / den⌋, rounded towards −∞ (restoring divider).
    ``div_q24(num, den)``: the datapath's divider: div_floor(num, den, 24) saturated to 32 bits,
    0 for den ≤ 0.
    ``cordic_vector(x, y)``: atan2(y, x) in BAM32 and √(x²+y²)·K, ``CORDIC_ITERATIONS`` steps.
    ``cordic_rotate(angle)``: (cos, sin) of a BAM32 angle in Q1.30.

Stages (inputs are raw sensor counts)
    ``calibrate_fixed``: gyro offset, accelerometer offset and scale, AK8963 ASA, axis mapping,
    hard- and soft-iron: raw counts -> body-axis counts.
    ``kalman_fixed``: the per-axis Kalman filter with body rates (the published form).
    ``complementary_fixed``: the complementary filter with body rates.
The engine as a whole (calibration then the selected filter, per sample, with the status
flags: what the gateware's attitude engine outputs) is ``reference/engine_model.py``
(``EngineModel``, ``attitude_fixed``), built from these and ``reference/flagship_fixed.py``.
"""

import math

import numpy as np

# the register encodings are the gateware's contract; the CORDIC table below is computed here,
# independently of the one the gateware holds (a test checks that they agree)
from ..hdl.contract.numeric_contract import CalibrationFixed, KalmanFixedConfig


__all__ = ["CORDIC_ITERATIONS", "CORDIC_SHORT_ITERATIONS", "ATAN_TABLE", "CORDIC_GAIN",
           "rshift_round", "sat",
           "wrap32", "div_floor", "cordic_vector", "cordic_rotate", "bam_to_deg", "deg_to_bam",
           "div_q24", "Status", "calibrate_fixed", "kalman_fixed", "complementary_fixed",
           "euler_rates_fixed", "step_n", "COS_PITCH_MIN", "tilt_angles",
           "mul", "mac", "sat32", "sat16"]
# (the register configurations it uses are the contract's, imported from there by everyone:
# ``hdl/contract/numeric_contract.py``)

# 16 iterations leave at most atan(2⁻¹⁵) = 0.0018° of angle: far below the sensors' noise, and
# a shift amount of 4 bits and a 16-entry table in the gateware
CORDIC_ITERATIONS = 16
# A vectoring CORDIC whose angle is not wanted (a length) may stop after 8 iterations: the
# vector is then within atan(2⁻⁷) of the x axis, so its x is the length times K to 3·10⁻⁵
# (K₈ is K's to 10⁻⁵); the engine's short VEC, 8 cycles quicker.
CORDIC_SHORT_ITERATIONS = 8
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


def div_floor(num, den, frac):
    """⌊num · 2^frac / den⌋ (rounded towards −∞); den > 0. Floor rather than truncation because
    the gateware then needs no negation: for num < 0 it divides ~num (with ones shifted in)
    and inverts the quotient, as ⌊N/d⌋ = ~⌊~N/d⌋."""
    if den <= 0:
        raise ZeroDivisionError("div_floor needs a positive denominator")
    return (num << frac) // den


def div_q24(num, den, status=None):
    """The datapath's divider: ⌊num·2²⁴/den⌋ (towards −∞), saturated to 32 bits; a
    denominator ≤ 0 gives 0 (and counts as a saturation)."""
    if den <= 0:
        if status is not None:
            status.saturated = True
        return 0
    return sat32(div_floor(num, den, 24), status)


class Status:
    """Sticky per-sample flag: did any result saturate?"""
    def __init__(self):
        self.saturated = False


def sat32(x, status=None):
    y = sat(x, 32)
    if status is not None and y != x:
        status.saturated = True
    return y


def sat16(x, status=None):
    y = sat(x, 16)
    if status is not None and y != x:
        status.saturated = True
    return y


def mul(a, b, shift, status=None):
    """sat32(rshift_round(a·b, shift)): one multiply of the datapath."""
    return sat32(rshift_round(a * b, shift), status)


# Euler-angle rates (``KalmanFixedConfig.euler_rates``): cos(pitch) is held at least this
# (Q1.30, cos 89.55°), so that tan(pitch) and 1/cos(pitch) stay inside Q8.24
COS_PITCH_MIN = 1 << 23


def euler_rates_fixed(u, theta, st=None):
    """Body rates ``u`` (three words of any one format) -> the Euler-angle rates of the ZYX
    angles ``theta`` (BAM32), in the same format: φ̇ = p + w·tan θ, θ̇ = q·cos φ − r·sin φ,
    ψ̇ = w / cos θ, w = q·sin φ + r·cos φ. The engine's steps: two rotations, cos θ held at
    ``COS_PITCH_MIN`` or above, two divisions (Q8.24), two MACs, two MULs and an ADD."""
    cr, sr = cordic_rotate(theta[0])
    cp, sp = cordic_rotate(theta[1])
    if sat32(cp - COS_PITCH_MIN, st) < 0:
        cp = COS_PITCH_MIN
    tp, sec = div_q24(sp, cp, st), div_q24(1 << 30, cp, st)
    w = mac([(sr, u[1]), (cr, u[2])], 30, st)
    pitch_rate = mac([(cr, u[1]), (sr, u[2], -1)], 30, st)
    return [sat32(u[0] + mul(w, tp, 24, st), st), pitch_rate, mul(w, sec, 24, st)]


def step_n(coefficient, periods, status=None):
    """A per-period rotation coefficient (RATE, K_RAD) times the sample periods since the
    previous sample (1 + ``Sample.skipped``): the engine's two MULs, (n·2²⁸ >> 14), then
    (c · n·2¹⁴ >> 14), exact unless the product leaves 32 bits (then saturated)."""
    return mul(coefficient, mul(periods, 1 << 28, 14, status), 14, status)


def mac(terms, shift, status=None):
    """sat32(rshift_round(Σ ±aᵢ·bᵢ, shift)): products summed exactly in the accumulator, one
    rounding at the end. ``terms``: (a, b) or (a, b, -1) for a subtracted product."""
    acc = sum(t[0] * t[1] * (t[2] if len(t) > 2 else 1) for t in terms)
    return sat32(rshift_round(acc, shift), status)


def bam_to_deg(a):
    return np.asarray(a, float) * (360.0 / 2 ** 32)


def deg_to_bam(d):
    return wrap32(int(round(d / 360.0 * 2 ** 32)))


def cordic_vector(x, y, status=None, iterations=CORDIC_ITERATIONS):
    """Vectoring CORDIC: (atan2(y, x) in BAM32, magnitude · K saturated to 32 bits). Inputs are
    32-bit integers (the gateware iterates on 34 bits, so nothing overflows inside); the vector
    is first turned into the right half-plane (±180° as needed) by inverting its bits, −v − 1
    rather than −v: one LSB off, and no adder in the gateware. ``iterations``:
    ``CORDIC_SHORT_ITERATIONS`` for the engine's short VEC (a length: its angle is coarse)."""
    if x == 0 and y == 0:
        return 0, 0                              # zero vector: angle 0 by definition
    # Left half-plane: turn the vector by 180°; adding 2³¹ (180°) and wrapping gives the angle.
    angle = 0
    if x < 0:
        x, y, angle = ~x, ~y, 1 << 31
    for i in range(iterations):
        if y >= 0:                               # a sign test, no zero test
            x, y = x + (y >> i), y - (x >> i)
            angle += ATAN_TABLE[i]
        else:
            x, y = x - (y >> i), y + (x >> i)
            angle -= ATAN_TABLE[i]
    return wrap32(angle), sat32(x, status)


def cordic_rotate(angle):
    """(cos, sin) of a BAM32 angle, Q1.30, by rotation-mode CORDIC from (1/K, 0); beyond ±90°
    the angle is turned by 180° and the start vector is (−1/K, 0) instead (no negation of the
    results needed)."""
    angle = wrap32(angle)
    x0 = INV_GAIN_Q30
    if angle > (1 << 30) or angle < -(1 << 30):
        angle = wrap32(angle + (1 << 31))
        x0 = -INV_GAIN_Q30
    x, y, z = x0, 0, angle
    for i in range(CORDIC_ITERATIONS):
        if z >= 0:
            x, y, z = x - (y >> i), y + (x >> i), z - ATAN_TABLE[i]
        else:
            x, y, z = x + (y >> i), y - (x >> i), z + ATAN_TABLE[i]
    return x, y


# -- calibration (``CalibrationFixed``: hdl/contract/numeric_contract.py)
# ----------------------------------

def _calibrate_one(g, a, h, asa, cal, st):
    """One sample: raw gyro/accel counts, raw AK8963 counts (AK axes), raw ASA fuse bytes."""
    gc = [sat16(sat32(g[i] - cal.gyro_offset[i], st), st) for i in range(3)]
    ac = [sat16(mul(sat32(a[i] - cal.accel_offset[i], st), cal.accel_scale[i], 14, st), st)
          for i in range(3)]
    adj = [mul(h[j], asa[j] + 128, 8, st) for j in range(3)]          # ASA: ·(ASA + 128)/256
    # AK8963 -> body axes: x_b = y_ak, y_b = x_ak, z_b = −z_ak; then the hard-iron offset
    d = [sat32(adj[1] - cal.hard_iron[0], st), sat32(adj[0] - cal.hard_iron[1], st),
         sat32(sat32(-adj[2], st) - cal.hard_iron[2], st)]
    s = cal.soft_iron
    mc = [sat16(mac([(s[3 * i + j], d[j]) for j in range(3)], 14, st), st) for i in range(3)]
    return gc, ac, mc


def calibrate_fixed(gyr_raw, acc_raw, mag_ak_raw, asa=(128, 128, 128), cal=CalibrationFixed()):
    """Raw counts -> calibrated body-axis counts (gyro, accel, mag), each (N, 3) int."""
    out = [np.empty((len(gyr_raw), 3), np.int64) for _ in range(3)]
    for k, (g, a, h) in enumerate(zip(*(np.asarray(x, np.int64).tolist()
                                         for x in (gyr_raw, acc_raw, mag_ak_raw)))):
        for o, v in zip(out, _calibrate_one(g, a, h, asa, cal, Status())):
            o[k] = v
    return tuple(out)


# -- filters (their registers: ``KalmanFixedConfig``, ``FilterRates`` in
# hdl/contract/numeric_contract.py)

def tilt_angles(x, y, z, st=None):
    """(roll, pitch) BAM32 of a specific-force vector in any scale: atan2(y, z),
    atan2(−x, √(y² + z²))."""
    roll, mag_k = cordic_vector(z, y, st)
    horiz = mul(mag_k, INV_GAIN_Q30, 30, st)             # √(y² + z²), K removed
    pitch, _ = cordic_vector(horiz, sat32(-x, st), st)
    return roll, pitch


def _tilt(ax, ay, az, st=None):
    """(roll, pitch) BAM32 from accelerometer counts, scaled by 2⁸ for the CORDIC."""
    return tilt_angles(ax << 8, ay << 8, az << 8, st)


def _heading(mx, my, mz, roll, pitch, st=None):
    """Tilt-compensated heading, BAM32, from body-frame field counts and the filter's tilt."""
    cr, sr = cordic_rotate(roll)
    cp, sp = cordic_rotate(pitch)
    # Q1.30 trig · 16-bit counts, 12 fractional bits kept: |hx| < 3·2²⁷, inside the CORDIC's
    # ±2²⁹ comfort zone
    spsr, spcr = mul(sp, sr, 30, st), mul(sp, cr, 30, st)
    hx = mac([(cp, mx), (spsr, my), (spcr, mz)], 18, st)
    hy = mac([(cr, my), (sr, mz, -1)], 18, st)
    angle, _ = cordic_vector(hy, hx, st)          # atan2(hx, hy): East of North is positive
    return angle


class _KalmanFixed:
    """State and one step of the per-axis Kalman filter in integers."""

    def __init__(self, config, overrides=None):
        self.reg = {**config.registers(), **(overrides or {})}
        self.theta = [0, 0, 0]
        self.bias = [0, 0, 0]                     # Q16.16 gyro counts
        self.P = [[self.reg["P0"], 0, 0, self.reg["P0"]] for _ in range(3)]
        self.prev = None

    def predict(self, g, st, periods=1):
        RATE, T, QA, QB = (self.reg[k] for k in ("RATE", "T", "Q_ANGLE", "Q_BIAS"))
        # the rotation covers every period since the last sample; the covariance one period
        RATE = step_n(RATE, periods, st)
        prev = g if self.prev is None else self.prev
        # the mean rate (ω_{k−1} + ω_k)/2 in Q16 counts, as Euler-angle rates if asked
        mean = [sat32((prev[i] + g[i]) << 15, st) for i in range(3)]
        if self.reg["EULER_RATES"]:
            mean = euler_rates_fixed(mean, self.theta, st)
        for i in range(3):
            # u = mean − b; θ += u·RATE >> 30
            u = sat32(mean[i] - self.bias[i], st)
            self.theta[i] = wrap32(self.theta[i] + mul(u, RATE, 30, st))
            p00, p01, p10, p11 = self.P[i]
            tp11 = mul(T, p11, 24, st)
            x = sat32(sat32(tp11 - p10, st) - p01, st)
            n00 = sat32(sat32(p00 + mul(T, x, 24, st), st) + QA, st)
            self.P[i] = [n00, sat32(p01 - tp11, st), sat32(p10 - tp11, st), sat32(p11 + QB, st)]
        self.prev = list(g)

    def update(self, i, z, st):
        R, BS = self.reg["R"], self.reg["BIAS_SCALE"]
        p00, p01, p10, p11 = self.P[i]
        s = sat32(p00 + R, st)
        k0, k1 = div_q24(p00, s, st), div_q24(p10, s, st)     # Q0.24, Q8.24 (1/s)
        y = wrap32(z - self.theta[i])                          # BAM32 innovation
        self.theta[i] = wrap32(self.theta[i] + mul(k0, y, 24, st))
        t = mul(k1, y, 24, st)                                 # BAM/s
        self.bias[i] = sat32(self.bias[i] + mul(t, BS, 24, st), st)
        self.P[i] = [sat32(p00 - mul(k0, p00, 24, st), st), sat32(p01 - mul(k0, p01, 24, st), st),
                     sat32(p10 - mul(k1, p00, 24, st), st), sat32(p11 - mul(k1, p01, 24, st), st)]

    def step(self, g, a, m, mag_ok, st, periods=1):
        self.predict(g, st, periods)
        acc_ok = any(a)
        mag_ok = bool(mag_ok) and any(m)
        # measurements after all three predicts: yaw is compensated with the predicted tilt
        roll_m, pitch_m = _tilt(*a, st) if acc_ok else (0, 0)
        yaw_m = _heading(*m, self.theta[0], self.theta[1], st) if mag_ok else 0
        for i, (use, z) in enumerate(((acc_ok, roll_m), (acc_ok, pitch_m), (mag_ok, yaw_m))):
            if use:
                self.update(i, z, st)
        return acc_ok, mag_ok


def _complementary_step(theta, g, a, m, mag_ok, reg, st, periods=1):
    """One complementary step on the shared angle registers; returns (θ, acc_ok, mag_ok)."""
    rate = step_n(reg["RATE"], periods, st)
    if reg["EULER_RATES"]:
        # in Q16 counts, so that the transform keeps the gyro's fractions
        u = euler_rates_fixed([mul(x, 1 << 30, 14, st) for x in g], theta, st)
        pred = [wrap32(theta[i] + mul(u[i], rate, 30, st)) for i in range(3)]
    else:
        pred = [wrap32(theta[i] + mul(g[i], rate, 14, st)) for i in range(3)]
    acc_ok = any(a)
    mag_ok = bool(mag_ok) and any(m)
    roll_m, pitch_m = _tilt(*a, st) if acc_ok else (pred[0], pred[1])
    meas = [roll_m, pitch_m, _heading(*m, pred[0], pred[1], st) if mag_ok else pred[2]]
    return [wrap32(pred[i] + mul(reg["ONE_MINUS_A"], wrap32(meas[i] - pred[i]), 24, st))
            for i in range(3)], acc_ok, mag_ok


def kalman_fixed(gyr_counts, acc_counts, mag_counts, config=KalmanFixedConfig(), *,
                 mag_valid=None):
    """Per-axis Kalman filter in integers on body-axis counts. Returns (angles BAM32 (N,3),
    bias Q16.16 counts (N,3)). Formats and steps: FIXED_POINT.md."""
    kf = _KalmanFixed(config)
    gyr, acc, mag = (np.asarray(x, np.int64).tolist() for x in (gyr_counts, acc_counts,
                                                                 mag_counts))
    n = len(gyr)
    valid = [True] * n if mag_valid is None else [bool(v) for v in mag_valid]
    out_theta = np.empty((n, 3), np.int64)
    out_bias = np.empty((n, 3), np.int64)
    for k in range(n):
        kf.step(gyr[k], acc[k], mag[k], valid[k], Status())
        out_theta[k] = kf.theta
        out_bias[k] = kf.bias
    return out_theta, out_bias


def complementary_fixed(gyr_counts, acc_counts, mag_counts, *, dt, a, gyro_lsb_per_dps=16.4,
                        mag_valid=None):
    """Complementary filter in integers: θ = pred + (1 − a)·wrap(meas − pred), pred = θ + ω·dt.
    Returns angles BAM32 (N,3)."""
    reg = KalmanFixedConfig(dt=dt, gyro_lsb_per_dps=gyro_lsb_per_dps, a=a).registers()
    gyr, acc, mag = (np.asarray(x, np.int64).tolist() for x in (gyr_counts, acc_counts,
                                                                 mag_counts))
    n = len(gyr)
    valid = [True] * n if mag_valid is None else [bool(v) for v in mag_valid]
    theta = [0, 0, 0]
    out = np.empty((n, 3), np.int64)
    for k in range(n):
        theta = _complementary_step(theta, gyr[k], acc[k], mag[k], valid[k], reg, Status())[0]
        out[k] = theta
    return out
