"""Complementary filter: θ_n = a·(θ_{n−1} + ω_n·dt) + (1 − a)·θ_meas,n, a = τ / (τ + dt).

Per axis: roll and pitch measured by accelerometer tilt, yaw by the tilt-compensated
magnetometer heading (using the filter's own roll and pitch). Angles and the blend wrap at ±180°
(the measurement is pulled to within 180° of the prediction before blending). A zero
accelerometer or field vector contributes nothing (the prediction stands). ``rates`` as in
``reference.kalman``. Units: degrees, °/s, seconds.
"""

import numpy as np

from .frames import accel_tilt, euler_to_quat, filter_inputs, tilt_compensated_heading
from .kalman import _wrap_deg


__all__ = ["PRESETS", "coefficient", "complementary_filter", "run_float"]


# Published presets: τ = 0.8 s at dt = 25 ms (a ≈ 0.97) and τ = 1.5 s at dt = 30 ms (a ≈ 0.98).
PRESETS = {"tau0.8_dt25ms": (0.8, 0.025), "tau1.5_dt30ms": (1.5, 0.030)}


def coefficient(tau, dt):
    return tau / (tau + dt)


def complementary_filter(gyr_dps, acc, mag, dt, *, tau=0.8, a=None, rates="euler",
                         mag_valid=None, theta0=None):
    """Returns (euler_deg (N,3), quat (N,4)). ``a`` overrides τ."""
    a = coefficient(tau, dt) if a is None else a
    gyr, acc, mag, mag_valid = filter_inputs(gyr_dps, acc, mag, mag_valid)
    n = len(gyr)
    meas_rp = np.degrees(accel_tilt(acc))
    theta = np.zeros(3) if theta0 is None else np.array(theta0, float)
    out = np.empty((n, 3))
    for k in range(n):
        w = gyr[k]
        if rates == "euler":
            roll, pitch = np.radians(theta[0]), np.radians(theta[1])
            sr, cr, tp = np.sin(roll), np.cos(roll), np.tan(pitch)
            cp = max(abs(np.cos(pitch)), 1e-6)
            w = np.array([w[0] + sr * tp * w[1] + cr * tp * w[2], cr * w[1] - sr * w[2],
                          (sr * w[1] + cr * w[2]) / cp])
        pred = theta + w * dt
        meas = np.empty(3)
        meas[:2] = meas_rp[k] if np.any(acc[k]) else pred[:2]     # free fall: no tilt
        meas[2] = np.degrees(tilt_compensated_heading(mag[k], np.radians(pred[0]),
                                                      np.radians(pred[1])))
        meas = pred + _wrap_deg(meas - pred)
        if not mag_valid[k] or not np.any(mag[k]):
            meas[2] = pred[2]
        theta = _wrap_deg(a * pred + (1 - a) * meas)
        out[k] = theta
    return out, euler_to_quat(np.radians(out))


def run_float(gyr, acc, mag, dt, **params):
    """The filter as ``evaluate.run_filter`` runs it (its record in ``filter_registry``): gyr
    rad/s, acc m/s², mag µT -> quaternions body->ENU; ``params``: ``tau``, ``rates``."""
    return complementary_filter(np.degrees(gyr), acc, mag, dt, tau=params.get("tau", 0.8),
                                rates=params.get("rates", "body"))[1]
