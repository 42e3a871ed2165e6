"""The flagship filter: full-range quaternion attitude with gyro bias estimation and rejection of
disturbed measurements, built for fixed point on a small FPGA.

It follows the structure of VQF (D. Laidig, T. Seel, "VQF: Highly accurate IMU orientation
estimation with bias estimation and magnetic disturbance rejection", Information Fusion 2023),
written from the paper's description, simplified:

    q = Rz(δ) ⊗ q_a ⊗ q_g

- q_g integrates the bias-corrected gyro: q_g ← q_g ⊗ exp((ω − b)·T). It maps the body to an
  almost-inertial frame I.
- Inclination (q_a, a rotation about horizontal axes): the specific force is rotated into I,
  a_I = R(q_g)·a, and low-passed there by a second-order Butterworth filter with VQF's cut-off
  for ``tau_acc``, f_c = √2/(2π·tau_acc) (VQF's choice too; a first-order one let about twice
  the linear acceleration through on the translation trials), built as a state-variable
  filter, which fixed point runs well with its poles this close to 1 (``svf_gain``). Linear
  accelerations average out in I while gravity does not, and no correction ever touches I, so
  the low-pass sees no feedback. Each sample, q_a is set so that R(q_a)·LP(a_I) points up.
- Heading (δ, a rotation about the vertical): the field in the tilt-corrected frame,
  m_E = R(q_a ⊗ q_g)·m, must point North: δ follows atan2(m_E,x, m_E,y) with time constant
  ``tau_mag`` (faster in the first ``mag_fast_s`` seconds, for start-up). A field whose norm or
  dip differs from the reference (low-passed over the first ``mag_ref_s`` seconds) by more than
  ``mag_norm_gate`` (relative) or ``mag_dip_gate`` (degrees) is rejected; one that stays
  different but steady (its norm within ``mag_norm_gate`` of the first such field's, its dip
  within half ``mag_dip_gate``) for ``mag_new_s`` seconds becomes the new reference.
- Gyro bias b: at rest (gyro within ``rest_gyro`` of its own low-pass, that low-pass under
  ``rest_bias``, and accelerometer within ``rest_acc`` of its low-pass, for
  ``rest_s`` seconds) b follows the low-passed gyro (time constant ``tau_rest``). As VQF's,
  the test does not compare the gyro with the bias estimate: one that starts at 0 would never
  see a part whose bias is beyond ``rest_gyro`` at rest. (VQF also estimates the bias in motion; an integral term on the corrections
  tried here made the recordings worse, so motion-time bias estimation is left out for now.)
There are no Euler angles in it, so it works at any attitude (no gimbal lock at ±90° pitch).

Start-up is causal (the gateware runs this filter sample by sample): the first sample sets the
inclination, the first usable field the heading. The fixed-point form that the attitude engine
runs, operation for operation, is ``reference/flagship_fixed.py`` (its cost:
``reference/FIXED_POINT.md``).
"""

import math

import numpy as np

from ..hdl.contract.numeric_contract import FlagshipParams, sample_counts, svf_gain
from .frames import filter_inputs


__all__ = ["flagship_filter", "run_float"]


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


