"""The flagship filter in integers: ``reference.flagship`` step by step, in the datapath's
operations (``reference.fixed_point``: 32-bit registers, 32×32 products rounded once, the
CORDIC, the divider), so that it can become a microcode sequence of the attitude engine.

Formats (FIXED_POINT.md, "Flagship filter")
    quaternions q_g, q_a, the output: Q2.30 (2³⁰ = 1)
    heading δ, dip, CORDIC angles: BAM32
    gyro, its low-pass and the bias: Q16.16 gyro counts
    accelerometer low-passes (body and inertial frame), rotated field: Q16.16 counts
    rotation vector per sample v = (ω − b)·T: Q2.30 radians
    low-pass gains 1 − exp(−T/τ): Q0.30
Inputs: calibrated body-axis counts (gyro, accelerometer, magnetometer), as ``kalman_fixed``.
"""

import math
from dataclasses import dataclass

import numpy as np

from .fixed_point import (INV_GAIN_Q30, Status, cordic_rotate, cordic_vector, mac, mul, sat32,
                          tilt_angles, wrap32)
from .flagship import FlagshipParams


__all__ = ["FlagshipFixedConfig", "flagship_fixed", "q30_to_float"]

ONE = 1 << 30


def _first_index(seconds, dt, strict=False):
    """The first sample index k with k·dt ≥ seconds (> with ``strict``), as the float filter
    decides it."""
    k = max(0, int(seconds / dt) - 2)
    while (k * dt <= seconds) if strict else (k * dt < seconds):
        k += 1
    return k


@dataclass(frozen=True)
class FlagshipFixedConfig:
    """Run-time registers of the fixed-point flagship, from the float parameters."""
    dt: float
    gyro_lsb_per_rad: float
    accel_lsb_per_ms2: float
    params: FlagshipParams = FlagshipParams()

    def registers(self):
        p, dt = self.params, self.dt
        gain = lambda tau: int(round((1 - math.exp(-dt / tau)) * ONE))      # Q0.30
        rest_gyro = p.rest_gyro * self.gyro_lsb_per_rad * 2 ** 8           # Q.8 counts
        rest_acc = p.rest_acc * self.accel_lsb_per_ms2 * 2 ** 8
        return {
            # v [Q2.30 rad] = (ω·2¹⁶ − b) · K_RAD >> 32
            "K_RAD": int(round(dt / self.gyro_lsb_per_rad * 2 ** 14 * 2 ** 32)),
            "A_DET": gain(0.5), "A_REST": gain(p.tau_rest), "A_ACC": gain(p.tau_acc),
            "A_MAG": gain(p.tau_mag), "A_MAG_FAST": gain(min(p.tau_mag, 0.2)),
            # squared thresholds in (Q.8 counts)² >> 16
            "REST_GYRO2": int(round(rest_gyro ** 2 / 2 ** 16)),
            "REST_ACC2": int(round(rest_acc ** 2 / 2 ** 16)),
            "GATE_NORM": int(round(p.mag_norm_gate * ONE)),
            "GATE_DIP": int(round(p.mag_dip_gate / 360 * 2 ** 32)),
            "K_REST": _first_index(p.rest_s, dt), "K_REF": _first_index(p.mag_ref_s, dt),
            "K_FAST": _first_index(p.mag_fast_s, dt, strict=True),
            "K_NEW": _first_index(p.mag_new_s, dt, strict=True),
            "K_ALIGN": max(1, int(round(0.1 / dt))),
        }


def _qmul(p, q, st):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (mac([(pw, qw), (px, qx, -1), (py, qy, -1), (pz, qz, -1)], 30, st),
            mac([(pw, qx), (px, qw), (py, qz), (pz, qy, -1)], 30, st),
            mac([(pw, qy), (px, qz, -1), (py, qw), (pz, qx)], 30, st),
            mac([(pw, qz), (px, qy), (py, qx, -1), (pz, qw)], 30, st))


def _normalise(q, st):
    """One Newton step towards |q| = 1: q·(3 − |q|²)/2 (q stays within 10⁻⁶ of unit length,
    where this is as good as a division by the norm)."""
    n2 = mac([(c, c) for c in q], 30, st)
    f = sat32((3 * ONE - n2) >> 1, st)
    return tuple(mul(c, f, 30, st) for c in q)


