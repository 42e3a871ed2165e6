"""Madgwick's gradient-descent MARG filter (quaternion, gain β), in the ENU frame.

q̇ = ½·q ⊗ (0, ω) − β·∇f/‖∇f‖, where f stacks the errors between the measured directions and
the earth references rotated into the body: gravity (0, 0, 1) against the normalised
accelerometer, and the field reference b = (0, ‖h_xy‖, h_z) against the normalised magnetometer,
with h = q ⊗ m ⊗ q* the measured field in the earth frame (North is +y in ENU).
The gradient is Jᵀf written out for a general earth vector, so no term can lose the factor 2
that widely copied C code drops from its earth-field reference terms.

Start-up alignment: q₀ from the first accelerometer + magnetometer sample
(``frames.quat_from_accel_mag``) instead of the identity, which removes the seconds-long
convergence from an arbitrary start. Units: rad/s, seconds; accelerometer and magnetometer in
any unit.
"""

import math

import numpy as np

from .frames import filter_inputs, quat_from_accel_mag


__all__ = ["madgwick_filter", "run_float"]


def _gradient_terms(w, x, y, z, d, s):
    """f = Rᵀd − s and Jᵀf for earth direction d and measured body direction s."""
    dx, dy, dz = d
    fx = (1 - 2 * (y * y + z * z)) * dx + 2 * (x * y + w * z) * dy + 2 * (x * z - w * y) * dz - s[0]
    fy = 2 * (x * y - w * z) * dx + (1 - 2 * (x * x + z * z)) * dy + 2 * (y * z + w * x) * dz - s[1]
    fz = 2 * (x * z + w * y) * dx + 2 * (y * z - w * x) * dy + (1 - 2 * (x * x + y * y)) * dz - s[2]
    gw = (2 * z * dy - 2 * y * dz) * fx + (-2 * z * dx + 2 * x * dz) * fy + (2 * y * dx - 2 * x * dy) * fz
    gx = (2 * y * dy + 2 * z * dz) * fx + (2 * y * dx - 4 * x * dy + 2 * w * dz) * fy + \
        (2 * z * dx - 2 * w * dy - 4 * x * dz) * fz
    gy = (-4 * y * dx + 2 * x * dy - 2 * w * dz) * fx + (2 * x * dx + 2 * z * dz) * fy + \
        (2 * w * dx + 2 * z * dy - 4 * y * dz) * fz
    gz = (-4 * z * dx + 2 * w * dy + 2 * x * dz) * fx + (-2 * w * dx - 4 * z * dy + 2 * y * dz) * fy + \
        (2 * x * dx + 2 * y * dy) * fz
    return gw, gx, gy, gz


def madgwick_filter(gyr, acc, mag, dt, *, beta=0.1, q0=None, align=True, mag_valid=None):
    """Returns quaternions (N,4). ``gyr`` in rad/s. ``mag=None`` runs the IMU (6-axis) form."""
    gyr, acc, magv, valid = filter_inputs(gyr, acc, mag, mag_valid)
    n = len(gyr)
    use_mag = magv is not None
    if q0 is not None:
        w, x, y, z = (float(v) for v in q0)
    elif align and use_mag:
        w, x, y, z = (float(v) for v in quat_from_accel_mag(acc[0], magv[0]))
    else:
        w, x, y, z = 1.0, 0.0, 0.0, 0.0
    out = np.empty((n, 4))
    for k in range(n):
        gx_, gy_, gz_ = gyr[k]
        dw = 0.5 * (-x * gx_ - y * gy_ - z * gz_)
        dx = 0.5 * (w * gx_ + y * gz_ - z * gy_)
        dy = 0.5 * (w * gy_ - x * gz_ + z * gx_)
        dz = 0.5 * (w * gz_ + x * gy_ - y * gx_)
        a = acc[k]
        an = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
        if an > 0:
            s = (a[0] / an, a[1] / an, a[2] / an)
            g = list(_gradient_terms(w, x, y, z, (0.0, 0.0, 1.0), s))
            if use_mag and valid[k]:
                m = magv[k]
                mn = math.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2])
                if mn > 0:
                    m = (m[0] / mn, m[1] / mn, m[2] / mn)
                    # h = q ⊗ m ⊗ q*: the field in the earth frame
                    hx = (1 - 2 * (y * y + z * z)) * m[0] + 2 * (x * y - w * z) * m[1] + 2 * (x * z + w * y) * m[2]
                    hy = 2 * (x * y + w * z) * m[0] + (1 - 2 * (x * x + z * z)) * m[1] + 2 * (y * z - w * x) * m[2]
                    hz = 2 * (x * z - w * y) * m[0] + 2 * (y * z + w * x) * m[1] + (1 - 2 * (x * x + y * y)) * m[2]
                    gm = _gradient_terms(w, x, y, z, (0.0, math.hypot(hx, hy), hz), m)
                    g = [g[i] + gm[i] for i in range(4)]
            gn = math.sqrt(sum(v * v for v in g))
            if gn > 0:
                dw -= beta * g[0] / gn
                dx -= beta * g[1] / gn
                dy -= beta * g[2] / gn
                dz -= beta * g[3] / gn
        w, x, y, z = w + dw * dt, x + dx * dt, y + dy * dt, z + dz * dt
        qn = math.sqrt(w * w + x * x + y * y + z * z)
        w, x, y, z = w / qn, x / qn, y / qn, z / qn
        out[k] = (w, x, y, z)
    return out


def run_float(gyr, acc, mag, dt, **params):
    """The filter as ``evaluate.run_filter`` runs it (its record in ``filter_registry``): gyr
    rad/s, acc m/s², mag µT -> quaternions body->ENU; ``params``: ``beta``."""
    return madgwick_filter(gyr, acc, mag, dt, beta=params.get("beta", 0.1))
