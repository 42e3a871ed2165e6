"""Calibration from data: what the gateware's calibration stage will load.

- ``gyro_bias``: mean rate over a stationary window (and its standard error).
- ``accel_six_pose``: offset and scale per axis from the mean readings in the six poses where one
  axis points up or down (a = scale·f + offset, f = ±g on that axis).
- ``mag_ellipsoid``: hard-iron offset b and soft-iron matrix A (symmetric) such that
  A·(m − b) lies on a sphere of the field's intensity, by a least-squares fit of a general
  ellipsoid; the quality figure is the RMS spread of ‖A·(m − b)‖ in percent of the intensity.
- ``asa_sensitivity``: the AK8963 fuse-ROM adjustment as a per-axis factor.
- ``estimate_noise`` / ``kalman_params_from_noise``: per-axis noise of each sensor from
  stationary data, and the per-axis Kalman filter's R and Q chosen from it rather than guessed.
All functions take readings in physical units (rad/s, m/s², µT) or counts alike.
"""

from dataclasses import dataclass

import numpy as np

from ..hdl.contract import ak8963_regs as A
from .frames import accel_tilt
from .kalman import KalmanParams


__all__ = ["gyro_bias", "accel_six_pose", "MagCalibration", "mag_ellipsoid", "asa_sensitivity",
           "estimate_noise", "kalman_params_from_noise"]


def gyro_bias(gyr_stationary):
    """(bias, standard error) per axis from a stationary window."""
    g = np.asarray(gyr_stationary, float)
    return g.mean(0), g.std(0, ddof=1) / np.sqrt(len(g))


def accel_six_pose(mean_readings, g=9.81):
    """``mean_readings``: dict with keys "+x", "-x", "+y", "-y", "+z", "-z" (the axis pointing
    up) -> mean accelerometer vector. Returns (offset (3), scale (3)): true = (a − offset)/scale.
    """
    offset, scale = np.empty(3), np.empty(3)
    for i, axis in enumerate("xyz"):
        up, down = np.asarray(mean_readings["+" + axis], float), \
            np.asarray(mean_readings["-" + axis], float)
        offset[i] = (up[i] + down[i]) / 2
        scale[i] = (up[i] - down[i]) / (2 * g)
    return offset, scale


@dataclass
class MagCalibration:
    offset: np.ndarray           # hard iron, same unit as the data
    matrix: np.ndarray           # soft iron correction: calibrated = matrix @ (m − offset)
    intensity: float             # radius of the calibrated sphere
    spread_percent: float        # RMS of (‖calibrated‖ / intensity − 1), in %

    def apply(self, mag):
        return (np.asarray(mag, float) - self.offset) @ self.matrix.T


def mag_ellipsoid(mag, intensity=None):
    """Least-squares ellipsoid fit. ``intensity``: the field the calibrated data should have
    (default: the geometric mean radius of the fitted ellipsoid, i.e. volume kept)."""
    m = np.asarray(mag, float)
    if len(m) < 9:
        raise ValueError("an ellipsoid fit needs at least 9 readings (and rotation about all axes)")
    x, y, z = m.T
    D = np.column_stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z, 2 * x, 2 * y, 2 * z])
    v, *_ = np.linalg.lstsq(D, np.ones(len(m)), rcond=None)
    M = np.array([[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]])
    n = v[6:9]
    try:
        b = -np.linalg.solve(M, n)
    except np.linalg.LinAlgError as e:
        raise ValueError("the readings do not determine an ellipsoid (too little rotation)") from e
    k = b @ M @ b + 1.0                       # (m − b)ᵀ M (m − b) = k
    Mn = M / k
    w, V = np.linalg.eigh(Mn)
    if np.any(w <= 0):
        raise ValueError("the fit is not an ellipsoid (too little rotation, or outliers)")
    sqrt_m = V @ np.diag(np.sqrt(w)) @ V.T    # unit sphere: ‖sqrt_m (m − b)‖ = 1
    radius = intensity if intensity is not None else float(np.prod(1 / np.sqrt(w)) ** (1 / 3))
    matrix = radius * sqrt_m
    cal = (m - b) @ matrix.T
    spread = 100 * float(np.sqrt(np.mean((np.linalg.norm(cal, axis=1) / radius - 1) ** 2)))
    return MagCalibration(b, matrix, radius, spread)


def asa_sensitivity(asa):
    """Per-axis factor from the AK8963's ASAX/Y/Z bytes: H_adj = H · factor."""
    return np.array([A.asa_adjust(1.0, a) for a in asa])


def estimate_noise(gyr, acc, mag=None):
    """Per-axis standard deviations of stationary data (and of the accelerometer tilt angles,
    in degrees), for choosing filter noise parameters from data."""
    out = {"gyro_std": np.std(gyr, axis=0, ddof=1), "accel_std": np.std(acc, axis=0, ddof=1),
           "tilt_std_deg": np.degrees(np.std(accel_tilt(acc), axis=0, ddof=1))}
    if mag is not None:
        out["mag_std"] = np.std(mag, axis=0, ddof=1)
    return out


def kalman_params_from_noise(gyr_dps, acc, dt, *, bias_instability_dps=0.01, rates="euler"):
    """KalmanParams with R = variance of the accelerometer angles (deg²), Q_angle = (σ_gyro·T)²
    (the angle noise one gyro sample adds), Q_bias = (bias instability)²·T (a random walk)."""
    noise = estimate_noise(gyr_dps, acc)
    r = float(np.mean(noise["tilt_std_deg"] ** 2))
    q_angle = float(np.mean(noise["gyro_std"] ** 2)) * dt * dt
    q_bias = bias_instability_dps ** 2 * dt
    return KalmanParams(q_angle=q_angle, q_bias=q_bias, r=r, rates=rates)
