"""The flagship filter in integers: ``reference.flagship`` step by step, in the datapath's
operations (``reference.fixed_point``: 32-bit registers, 32×32 products rounded once with the
engine's shifts 14/24/29/30, the CORDIC, the divider), as the attitude engine's microcode runs it.

Formats (FIXED_POINT.md, "Flagship filter")
    quaternions q_g, q_a, q_a⊗q_g, the output: Q2.30 (2³⁰ = 1); rotation matrices Q2.30
    heading δ, dip, CORDIC angles: BAM32
    gyro, its low-pass and the bias: Q16.16 gyro counts
    accelerometer low-passes (body and inertial frame), rotated field: Q16.16 counts
    field norm: Q16.16 counts
    rotation vector per sample v = (ω − b)·T: Q2.30 radians
    low-pass gains 1 − exp(−T/τ): Q0.30
Inputs: calibrated body-axis counts (gyro, accelerometer, magnetometer), as ``kalman_fixed``.

``FlagshipFixed`` holds the state and does one sample (``step``); ``flagship_fixed`` runs it
over arrays; ``engine_outputs`` gives what the engine reports for any filter (quaternion and
angles), so that the per-axis filters' results carry a quaternion too.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from ..hdl.contract.numeric_contract import FlagshipFixedConfig
from .fixed_point import (INV_GAIN_Q30, Status, cordic_rotate, cordic_vector, mac, mul, sat32,
                          step_n, tilt_angles, wrap32)


__all__ = ["FlagshipFixed", "engine_step", "flagship_fixed",
           "q30_to_float", "euler_quat_fixed", "quat_angles_fixed", "FLAGSHIP_CONSTANTS", "ONE", "HALF"]

ONE = 1 << 30
HALF = 1 << 29                 # mul(x, HALF, 30) = x / 2 rounded half up
# Constants the microcode multiplies or adds with (register-file words no program writes).
FLAGSHIP_CONSTANTS = {
    "ONE": ONE,                # also: mul(x, ONE, 14) = x << 16
    "HALF": HALF,
    "EIGHTH": 1 << 27,         # mul(x, EIGHTH, 30) = x / 8 rounded
    "ONE_48": ONE // 48,       # 1/48 in Q0.30
    "THREE_HALVES": 3 << 29,   # 1.5 in Q2.30
    "SHR10": 1 << 20,          # mul(x, SHR10, 30) = x / 2¹⁰ rounded
    "INT1": 1,
    "SQRT2": round(math.sqrt(2) * 2 ** 30),   # √2 in Q2.30: the Butterworth's damping 2ζ
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
    f = sat32(FLAGSHIP_CONSTANTS["THREE_HALVES"] - mul(n2, HALF, 30, st), st)
    return tuple(mul(c, f, 30, st) for c in q)


def _matrix(q, st):
    """R(q) in Q2.30, row-major; the doubled products 2·a·b as mul(a, b, 29)."""
    w, x, y, z = q
    p = lambda a, b: mul(a, b, 29, st)
    xx, yy, zz = p(x, x), p(y, y), p(z, z)
    xy, xz, yz, wx, wy, wz = p(x, y), p(x, z), p(y, z), p(w, x), p(w, y), p(w, z)
    s = lambda a, b: sat32(a - b, st)
    a = lambda a, b: sat32(a + b, st)
    return (s(s(ONE, yy), zz), s(xy, wz), a(xz, wy),
            a(xy, wz), s(s(ONE, xx), zz), s(yz, wx),
            s(xz, wy), a(yz, wx), s(s(ONE, xx), yy))


def _rotate(m, v, st):
    return tuple(mac([(m[3 * i + j], v[j]) for j in range(3)], 30, st) for i in range(3))


def _abs(x, st):
    return sat32(-x, st) if x < 0 else x


def euler_quat_fixed(angles, st):
    """Body->ENU quaternion (Q2.30) of ZYX angles (roll, pitch, yaw BAM32): the per-axis
    filters' results carry it."""
    (cr, sr), (cp, sp), (cy, sy) = (cordic_rotate(mul(t, HALF, 30, st)) for t in angles)
    cc, ss = mul(cy, cp, 30, st), mul(sy, sp, 30, st)
    cs, sc = mul(cy, sp, 30, st), mul(sy, cp, 30, st)
    return (mac([(cr, cc), (sr, ss)], 30, st), mac([(sr, cc), (cr, ss, -1)], 30, st),
            mac([(cr, cs), (sr, sc)], 30, st), mac([(cr, sc), (sr, cs, -1)], 30, st))