def flagship_filter(gyr, acc, mag, dt, params=FlagshipParams(), *, mag_valid=None,
                    return_bias=False, mag_dt=None):
    """gyr rad/s, acc m/s² (any unit: only directions and deviations matter, rest_acc is in the
    same unit), mag any unit or None (6-axis). Returns quaternions body->ENU (N,4).

    Causal, as the gateware must be: the first sample starts the filter (q_g = q_a = 1, the
    inclination step then tilts q_a onto that sample's specific force in one go), the heading
    δ is taken from the first usable field and then follows it. Times are sample counts
    (``sample_counts``); each countdown is decremented at the start of a sample. ``mag_dt``:
    the time between new fields (``mag_valid`` true), for the heading's and the reference's
    gains; ``dt`` if None (a field every sample)."""
    p = params
    gyr, acc, magv, valid = filter_inputs(gyr, acc, mag, mag_valid)
    n = len(gyr)
    use_mag = magv is not None
    gyr_l, acc_l = gyr.tolist(), acc.tolist()
    mag_l = magv.tolist() if use_mag else None
    k_rest, k_ref, k_fast, k_new = sample_counts(p, dt)

    qg = qa = (1.0, 0.0, 0.0, 0.0)
    delta = None
    # the low-passes start at the first sample
    lp, acc_lp, gyr_lp = (list(x[0]) if n else [] for x in (acc_l, acc_l, gyr_l))
    b = [0.0, 0.0, 0.0]
    f_acc = svf_gain(p.tau_acc, dt)
    band = [0.0, 0.0, 0.0]                      # the low-pass's second state
    a_rest = 1 - math.exp(-dt / p.tau_rest)
    a_det = 1 - math.exp(-dt / 0.5)
    # the heading's and the field reference's gains act once per new field: for its period
    # (``mag_dt``, ``FlagshipFixedConfig.mag_dt``; ``dt`` when every sample has one)
    mdt = dt if mag_dt is None else mag_dt
    a_mag, a_mag_fast = 1 - math.exp(-mdt / p.tau_mag), 1 - math.exp(-mdt / min(p.tau_mag, 0.2))
    rest_left, fast_left, ref_left, cand_left = k_rest, k_fast, k_ref, 0
    ref = None                          # (norm, dip)
    ref_norm = ref_dip = None           # the reference being learnt
    a_ref = 1 - math.exp(-mdt / p.tau_ref)
    cand = None                         # (norm, dip)
    out = np.empty((n, 4))
    biases = np.empty((n, 3))

    for k in range(n):
        fast_left, ref_left, cand_left = (max(0, t - 1) for t in (fast_left, ref_left,
                                                                   cand_left))
        g = gyr_l[k]
        a = acc_l[k]
        # -- rest detection and bias at rest ---------------------------------------------------
        for i in range(3):
            gyr_lp[i] += a_det * (g[i] - gyr_lp[i])
            acc_lp[i] += a_det * (a[i] - acc_lp[i])
        # still: the gyro near its own low-pass (whatever the bias: a part may read up to
        # ±5 °/s an axis at rest), the low-pass itself no faster than a bias can be
        # (``rest_bias``), the specific force near its low-pass
        dg = math.sqrt(sum((g[i] - gyr_lp[i]) ** 2 for i in range(3)))
        slow = math.sqrt(sum(gyr_lp[i] ** 2 for i in range(3)))
        da = math.sqrt(sum((a[i] - acc_lp[i]) ** 2 for i in range(3)))
        still = dg < p.rest_gyro and slow < p.rest_bias and da < p.rest_acc
        rest_left = max(0, rest_left - 1) if still else k_rest
        gb = [g[i] - b[i] for i in range(3)]
        if rest_left == 0:                  # at rest: the gyro reads its bias
            for i in range(3):
                b[i] += a_rest * (gyr_lp[i] - b[i])

        # -- strapdown ------------------------------------------------------------------------
        qg = _qnorm(_qmul(qg, _qexp(gb[0] * dt, gb[1] * dt, gb[2] * dt)))

        # -- inclination ----------------------------------------------------------------------
        if any(a):
            aI = _rot(qg, a)
            for i in range(3):
                lp[i] += f_acc * band[i]
                band[i] += f_acc * (aI[i] - lp[i] - math.sqrt(2) * band[i])
            e = _rot(qa, lp)
            s = math.hypot(e[0], e[1])
            if s > 0:
                # rotation taking e to up: axis e × z = (ey, −ex, 0)/s, angle atan2(s, ez)
                angle = math.atan2(s, e[2])
                qa = _qnorm(_qmul(_qexp(e[1] / s * angle, -e[0] / s * angle, 0.0), qa))
        qag = _qmul(qa, qg)

        # -- heading --------------------------------------------------------------------------
        if use_mag and valid[k] and any(mag_l[k]):
            mE = _rot(qag, mag_l[k])
            mn = math.sqrt(mE[0] * mE[0] + mE[1] * mE[1] + mE[2] * mE[2])
            horiz = math.hypot(mE[0], mE[1])
            if horiz > 0:
                dip = math.degrees(math.atan2(-mE[2], horiz))
                good = True
                if ref is None:
                    # a low-pass of the fields seen while the reference is learnt, from the
                    # first one on
                    if ref_norm is None:
                        ref_norm, ref_dip = mn, dip
                    else:
                        ref_norm += a_ref * (mn - ref_norm)
                        ref_dip += a_ref * (dip - ref_dip)
                    if ref_left == 0:
                        ref = (ref_norm, ref_dip)
                else:
                    good = abs(mn - ref[0]) < ref[0] * p.mag_norm_gate and \
                        abs(dip - ref[1]) < p.mag_dip_gate
                    if not good:
                        if cand is None or abs(mn - cand[0]) > cand[0] * p.mag_norm_gate \
                                or abs(dip - cand[1]) > p.mag_dip_gate / 2:
                            cand, cand_left = (mn, dip), k_new
                        elif cand_left == 0:
                            ref, cand = cand, None
                    else:
                        cand = None
                if good:
                    psi = math.atan2(mE[0], mE[1])          # field direction east of North
                    if delta is None:
                        delta = psi
                    else:
                        err = (psi - delta + math.pi) % (2 * math.pi) - math.pi
                        gain = a_mag_fast if fast_left else a_mag
                        delta = (delta + err * gain + math.pi) % (2 * math.pi) - math.pi

        d = 0.0 if delta is None else delta
        out[k] = _qmul((math.cos(d / 2), 0.0, 0.0, math.sin(d / 2)), qag)
        biases[k] = b
    return (out, biases) if return_bias else out


def run_float(gyr, acc, mag, dt, **params):
    """The filter as ``evaluate.run_filter`` runs it (its record in ``filter_registry``): gyr
    rad/s, acc m/s², mag µT -> quaternions body->ENU; ``params``: ``flagship``
    (``FlagshipParams``), ``mag_valid``, ``mag_dt``."""
    return flagship_filter(gyr, acc, mag, dt, params.get("flagship", FlagshipParams()),
                           mag_valid=params.get("mag_valid"), mag_dt=params.get("mag_dt"))