def _matrix(q, st):
    """R(q) in Q2.30, row-major."""
    w, x, y, z = q
    p = lambda a, b: mul(a, b, 29, st)                 # 2·a·b
    xx, yy, zz = p(x, x), p(y, y), p(z, z)
    xy, xz, yz, wx, wy, wz = p(x, y), p(x, z), p(y, z), p(w, x), p(w, y), p(w, z)
    return (ONE - yy - zz, xy - wz, xz + wy,
            xy + wz, ONE - xx - zz, yz - wx,
            xz - wy, yz + wx, ONE - xx - yy)


def _rotate(m, v, st):
    return tuple(mac([(m[3 * i + j], v[j]) for j in range(3)], 30, st) for i in range(3))


def _inclination_quat(a, st):
    """q_a = Ry(pitch)·Rx(roll) putting ``a`` up, from CORDIC half-angle sines and cosines."""
    roll, pitch = tilt_angles(*a, st)
    cr, sr = cordic_rotate(roll >> 1)
    cp, sp = cordic_rotate(pitch >> 1)
    return (mul(cr, cp, 30, st), mul(sr, cp, 30, st), mul(cr, sp, 30, st),
            sat32(-mul(sr, sp, 30, st), st))


def _field(me, st):
    """(norm, dip BAM32, heading ψ BAM32) of a field vector in the tilt-corrected frame."""
    psi, hk = cordic_vector(me[1], me[0], st)           # atan2(mE_x, mE_y)
    horiz = mul(hk, INV_GAIN_Q30, 30, st)
    dip, nk = cordic_vector(horiz, sat32(-me[2], st), st)
    return mul(nk, INV_GAIN_Q30, 30, st), dip, psi, horiz