def quat_angles_fixed(m, delta, st):
    """ZYX angles (BAM32) of Rz(δ)·R, R a rotation matrix (Q2.30): roll and pitch from R's
    bottom row (Rz leaves it alone), yaw = δ + atan2(R10, R00)."""
    roll, pitch = tilt_angles(m[6], m[7], m[8], st)
    yaw, _ = cordic_vector(m[0], m[3], st)
    return [roll, pitch, wrap32(delta + yaw)]


@dataclass
class FlagshipFixed:
    """State of the fixed-point flagship (the engine's registers of the same names) and one
    step. ``bias`` is shared with the per-axis Kalman filter (the same Q16.16 format)."""
    reg: dict
    bias: list = field(default_factory=lambda: [0, 0, 0])
    first: bool = True

    def start(self, g16, a16):
        """The first sample after a reset or a switch to this filter (bias kept)."""
        reg = self.reg
        self.qg = self.qa = (ONE, 0, 0, 0)
        self.delta, self.delta_ok = 0, False
        self.lp, self.acc_lp, self.gyr_lp = list(a16), list(a16), list(g16)
        self.band = [0, 0, 0]
        self.rest_left, self.fast_left = reg["K_REST"], reg["K_FAST"]
        self.ref_left, self.cand_left = reg["K_REF"], 0
        self.ref_ok, self.ref_seen, self.ref_norm, self.ref_dip = False, False, 0, 0
        self.cand_norm, self.cand_dip = 0, 0                    # norm 0: no candidate
        self.first = False

    def step(self, g, a, m, mag_valid, st, periods=1):
        """One calibrated sample (counts) ``periods`` sample periods after the previous one.
        Returns (quaternion, angles, flags): flags is the set of names among acc_used,
        mag_used, mag_disturbed, mag_new_ref, at_rest, bias_updated."""
        reg, b = self.reg, self.bias
        # the strapdown step rotates by every period since the last sample (computed first,
        # as the microcode does, so that a saturation flags alike on every path)
        k_rad = step_n(reg["K_RAD"], periods, st)
        flags = set()
        g16 = [mul(x, ONE, 14, st) for x in g]                  # << 16
        a16 = [mul(x, ONE, 14, st) for x in a]
        if self.first:
            self.start(g16, a16)
        dec = lambda t: t - 1 if t else 0
        self.fast_left, self.ref_left, self.cand_left = (dec(t) for t in (
            self.fast_left, self.ref_left, self.cand_left))

        # -- rest detection and bias at rest ------------------------------------------------------
        for i in range(3):
            self.gyr_lp[i] = sat32(self.gyr_lp[i] + mul(reg["A_DET"], sat32(
                g16[i] - self.gyr_lp[i], st), 30, st), st)
            self.acc_lp[i] = sat32(self.acc_lp[i] + mul(reg["A_DET"], sat32(
                a16[i] - self.acc_lp[i], st), 30, st), st)
        u = [sat32(g16[i] - b[i], st) for i in range(3)]         # ω − b, Q16.16
        # still: the gyro near its low-pass, the low-pass itself under rest_bias, the specific
        # force near its low-pass; every sum formed, as the microcode forms them
        shr10 = FLAGSHIP_CONSTANTS["SHR10"]
        dg = [mul(sat32(g16[i] - self.gyr_lp[i], st), shr10, 30, st) for i in range(3)]
        da = [mul(sat32(a16[i] - self.acc_lp[i], st), shr10, 30, st) for i in range(3)]
        db = [mul(x, shr10, 30, st) for x in self.gyr_lp]
        sums = (sat32(mac([(d, d) for d in dg], 14, st) - reg["REST_GYRO2"], st),
                sat32(mac([(d, d) for d in da], 14, st) - reg["REST_ACC2"], st),
                sat32(mac([(d, d) for d in db], 14, st) - reg["REST_BIAS2"], st))
        still = all(x < 0 for x in sums)
        self.rest_left = dec(self.rest_left) if still else reg["K_REST"]
        if self.rest_left == 0:
            flags |= {"at_rest", "bias_updated"}
            for i in range(3):
                b[i] = sat32(b[i] + mul(reg["A_REST"], sat32(self.gyr_lp[i] - b[i], st), 30,
                                        st), st)

        # -- strapdown: q_g ⊗ exp(v), v = (ω − b)·T, exp to second order -------------------------
        v = [mul(x, k_rad, 30, st) for x in u]
        v2 = mac([(x, x) for x in v], 30, st)
        c = sat32(ONE - mul(v2, FLAGSHIP_CONSTANTS["EIGHTH"], 30, st), st)       # cos(|v|/2)
        s = sat32(HALF - mul(v2, FLAGSHIP_CONSTANTS["ONE_48"], 30, st), st)      # sin(|v|/2)/|v|
        self.qg = _normalise(_qmul(self.qg, (c, *(mul(x, s, 30, st) for x in v)), st), st)

        # -- inclination --------------------------------------------------------------------------
        if any(a):
            a_i = _rotate(_matrix(self.qg, st), a16, st)
            # second-order low-pass (state-variable form): lp += f·band, then
            # band += f·(a_I − lp − √2·band), each axis, in the microcode's order
            for i in range(3):
                self.lp[i] = sat32(self.lp[i] + mul(reg["A_ACC"], self.band[i], 30, st), st)
            for i in range(3):
                d = sat32(sat32(a_i[i] - self.lp[i], st)
                          - mul(self.band[i], FLAGSHIP_CONSTANTS["SQRT2"], 30, st), st)
                self.band[i] = sat32(self.band[i] + mul(reg["A_ACC"], d, 30, st), st)
            e = _rotate(_matrix(self.qa, st), self.lp, st)
            phi, sk = cordic_vector(e[0], e[1], st)              # e_xy = s·(cos φ, sin φ)
            if sk != 0:
                flags.add("acc_used")
                s_xy = mul(sk, INV_GAIN_Q30, 30, st)
                theta, _ = cordic_vector(e[2], s_xy, st)        # angle from up: atan2(s, e_z)
                cphi, sphi = cordic_rotate(phi)
                ch, sh = cordic_rotate(mul(theta, HALF, 30, st))
                # rotation about (sin φ, −cos φ, 0) by θ takes e to up: (ch, sφ·sh, −cφ·sh, 0)
                cx, cy = mul(sphi, sh, 30, st), sat32(-mul(cphi, sh, 30, st), st)
                qw, qx, qy, qz = self.qa
                self.qa = _normalise((mac([(ch, qw), (cx, qx, -1), (cy, qy, -1)], 30, st),
                                      mac([(ch, qx), (cx, qw), (cy, qz)], 30, st),
                                      mac([(ch, qy), (cx, qz, -1), (cy, qw)], 30, st),
                                      mac([(ch, qz), (cx, qy), (cy, qx, -1)], 30, st)), st)
        qag = _qmul(self.qa, self.qg, st)
        rag = _matrix(qag, st)

        # -- heading ------------------------------------------------------------------------------
        if mag_valid and any(m):
            me = _rotate(rag, [mul(x, ONE, 14, st) for x in m], st)
            psi, hk = cordic_vector(me[1], me[0], st)           # atan2(mE_x, mE_y)
            horiz = mul(hk, INV_GAIN_Q30, 30, st)
            if horiz != 0:
                dip, nk = cordic_vector(horiz, sat32(-me[2], st), st)
                mn = mul(nk, INV_GAIN_Q30, 30, st)
                good = self._gate(mn, dip, flags, st)
                if good:
                    flags.add("mag_used")
                    if not self.delta_ok:
                        self.delta, self.delta_ok = psi, True
                    else:
                        gain = reg["A_MAG_FAST"] if self.fast_left else reg["A_MAG"]
                        self.delta = wrap32(self.delta + mul(wrap32(psi - self.delta), gain, 30,
                                                             st))

        # -- output -------------------------------------------------------------------------------
        ch, sh = cordic_rotate(mul(self.delta, HALF, 30, st))
        w, x, y, z = qag
        q = (mac([(ch, w), (sh, z, -1)], 30, st), mac([(ch, x), (sh, y, -1)], 30, st),
             mac([(ch, y), (sh, x)], 30, st), mac([(ch, z), (sh, w)], 30, st))
        return q, quat_angles_fixed(rag, self.delta, st), flags

    def _gate(self, mn, dip, flags, st):
        """The magnetic disturbance gate (norm and dip against the reference); learns the
        reference first, adopts a steady new field as the reference after K_NEW samples."""
        reg = self.reg
        if not self.ref_ok:
            # learning: the first field, then ref += mul(A_REF, x − ref, 30)
            if not self.ref_seen:
                self.ref_norm, self.ref_dip, self.ref_seen = mn, dip, True
            else:
                self.ref_norm = sat32(self.ref_norm + mul(sat32(mn - self.ref_norm, st),
                                                          reg["A_REF"], 30, st), st)
                self.ref_dip = sat32(self.ref_dip + mul(sat32(dip - self.ref_dip, st),
                                                        reg["A_REF"], 30, st), st)
            if self.ref_left == 0:
                self.ref_ok = True
                flags.add("mag_new_ref")
            return True
        norm_lim = mul(self.ref_norm, reg["GATE_NORM"], 30, st)
        good = (sat32(_abs(sat32(mn - self.ref_norm, st), st) - norm_lim, st) < 0 and
                sat32(_abs(wrap32(dip - self.ref_dip), st) - reg["GATE_DIP"], st) < 0)
        if good:
            self.cand_norm = 0
            return True
        flags.add("mag_disturbed")
        half_dip = mul(reg["GATE_DIP"], HALF, 30, st)
        moved = (self.cand_norm == 0
                 or sat32(mul(self.cand_norm, reg["GATE_NORM"], 30, st) - _abs(sat32(
                     mn - self.cand_norm, st), st), st) < 0
                 or sat32(half_dip - _abs(wrap32(dip - self.cand_dip), st), st) < 0)
        if moved:
            self.cand_norm, self.cand_dip, self.cand_left = mn, dip, reg["K_NEW"]
        elif self.cand_left == 0:
            self.ref_norm, self.ref_dip, self.cand_norm = self.cand_norm, self.cand_dip, 0
            flags.add("mag_new_ref")
        return False


