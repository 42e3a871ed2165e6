"""Per-axis Kalman filter (angle and gyro bias), as published for MPU9250 attitude detection.

For each of roll, pitch and yaw, state x = [angle, gyro bias] (degrees, °/s):
    predict  x_k = A·x_{k−1} + B·u_k,  A = [[1, −T], [0, 1]],  B = [T, 0]ᵀ,
             u_k = (ω_{k−1} + ω_k) / 2  (trapezoidal rate),   P = A·P·Aᵀ + Q
    update   z = accelerometer tilt (roll, pitch) or tilt-compensated magnetometer heading (yaw,
             using the filter's own roll and pitch), H = [1, 0], R; innovations and angles wrap
             at ±180°.
``rates="body"`` feeds each axis its body rate (the published form: exact only near level);
``rates="euler"`` maps body rates to Euler-angle rates first (right at any attitude short of
±90° pitch, where yaw and roll are undefined).
A sample with ``mag_valid`` false, or a zero field, skips the yaw update; one with ``acc_valid``
false, or a zero accelerometer vector (free fall), skips the roll and pitch updates.

Units: gyro °/s, accelerometer and magnetometer any (only directions matter), T in seconds.
"""

from dataclasses import dataclass

import numpy as np

from .frames import accel_tilt, euler_to_quat, filter_inputs, tilt_compensated_heading


__all__ = ["KalmanParams", "PUBLISHED", "kalman_filter", "run_float"]


@dataclass(frozen=True)
class KalmanParams:
    q_angle: float = 0.2        # process noise of the angle, deg² per step
    q_bias: float = 0.1         # process noise of the bias, (deg/s)² per step
    r: float = 2.0              # measurement noise, deg²
    r_yaw: float = None         # yaw measurement noise (None: same as r)
    p0: float = 1.0             # initial covariance (identity · p0)
    rates: str = "body"         # the published form (and the fixed-point model's)


# The published preset (T = 0.01 s): x0 = 0, P0 = I, Q = diag(0.2, 0.1), R = 2, body rates.
PUBLISHED = KalmanParams(q_angle=0.2, q_bias=0.1, r=2.0, p0=1.0, rates="body")


def _wrap_deg(a):
    return (a + 180.0) % 360.0 - 180.0


def kalman_filter(gyr_dps, acc, mag, dt, params=KalmanParams(), *, mag_valid=None,
                  acc_valid=None, x0=None):
    """Run the filter over N samples. Returns (euler_deg (N,3), bias_dps (N,3), quat (N,4))."""
    gyr, acc, mag, mag_valid = filter_inputs(gyr_dps, acc, mag, mag_valid)
    n = len(gyr)
    meas_rp = np.degrees(accel_tilt(acc))
    acc_valid = np.ones(n, bool) if acc_valid is None else np.asarray(acc_valid, bool)
    r = np.array([params.r, params.r, params.r if params.r_yaw is None else params.r_yaw])

    x = np.zeros((3, 2)) if x0 is None else np.array(x0, float).reshape(3, 2)
    P = np.tile(np.eye(2) * params.p0, (3, 1, 1))
    q_angle, q_bias = params.q_angle, params.q_bias
    euler = np.empty((n, 3))
    bias = np.empty((n, 3))
    prev = gyr[0]
    for k in range(n):
        u_body = (prev + gyr[k]) / 2
        prev = gyr[k]
        if params.rates == "euler":
            roll, pitch = np.radians(x[0, 0]), np.radians(x[1, 0])
            sr, cr, cp, tp = np.sin(roll), np.cos(roll), np.cos(pitch), np.tan(pitch)
            cp = cp if abs(cp) > 1e-6 else 1e-6
            u = np.array([u_body[0] + sr * tp * u_body[1] + cr * tp * u_body[2],
                          cr * u_body[1] - sr * u_body[2],
                          (sr * u_body[1] + cr * u_body[2]) / cp])
        else:
            u = u_body
        # predict (A = [[1, -T], [0, 1]])
        x[:, 0] = _wrap_deg(x[:, 0] + dt * (u - x[:, 1]))
        p00, p01, p10, p11 = P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1]
        n00 = p00 - dt * (p10 + p01) + dt * dt * p11 + q_angle
        n01 = p01 - dt * p11
        n10 = p10 - dt * p11
        n11 = p11 + q_bias
        P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1] = n00, n01, n10, n11
        # measurements
        z = np.empty(3)
        z[:2] = meas_rp[k]
        z[2] = np.degrees(tilt_compensated_heading(mag[k], np.radians(x[0, 0]),
                                                   np.radians(x[1, 0])))
        # A zero vector (free fall, a dead magnetometer) has no direction: no update.
        acc_ok = acc_valid[k] and np.any(acc[k])
        use = np.array([acc_ok, acc_ok, mag_valid[k] and np.any(mag[k])])
        y = _wrap_deg(z - x[:, 0])
        s = P[:, 0, 0] + r
        k0, k1 = P[:, 0, 0] / s, P[:, 1, 0] / s
        k0, k1 = np.where(use, k0, 0.0), np.where(use, k1, 0.0)
        x[:, 0] = _wrap_deg(x[:, 0] + k0 * y)
        x[:, 1] += k1 * y
        p00, p01 = P[:, 0, 0].copy(), P[:, 0, 1].copy()
        P[:, 0, 0] -= k0 * p00
        P[:, 0, 1] -= k0 * p01
        P[:, 1, 0] -= k1 * p00
        P[:, 1, 1] -= k1 * p01
        euler[k] = x[:, 0]
        bias[k] = x[:, 1]
    return euler, bias, euler_to_quat(np.radians(euler))


def run_float(gyr, acc, mag, dt, **params):
    """The filter as ``evaluate.run_filter`` runs it (its record in ``filter_registry``): gyr
    rad/s, acc m/s², mag µT -> quaternions body->ENU; ``params``: ``kalman`` (``KalmanParams``)."""
    return kalman_filter(np.degrees(gyr), acc, mag, dt, params.get("kalman", KalmanParams()))[2]
