"""Frames, quaternions and the measurement building blocks every filter here shares.

Conventions (all filters, all outputs)
- Body frame: the MPU9250's accelerometer/gyro axes. AK8963 readings are mapped into it with
  ``mag_to_body`` (mag x = accel y, mag y = accel x, mag z = −accel z).
- Earth frame: East-North-Up (ENU). At rest the accelerometer reads +g along the body's up
  direction (specific force).
- Quaternions are ``[w, x, y, z]`` (Hamilton product), unit, and map body vectors to earth:
  v_earth = q ⊗ v_body ⊗ q*.
- Euler angles are ZYX (yaw, then pitch, then roll), in radians: R = Rz(yaw)·Ry(pitch)·Rx(roll).
  Yaw is measured from East towards North (0 = body x axis points East, +90° = North), in
  (−π, π].
Everything works on arrays: a leading axis of samples is allowed everywhere.
"""

import numpy as np


__all__ = ["quat_mul", "quat_conj", "quat_normalize", "quat_rotate", "quat_to_matrix",
           "matrix_to_quat", "quat_from_rotvec", "quat_to_euler", "euler_to_quat",
           "accel_tilt", "tilt_compensated_heading", "quat_from_accel_mag", "filter_inputs",
           "mag_to_body", "body_to_mag", "wrap_angle", "orientation_errors"]


def quat_mul(p, q):
    p, q = np.asarray(p, float), np.asarray(q, float)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack([pw * qw - px * qx - py * qy - pz * qz,
                     pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw], axis=-1)


