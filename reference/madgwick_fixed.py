"""Madgwick's gradient-descent filter in integers: ``reference.madgwick`` step by step, in the
datapath's operations (``reference.fixed_point``), as the attitude engine's microcode
(``hdl/filters/madgwick.py``) runs it.

Formats (FIXED_POINT.md, "Madgwick filter")
    quaternion q (the engine's QOUT), rotation matrix R(q), unit vectors ŝ (accelerometer), m̂
    (field), the errors f: Q2.30
    half rotation per sample ½·ω·T: Q2.30 radians (gyro counts · K_RAD, halved)
    gradient G = ∇f / 16: Q2.30 (|∇f| ≤ 8, so |G|·K² stays inside the CORDIC's 32 bits)
    gradient step: BETA_K = β·T·K²·2³⁰ (``numeric_contract.MadgwickFixedConfig``)
Inputs: calibrated body-axis counts, as the other filters.

The float filter normalises the accelerometer, the field and the gradient exactly; so does this
one, each length from two or three vectoring CORDICs and one division: ``v / |v|`` = mul(v·2⁸,
⌊2⁴⁴ / |v·2⁸|⌋, 14). One departure: a gradient too small for its step's quotient (|∇f| below
about 10⁻⁴ at 100 Hz: an error within the sensors' noise) takes no step, where the float filter
takes a whole β·T step in the noise's direction. The quaternion is renormalised by one Newton
step (the flagship's), as it stays within 10⁻⁶ of unit length. The first sample after a reset or
a switch to this filter starts from the accelerometer's tilt and the tilt-compensated heading
(the float filter's alignment) and integrates the gyro; the gradient steps begin with
the next sample (the float filter also takes one on the first sample, from a gradient that
the alignment has made all but zero).
"""

from dataclasses import dataclass

from .fixed_point import (INV_GAIN_Q30, _heading, _tilt, cordic_vector, div_q24, mac, mul, sat32,
                          step_n)
from .flagship_fixed import (HALF, ONE, _matrix, _normalise, euler_quat_fixed,
                             quat_angles_fixed)


__all__ = ["MadgwickFixed"]


def _unit(v, st):
    """v / |v| in Q2.30 (v: counts, not all 0): the length from two vectoring CORDICs, then
    one division. Saturates (and flags) for |v| under 32 counts."""
    v8 = [mul(x, 1 << 22, 14, st) for x in v]                   # << 8
    _, rk = cordic_vector(v8[0], v8[1], st)
    _, nk = cordic_vector(mul(rk, INV_GAIN_Q30, 30, st), v8[2], st)
    inv = div_q24(1 << 20, mul(nk, INV_GAIN_Q30, 30, st), st)   # 2⁴⁴ / |v·2⁸|
    return [mul(x, inv, 14, st) for x in v8]


