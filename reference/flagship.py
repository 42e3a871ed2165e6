"""The flagship filter: full-range quaternion attitude with gyro bias estimation and rejection of
disturbed measurements, built for fixed point on a small FPGA.

It follows the structure of VQF (D. Laidig, T. Seel, "VQF: Highly accurate IMU orientation
estimation with bias estimation and magnetic disturbance rejection", Information Fusion 2023),
written from the paper's description, simplified:

    q = Rz(δ) ⊗ q_a ⊗ q_g

- q_g integrates the bias-corrected gyro: q_g ← q_g ⊗ exp((ω − b)·T). It maps the body to an
  almost-inertial frame I.
- Inclination (q_a, a rotation about horizontal axes): the specific force is rotated into I,
  a_I = R(q_g)·a, and low-passed there with time constant ``tau_acc``. Linear accelerations
  average out in I while gravity does not, and no correction ever touches I, so the low-pass
  sees no feedback. Each sample, q_a is set so that R(q_a)·LP(a_I) points up.
- Heading (δ, a rotation about the vertical): the field in the tilt-corrected frame,
  m_E = R(q_a ⊗ q_g)·m, must point North: δ follows atan2(m_E,x, m_E,y) with time constant
  ``tau_mag`` (faster in the first ``mag_fast_s`` seconds, for start-up). A field whose norm or
  dip differs from the reference (learnt over the first ``mag_ref_s`` seconds) by more than
  ``mag_norm_gate`` (relative) or ``mag_dip_gate`` (degrees) is rejected; one that stays
  different but steady for ``mag_new_s`` seconds becomes the new reference.
- Gyro bias b: at rest (gyro within ``rest_gyro`` of the bias and accelerometer within
  ``rest_acc`` of its mean for ``rest_s`` seconds) b follows the low-passed gyro (time constant
  ``tau_rest``). (VQF also estimates the bias in motion; an integral term on the corrections
  tried here made the recordings worse, so motion-time bias estimation is left out for now.)
There are no Euler angles in it, so it works at any attitude (no gimbal lock at ±90° pitch).

Cost per sample in fixed point (``reference/flagship_fixed.py``, the same steps in the
datapath's operations): about 57 single multiplies and 114 multiply-accumulate terms, 4
vectoring and 3 rotation CORDIC runs, no division (normalisation is one Newton step).
"""

import math
from dataclasses import dataclass

import numpy as np

from .frames import filter_inputs, quat_from_accel_mag


__all__ = ["FlagshipParams", "flagship_filter"]


@dataclass(frozen=True)
class FlagshipParams:
    tau_acc: float = 5.0            # s, low-pass of the specific force in the inertial frame
    tau_mag: float = 15.0           # s, heading correction
    mag_fast_s: float = 3.0         # s of fast heading convergence at start-up
    mag_ref_s: float = 2.0          # s over which the reference field is learnt
    mag_norm_gate: float = 0.1
    mag_dip_gate: float = 10.0      # degrees
    mag_new_s: float = 20.0
    rest_gyro: float = math.radians(2.0)   # rad/s
    rest_acc: float = 0.5           # m/s²
    rest_s: float = 1.5
    tau_rest: float = 3.0


def _qmul(p, q):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw)


def _qexp(vx, vy, vz):
    a = math.sqrt(vx * vx + vy * vy + vz * vz)
    if a < 1e-12:
        return (1.0, vx / 2, vy / 2, vz / 2)
    s = math.sin(a / 2) / a
    return (math.cos(a / 2), vx * s, vy * s, vz * s)


def _qnorm(q):
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def _rot(q, v):
    """R(q)·v."""
    w, x, y, z = q
    vx, vy, vz = v
    return ((1 - 2 * (y * y + z * z)) * vx + 2 * (x * y - w * z) * vy + 2 * (x * z + w * y) * vz,
            2 * (x * y + w * z) * vx + (1 - 2 * (x * x + z * z)) * vy + 2 * (y * z - w * x) * vz,
            2 * (x * z - w * y) * vx + 2 * (y * z + w * x) * vy + (1 - 2 * (x * x + y * y)) * vz)


def _rot_t(q, v):
    """R(q)ᵀ·v."""
    return _rot((q[0], -q[1], -q[2], -q[3]), v)