def engine_step(reg, kf):
    """The flagship as the engine model runs it (its record in ``filter_registry``): its bias
    the per-axis Kalman filter's (``kf.bias``, the same Q16.16 words)."""
    return FlagshipFixed(reg, kf.bias)


def flagship_fixed(gyr_counts, acc_counts, mag_counts, config=FlagshipFixedConfig(), *,
                   mag_valid=None):
    """Quaternions body->ENU in Q2.30 (N, 4) int, and the bias in Q16.16 counts (N, 3), of
    calibrated body-axis counts (``mag_counts`` None: six axes)."""
    f = FlagshipFixed(config.registers())
    gyr = np.asarray(gyr_counts, np.int64).tolist()
    acc = np.asarray(acc_counts, np.int64).tolist()
    n = len(gyr)
    mag = [[0, 0, 0]] * n if mag_counts is None else np.asarray(mag_counts, np.int64).tolist()
    valid = [mag_counts is not None] * n if mag_valid is None else [bool(v) for v in mag_valid]
    out_q = np.empty((n, 4), np.int64)
    out_b = np.empty((n, 3), np.int64)
    for k in range(n):
        out_q[k] = f.step(gyr[k], acc[k], mag[k], valid[k], Status())[0]
        out_b[k] = f.bias
    return out_q, out_b


def q30_to_float(q):
    return np.asarray(q, float) / ONE