@dataclass
class MadgwickFixed:
    """State of the fixed-point Madgwick filter (the quaternion, the engine's QOUT, and its
    rotation matrix, which the next step's gradient uses) and one step; ``first``: the next
    sample aligns it."""
    reg: dict
    first: bool = True
    q: tuple = (ONE, 0, 0, 0)
    rm: tuple = ()

    def align(self, a, m, acc_ok, mag_ok, st):
        """The start: roll and pitch from the accelerometer, the tilt-compensated heading from
        the field (each 0 without its sensor), as a quaternion; the flags of what was used."""
        roll, pitch = _tilt(*a, st) if acc_ok else (0, 0)
        yaw = _heading(*m, roll, pitch, st) if mag_ok else 0
        self.q = euler_quat_fixed([roll, pitch, yaw], st)
        self.first = False
        return ({"acc_used"} if acc_ok else set()) | ({"mag_used"} if mag_ok else set())

    def step(self, g, a, m, mag_valid, st, periods=1):
        """One calibrated sample (counts), ``periods`` sample periods after the previous one.
        Returns (quaternion, angles, flags), flags among acc_used and mag_used."""
        reg = self.reg
        k = step_n(reg["K_RAD"], periods, st)
        bn = step_n(reg["BETA_K"], periods, st)
        acc_ok = any(a)
        mag_ok = bool(mag_valid) and any(m)
        first = self.first
        flags = self.align(a, m, acc_ok, mag_ok, st) if first else set()
        w, x, y, z = q = self.q
        # ½·q ⊗ (0, ω)·T
        hk = mul(k, HALF, 30, st)
        hv = [mul(mul(c, ONE, 14, st), hk, 30, st) for c in g]
        qd = (mac([(x, hv[0], -1), (y, hv[1], -1), (z, hv[2], -1)], 30, st),
              mac([(w, hv[0]), (y, hv[2]), (z, hv[1], -1)], 30, st),
              mac([(w, hv[1]), (x, hv[2], -1), (z, hv[0])], 30, st),
              mac([(w, hv[2]), (x, hv[1]), (y, hv[0], -1)], 30, st))
        step = (0, 0, 0, 0)
        if acc_ok and not first:
            flags.add("acc_used")
            grad = self._gradient(q, self.rm, a, m, mag_ok, st)
            if mag_ok:
                flags.add("mag_used")
            # |G|·K² from three vectoring CORDICs; the step β·T·n·G/|G|
            _, k01 = cordic_vector(grad[0], grad[1], st)
            _, k23 = cordic_vector(grad[2], grad[3], st)
            _, gk = cordic_vector(k01, k23, st)
            # a gradient so small that β·T·n / |G| leaves 32 bits (|∇f| under about 10⁻⁴: the
            # error is the sensors' noise) takes no step, rather than a saturated one
            if sat32(mul(bn, 1 << 23, 30, st) - gk, st) < 0:            # |G|·K² > β·T·n / 2⁷
                r = div_q24(bn, gk, st)
                step = tuple(mul(c, r, 24, st) for c in grad)
        qn = [sat32(sat32(q[i] + qd[i], st) - step[i], st) for i in range(4)]
        self.q = _normalise(qn, st)
        self.rm = _matrix(self.q, st)
        return self.q, quat_angles_fixed(self.rm, 0, st), flags

    @staticmethod
    def _gradient(q, rm, a, m, mag_ok, st):
        """G = ∇f / 16: the gravity term, and the field's with ``mag_ok``, each product of an
        eighth of the quaternion with an error term, summed in one accumulation. ``rm``: R(q),
        as the last step's output computed it (q has not changed since)."""
        s = _unit(a, st)
        fa = [sat32(rm[6 + j] - s[j], st) for j in range(3)]              # Rᵀ·(0, 0, 1) − ŝ
        w8, x8, y8, z8 = (mul(c, 1 << 27, 30, st) for c in q)
        terms = [[(y8, fa[0], -1), (x8, fa[1])],
                 [(z8, fa[0]), (w8, fa[1]), (x8, fa[2], -1), (x8, fa[2], -1)],
                 [(w8, fa[0], -1), (z8, fa[1]), (y8, fa[2], -1), (y8, fa[2], -1)],
                 [(x8, fa[0]), (y8, fa[1])]]
        if mag_ok:
            mh = _unit(m, st)
            h = [mac([(rm[3 * i + j], mh[j]) for j in range(3)], 30, st) for i in range(3)]
            _, byk = cordic_vector(h[0], h[1], st)
            by, bz = mul(byk, INV_GAIN_Q30, 30, st), h[2]               # b = (0, |h_xy|, h_z)
            fm = [mac([(rm[3 + j], by), (rm[6 + j], bz), (mh[j], ONE, -1)], 30, st)
                  for j in range(3)]                                     # Rᵀ·b − m̂
            pb = [mul(by, f, 30, st) for f in fm]
            qb = [mul(bz, f, 30, st) for f in fm]
            terms[0] += [(z8, pb[0]), (y8, qb[0], -1), (x8, qb[1]), (x8, pb[2], -1)]
            terms[1] += [(y8, pb[0]), (z8, qb[0]), (x8, pb[1], -1), (x8, pb[1], -1),
                         (w8, qb[1]), (w8, pb[2], -1), (x8, qb[2], -1), (x8, qb[2], -1)]
            terms[2] += [(x8, pb[0]), (w8, qb[0], -1), (z8, qb[1]), (z8, pb[2]),
                         (y8, qb[2], -1), (y8, qb[2], -1)]
            terms[3] += [(w8, pb[0]), (x8, qb[0]), (z8, pb[1], -1), (z8, pb[1], -1),
                         (y8, qb[1]), (y8, pb[2])]
        return [mac(t, 30, st) for t in terms]