def flagship_filter(gyr, acc, mag, dt, params=FlagshipParams(), *, mag_valid=None,
                    return_bias=False):
    """gyr rad/s, acc m/s² (any unit: only directions and deviations matter, rest_acc is in the
    same unit), mag any unit or None (6-axis). Returns quaternions body->ENU (N,4)."""
    p = params
    gyr, acc, magv, valid = filter_inputs(gyr, acc, mag, mag_valid)
    n = len(gyr)
    use_mag = magv is not None
    gyr_l, acc_l = gyr.tolist(), acc.tolist()
    mag_l = magv.tolist() if use_mag else None

    # Start-up alignment: the first 0.1 s of accelerometer (and magnetometer) data.
    k0 = max(1, min(n, int(round(0.1 / dt))))
    if use_mag:
        q0 = tuple(quat_from_accel_mag(acc[:k0].mean(0), magv[:k0].mean(0)))
    else:
        a = acc[:k0].mean(0)
        q0 = tuple(quat_from_accel_mag(a, np.cross(a, [0.0, 1.0, 0.0]) if abs(a[0]) < abs(a[1])
                                       else np.cross(a, [1.0, 0.0, 0.0])))
    # Split q0 into a heading part δ and an inclination part q_a; q_g starts at identity.
    w, x, y, z = q0
    delta = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    qa = _qnorm(_qmul((math.cos(delta / 2), 0.0, 0.0, -math.sin(delta / 2)), q0))
    qg = (1.0, 0.0, 0.0, 0.0)
    lp = list(_rot(qg, acc_l[0]))
    b = [0.0, 0.0, 0.0]

    a_acc = 1 - math.exp(-dt / p.tau_acc)
    a_rest = 1 - math.exp(-dt / p.tau_rest)
    a_det = 1 - math.exp(-dt / 0.5)
    gyr_lp, acc_lp = list(gyr_l[0]), list(acc_l[0])
    rest_time = 0.0
    ref_norm = ref_dip = None
    ref_acc = []
    cand = None
    out = np.empty((n, 4))
    biases = np.empty((n, 3))

    for k in range(n):
        t = k * dt
        g = gyr_l[k]
        a = acc_l[k]
        # -- rest detection and bias at rest ---------------------------------------------------
        for i in range(3):
            gyr_lp[i] += a_det * (g[i] - gyr_lp[i])
            acc_lp[i] += a_det * (a[i] - acc_lp[i])
        dg = math.sqrt(sum((g[i] - b[i]) ** 2 for i in range(3)))
        da = math.sqrt(sum((a[i] - acc_lp[i]) ** 2 for i in range(3)))
        rest_time = rest_time + dt if (dg < p.rest_gyro and da < p.rest_acc) else 0.0
        if rest_time >= p.rest_s:           # at rest: the gyro reads its bias
            for i in range(3):
                b[i] += a_rest * (gyr_lp[i] - b[i])

        # -- strapdown ------------------------------------------------------------------------
        qg = _qnorm(_qmul(qg, _qexp((g[0] - b[0]) * dt, (g[1] - b[1]) * dt,
                                    (g[2] - b[2]) * dt)))

        # -- inclination ----------------------------------------------------------------------
        aI = _rot(qg, a)
        for i in range(3):
            lp[i] += a_acc * (aI[i] - lp[i])
        e = _rot(qa, lp)
        en = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        corr_e = (0.0, 0.0, 0.0)
        if en > 0:
            ex, ey, ez = e[0] / en, e[1] / en, e[2] / en
            # rotation taking e to up: axis e × z = (ey, −ex, 0), angle acos(ez)
            s = math.hypot(ex, ey)
            if s > 1e-12:
                angle = math.atan2(s, ez)
                corr_e = (ey / s * angle, -ex / s * angle, 0.0)
                qa = _qnorm(_qmul(_qexp(*corr_e), qa))

        # -- heading --------------------------------------------------------------------------
        corr_h = 0.0
        if use_mag and valid[k]:
            m = mag_l[k]
            mE = _rot(qa, _rot(qg, m))
            mn = math.sqrt(mE[0] * mE[0] + mE[1] * mE[1] + mE[2] * mE[2])
            horiz = math.hypot(mE[0], mE[1])
            if mn > 0 and horiz > 0:
                dip = math.degrees(math.atan2(-mE[2], horiz))
                if ref_norm is None:
                    ref_acc.append((mn, dip))
                    if t >= p.mag_ref_s:
                        # the mean (a running sum in hardware) of the first seconds
                        ref_norm = float(np.mean([r[0] for r in ref_acc]))
                        ref_dip = float(np.mean([r[1] for r in ref_acc]))
                good = ref_norm is None or (abs(mn / ref_norm - 1) < p.mag_norm_gate and
                                           abs(dip - ref_dip) < p.mag_dip_gate)
                if ref_norm is not None and not good:
                    if cand is None or abs(mn / cand[0] - 1) > p.mag_norm_gate / 2 or \
                            abs(dip - cand[1]) > p.mag_dip_gate / 2:
                        cand = (mn, dip, t)
                    elif t - cand[2] > p.mag_new_s:
                        ref_norm, ref_dip, cand = cand[0], cand[1], None
                elif good:
                    cand = None
                if good:
                    psi = math.atan2(mE[0], mE[1])          # field direction east of North
                    tau = p.tau_mag if t > p.mag_fast_s else min(p.tau_mag, 0.2)
                    err = (psi - delta + math.pi) % (2 * math.pi) - math.pi
                    corr_h = err * (1 - math.exp(-dt / tau))
                    delta = (delta + corr_h + math.pi) % (2 * math.pi) - math.pi

        qh = (math.cos(delta / 2), 0.0, 0.0, math.sin(delta / 2))
        out[k] = _qmul(qh, _qmul(qa, qg))
        biases[k] = b
    return (out, biases) if return_bias else out