def flagship_fixed(gyr_counts, acc_counts, mag_counts, config, *, mag_valid=None):
    """Quaternions body->ENU in Q2.30 (N, 4) int, and the bias in Q16.16 counts (N, 3)."""
    reg = config.registers()
    st = Status()
    gyr = np.asarray(gyr_counts, np.int64).tolist()
    acc = np.asarray(acc_counts, np.int64).tolist()
    mag = None if mag_counts is None else np.asarray(mag_counts, np.int64).tolist()
    n = len(gyr)
    valid = [True] * n if mag_valid is None else [bool(v) for v in mag_valid]

    # start-up alignment from the sums (directions) of the first 0.1 s
    k0 = min(n, reg["K_ALIGN"])
    a_sum = [sat32(sum(acc[k][i] for k in range(k0)) << 8, st) for i in range(3)]
    qa = _inclination_quat(a_sum, st)
    delta = 0
    if mag is not None:
        m_sum = [sat32(sum(mag[k][i] for k in range(k0)) << 8, st) for i in range(3)]
        delta = _field(_rotate(_matrix(qa, st), m_sum, st), st)[2]
    qg = (ONE, 0, 0, 0)
    lp = [acc[0][i] << 16 for i in range(3)]
    gyr_lp = [gyr[0][i] << 16 for i in range(3)]
    acc_lp = [acc[0][i] << 16 for i in range(3)]
    b = [0, 0, 0]
    rest = 0
    ref = None                       # (norm, dip)
    ref_sum = [0, 0, 0]              # norm, dip, count
    cand = None                      # (norm, dip, k)
    out_q = np.empty((n, 4), np.int64)
    out_b = np.empty((n, 3), np.int64)

    for k in range(n):
        g16 = [gyr[k][i] << 16 for i in range(3)]
        a16 = [acc[k][i] << 16 for i in range(3)]
        # -- rest detection and bias at rest ---------------------------------------------------
        for i in range(3):
            gyr_lp[i] = sat32(gyr_lp[i] + mul(reg["A_DET"], sat32(g16[i] - gyr_lp[i], st), 30,
                                              st), st)
            acc_lp[i] = sat32(acc_lp[i] + mul(reg["A_DET"], sat32(a16[i] - acc_lp[i], st), 30,
                                              st), st)
        dg = [sat32(g16[i] - b[i], st) >> 8 for i in range(3)]          # Q.8 counts
        da = [sat32(a16[i] - acc_lp[i], st) >> 8 for i in range(3)]
        still = (mac([(d, d) for d in dg], 16) < reg["REST_GYRO2"]
                 and mac([(d, d) for d in da], 16) < reg["REST_ACC2"])
        rest = rest + 1 if still else 0
        if rest >= reg["K_REST"]:
            for i in range(3):
                b[i] = sat32(b[i] + mul(reg["A_REST"], sat32(gyr_lp[i] - b[i], st), 30, st), st)

        # -- strapdown: q_g ⊗ exp(v), v = (ω − b)·T, exp to second order -----------------------
        v = [mul(sat32(g16[i] - b[i], st), reg["K_RAD"], 32, st) for i in range(3)]
        v2 = mac([(x, x) for x in v], 30, st)
        c = sat32(ONE - (v2 >> 3), st)                                  # cos(|v|/2)
        s = sat32((ONE >> 1) - mul(v2, ONE // 48, 30, st), st)          # sin(|v|/2)/|v|
        qg = _normalise(_qmul(qg, (c, mul(v[0], s, 30, st), mul(v[1], s, 30, st),
                                   mul(v[2], s, 30, st)), st), st)
        mg = _matrix(qg, st)

        # -- inclination ----------------------------------------------------------------------
        aI = _rotate(mg, a16, st)
        for i in range(3):
            lp[i] = sat32(lp[i] + mul(reg["A_ACC"], sat32(aI[i] - lp[i], st), 30, st), st)
        e = _rotate(_matrix(qa, st), lp, st)
        phi, sk = cordic_vector(e[0], e[1], st)             # e_xy = s·(cos φ, sin φ)
        if sk != 0:
            s_xy = mul(sk, INV_GAIN_Q30, 30, st)
            theta, _ = cordic_vector(e[2], s_xy, st)        # angle from up: atan2(s, e_z)
            cphi, sphi = cordic_rotate(phi)
            ch, sh = cordic_rotate(theta >> 1)
            # rotation about (sin φ, −cos φ, 0) = (e_y, −e_x, 0)/s by θ takes e to up
            corr = (ch, mul(sphi, sh, 30, st), sat32(-mul(cphi, sh, 30, st), st), 0)
            qa = _normalise(_qmul(corr, qa, st), st)

        # -- heading --------------------------------------------------------------------------
        if mag is not None and valid[k]:
            m16 = [mag[k][i] << 16 for i in range(3)]
            me = _rotate(_matrix(qa, st), _rotate(mg, m16, st), st)
            mn, dip, psi, horiz = _field(me, st)
            if mn > 0 and horiz > 0:
                if ref is None:
                    ref_sum = [ref_sum[0] + mn, ref_sum[1] + dip, ref_sum[2] + 1]
                    if k >= reg["K_REF"]:
                        ref = (int(ref_sum[0] / ref_sum[2]), int(ref_sum[1] / ref_sum[2]))
                good = ref is None or (
                    abs(mn - ref[0]) < mul(ref[0], reg["GATE_NORM"], 30)
                    and abs(wrap32(dip - ref[1])) < reg["GATE_DIP"])
                if ref is not None and not good:
                    if cand is None or abs(mn - cand[0]) > mul(cand[0], reg["GATE_NORM"], 31) \
                            or abs(wrap32(dip - cand[1])) > reg["GATE_DIP"] >> 1:
                        cand = (mn, dip, k)
                    elif k - cand[2] >= reg["K_NEW"]:
                        ref, cand = (cand[0], cand[1]), None
                elif good:
                    cand = None
                if good:
                    gain = reg["A_MAG"] if k >= reg["K_FAST"] else reg["A_MAG_FAST"]
                    delta = wrap32(delta + mul(wrap32(psi - delta), gain, 30, st))

        ch, sh = cordic_rotate(delta >> 1)
        out_q[k] = _qmul((ch, 0, 0, sh), _qmul(qa, qg, st), st)
        out_b[k] = b
    return out_q, out_b


def q30_to_float(q):
    return np.asarray(q, float) / ONE