def quat_conj(q):
    return np.asarray(q, float) * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q):
    q = np.asarray(q, float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_to_matrix(q):
    """Rotation matrix R (body -> earth) of unit quaternion(s) ``q``."""
    w, x, y, z = np.moveaxis(np.asarray(q, float), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def quat_rotate(q, v):
    """Earth coordinates of body vector(s) ``v``."""
    return np.einsum("...ij,...j->...i", quat_to_matrix(q), np.asarray(v, float))


def matrix_to_quat(R):
    """Unit quaternion (w >= 0) of rotation matrix/matrices ``R`` (Shepperd's method)."""
    R = np.asarray(R, float)
    shape = R.shape[:-2]
    R = R.reshape(-1, 3, 3)
    q = np.empty((len(R), 4))
    tr = np.trace(R, axis1=1, axis2=2)
    diag = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    k = np.argmax(diag, axis=1)
    for i, (m, kk) in enumerate(zip(R, k)):
        if kk == 0:
            s = 2 * np.sqrt(1 + tr[i])
            q[i] = [s / 4, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
        elif kk == 1:
            s = 2 * np.sqrt(1 + m[0, 0] - m[1, 1] - m[2, 2])
            q[i] = [(m[2, 1] - m[1, 2]) / s, s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
        elif kk == 2:
            s = 2 * np.sqrt(1 - m[0, 0] + m[1, 1] - m[2, 2])
            q[i] = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s]
        else:
            s = 2 * np.sqrt(1 - m[0, 0] - m[1, 1] + m[2, 2])
            q[i] = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4]
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return quat_normalize(q).reshape(*shape, 4)


def quat_from_rotvec(v):
    """Quaternion(s) of rotation vector(s) ``v`` (axis · angle, radians)."""
    v = np.asarray(v, float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = angle / 2
    # sin(x/2)/x -> 1/2 for small x, without dividing by zero
    k = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1), 0.5)
    return np.concatenate([np.cos(half), v * k], axis=-1)


def quat_to_euler(q):
    """(roll, pitch, yaw) in radians, ZYX, from body->ENU quaternion(s)."""
    w, x, y, z = np.moveaxis(np.asarray(q, float), -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def euler_to_quat(euler):
    """Body->ENU quaternion(s) from (roll, pitch, yaw) in radians, ZYX."""
    roll, pitch, yaw = np.moveaxis(np.asarray(euler, float), -1, 0)
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return np.stack([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy], axis=-1)


def wrap_angle(a):
    """Angle(s) wrapped to (−π, π]."""
    return -((-np.asarray(a, float) + np.pi) % (2 * np.pi) - np.pi)


def accel_tilt(acc):
    """(roll, pitch) in radians from accelerometer reading(s) (any unit)."""
    ax, ay, az = np.moveaxis(np.asarray(acc, float), -1, 0)
    return np.stack([np.arctan2(ay, az), np.arctan2(-ax, np.hypot(ay, az))], axis=-1)


def tilt_compensated_heading(mag, roll, pitch):
    """Yaw (radians, from East towards North) from body-frame field(s) and tilt."""
    mx, my, mz = np.moveaxis(np.asarray(mag, float), -1, 0)
    cr, sr, cp, sp = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch)
    # Level the field: Ry(pitch)·Rx(roll)·m; its horizontal part must point North.
    hx = cp * mx + sp * sr * my + sp * cr * mz
    hy = cr * my - sr * mz
    return np.arctan2(hx, hy)


def quat_from_accel_mag(acc, mag):
    """Body->ENU quaternion(s) that put ``acc`` up and the horizontal part of ``mag`` North."""
    up = np.asarray(acc, float)
    up = up / np.linalg.norm(up, axis=-1, keepdims=True)
    east = np.cross(np.asarray(mag, float), up)
    east = east / np.linalg.norm(east, axis=-1, keepdims=True)
    north = np.cross(up, east)
    R = np.stack([east, north, up], axis=-2)        # rows: earth axes in body coordinates
    return matrix_to_quat(R)


def filter_inputs(gyr, acc, mag, mag_valid=None):
    """A filter's inputs as arrays: (gyr, acc, mag or None, mag_valid) — floats, and a
    boolean mask that is all true when ``mag_valid`` is None."""
    gyr = np.asarray(gyr, float)
    mask = np.ones(len(gyr), bool) if mag_valid is None else np.asarray(mag_valid, bool)
    return (gyr, np.asarray(acc, float), None if mag is None else np.asarray(mag, float),
            mask)


def mag_to_body(mag_ak):
    """AK8963 axes -> MPU9250 body axes: (x, y, z)_body = (y, x, −z)_AK8963 (the dtype is
    kept, so counts stay integers)."""
    m = np.asarray(mag_ak)
    return np.stack([m[..., 1], m[..., 0], -m[..., 2]], axis=-1)


def body_to_mag(mag_body):
    """MPU9250 body axes -> AK8963 axes: the same swap, which is its own inverse."""
    return mag_to_body(mag_body)


def _unit(q):
    """``q`` (… × 4) scaled to unit norm, row by row (a zero row stays zero)."""
    q = np.asarray(q, float)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    return q / np.where(norm > 0, norm, 1.0)


def orientation_errors(q, q_ref):
    """BROAD's error metric per sample (radians): total, heading, inclination.

    e = q ⊗ q_ref⁻¹ (the error expressed in the earth frame); total = 2·acos(|e_w|),
    heading = 2·atan(|e_z / e_w|), inclination = 2·acos(√(e_w² + e_z²)).

    Both are normalised first: the metric is of rotations, and an input a little off unit norm
    (a truth stored rounded, an estimate in fixed point) would otherwise move it, most near
    zero error where |e_w| is clipped at 1 (truth × 1.001 scored 0.0°, × 0.995 11.5°, for a
    true 1.33°).
    """
    e = quat_mul(_unit(q), quat_conj(_unit(q_ref)))
    w, z = np.abs(e[..., 0]), e[..., 3]
    total = 2 * np.arccos(np.clip(w, 0, 1))
    heading = 2 * np.arctan(np.abs(z) / np.maximum(w, 1e-300))
    inclination = 2 * np.arccos(np.clip(np.sqrt(w * w + z * z), 0, 1))
    return np.stack([total, heading, inclination], axis=-1)
