"""Madgwick's gradient-descent filter in integers: ``reference.madgwick`` step by step, in the
datapath's operations (``reference.fixed_point``), as the attitude engine's microcode
(``hdl/engine/filters/madgwick.py``) runs it.

Formats (FIXED_POINT.md, "Madgwick filter")
    quaternion q (the engine's QOUT), rotation matrix R(q), unit vectors ŝ (accelerometer), m̂
    (field), the errors f: Q2.30
    half rotation per sample ½·ω·T: Q2.30 radians (gyro counts · K_RAD, halved)
    gradient G = ∇f / 16: Q2.30 (|∇f| ≤ 8, so |G|·K² stays inside the CORDIC's 32 bits)
    gradient step: BETA_K = β·T·K²·2³⁰ (``numeric_contract.MadgwickFixedConfig``)
Inputs: calibrated body-axis counts, as the other filters.

The float filter normalises the accelerometer, the field and the gradient exactly. This one
normalises the gradient by its length from three short vectoring CORDICs (8 iterations: the
length to 3·10⁻⁵) and one division, and a sensor vector v by ``v / |v|`` = mul(v·2⁸, y, 14)
with y = 2³⁶/|v| from the last sample's y by one Newton step when the length has changed by
under 3 % (``_unit``: within 0.15 % of unit length at worst, a few 10⁻⁵ for a vector a
hundred times its noise; the usual case, and the quick one), else afresh by two short
CORDICs and one division. One departure: a gradient too small for its step's quotient (|∇f|
below about 10⁻⁴ at 100 Hz: an error within the sensors' noise) takes no step, where the
float filter takes a whole β·T step in the noise's direction. The quaternion is renormalised
by one Newton step (the flagship's), as it stays within 10⁻⁶ of unit length. The first
sample after a reset or a switch to this filter starts from the accelerometer's tilt and the
tilt-compensated heading (the float filter's alignment) and integrates the gyro; the gradient
steps begin with the next sample (the float filter also takes one on the first sample, from a
gradient that the alignment has made all but zero).
"""

from dataclasses import dataclass

from ..hdl.contract.numeric_contract import MADGWICK_UNIT_BOUNDS
from .fixed_point import (CORDIC_SHORT_ITERATIONS, INV_GAIN_Q30, _heading, _tilt, cordic_vector,
                          div_q24, mac, mul, sat32, step_n)
from .flagship_fixed import (FLAGSHIP_CONSTANTS, HALF, ONE, _matrix, _normalise,
                             euler_quat_fixed, quat_angles_fixed)

THREE_HALVES = FLAGSHIP_CONSTANTS["THREE_HALVES"]


__all__ = ["MadgwickFixed", "engine_step"]


# The quick normalisation (``_unit``): taken when |v·y|² is within 1 ± 1/16 of one (Q.14 bounds),
# its inverse length kept as the next seed only from a vector over 128 counts (y < 2²⁹), so
# that no later vector is long enough against it to overflow |s|² (362 times the length).
UNIT_LO, UNIT_HI = MADGWICK_UNIT_BOUNDS
SEED_LIMIT = 1 << 29


def _length_k2(v8, st):
    """|v8|·K² from two short vectoring CORDICs (the first's length turned back by 1/K)."""
    _, rk = cordic_vector(v8[0], v8[1], st, CORDIC_SHORT_ITERATIONS)
    _, nk = cordic_vector(mul(rk, INV_GAIN_Q30, 30, st), v8[2], st, CORDIC_SHORT_ITERATIONS)
    return nk


def _unit(v, seed, st):
    """(v / |v| in Q2.30, the seed for the next sample), v in counts, not all 0.

    The inverse length y = 2³⁶/|v| (so that v/|v| = mul(v·2⁸, y, 14)) is the last sample's
    (``seed``) corrected by one Newton step, y·(3 − |v·y|²)/2, when |v·y|² is within 1/16 of
    one (the length changed by under 3 % since: |v|/|v| is then within 0.15 % of one, a few
    10⁻⁵ for a vector a hundred times its noise); otherwise it is computed afresh: |v| from
    two short CORDICs, one division (saturating, and flagging, for |v| under 32 counts)."""
    v8 = [mul(x, 1 << 22, 14, st) for x in v]                   # << 8
    s = [mul(x, seed, 14, st) for x in v]                       # v·y / 2¹⁴: v/|v| · 2²²
    n2 = mac([(c, c) for c in s], 30, st)                       # |s|², Q.14
    if sat32(n2 - UNIT_LO, st) >= 0 and sat32(UNIT_HI - n2, st) >= 0:
        c = sat32(THREE_HALVES - mul(n2, 1 << 29, 14, st), st)  # (3 − |s|²)/2, Q2.30
        y = keep = mul(seed, c, 30, st)
    else:
        nk = _length_k2(v8, st)
        y = div_q24(1 << 20, mul(nk, INV_GAIN_Q30, 30, st), st)   # 2⁴⁴ / |v·2⁸|
        keep = y if sat32(y - SEED_LIMIT, st) < 0 else 0
    return [mul(x, y, 14, st) for x in v8], keep


@dataclass
class MadgwickFixed:
    """State of the fixed-point Madgwick filter (the quaternion, the engine's QOUT, its
    rotation matrix, which the next step's gradient uses, and the inverse lengths the next
    normalisations start from) and one step; ``first``: the next sample aligns it."""
    reg: dict
    first: bool = True
    q: tuple = (ONE, 0, 0, 0)
    rm: tuple = ()
    seed_a: int = 0             # the inverse lengths ``_unit`` starts from (0: none)
    seed_m: int = 0

    def align(self, a, m, acc_ok, mag_ok, st):
        """The start: roll and pitch from the accelerometer, the tilt-compensated heading from
        the field (each 0 without its sensor), as a quaternion; the flags of what was used."""
        roll, pitch = _tilt(*a, st) if acc_ok else (0, 0)
        yaw = _heading(*m, roll, pitch, st) if mag_ok else 0
        self.q = euler_quat_fixed([roll, pitch, yaw], st)
        self.first = False
        self.seed_a = self.seed_m = 0               # this sample's lengths are found afresh
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
        hv = [mul(c, hk, 14, st) for c in g]            # ω·hk: exactly (ω·2¹⁶)·hk / 2³⁰
        qd = (mac([(x, hv[0], -1), (y, hv[1], -1), (z, hv[2], -1)], 30, st),
              mac([(w, hv[0]), (y, hv[2]), (z, hv[1], -1)], 30, st),
              mac([(w, hv[1]), (x, hv[2], -1), (z, hv[0])], 30, st),
              mac([(w, hv[2]), (x, hv[1]), (y, hv[0], -1)], 30, st))
        step = (0, 0, 0, 0)
        if acc_ok:
            # the unit vectors on the first sample too: its lengths seed the next one's
            s, self.seed_a = _unit(a, self.seed_a, st)
            if mag_ok:
                mh, self.seed_m = _unit(m, self.seed_m, st)
        if acc_ok and not first:
            flags.add("acc_used")
            grad = self._gradient(q, self.rm, s, mh if mag_ok else None, st)
            if mag_ok:
                flags.add("mag_used")
            # |G|·K² from three short vectoring CORDICs; the step β·T·n·G/|G|
            short = CORDIC_SHORT_ITERATIONS
            _, k01 = cordic_vector(grad[0], grad[1], st, short)
            _, k23 = cordic_vector(grad[2], grad[3], st, short)
            _, gk = cordic_vector(k01, k23, st, short)
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
    def _gradient(q, rm, s, mh, st):
        """G = ∇f / 16: the gravity term, and the field's with a unit field ``mh`` (None:
        none), each product of an eighth of the quaternion with an error term, summed in one
        accumulation. ``s``: the unit acceleration. ``rm``: R(q), as the last step's output
        computed it (q has not changed since)."""
        fa = [sat32(rm[6 + j] - s[j], st) for j in range(3)]              # Rᵀ·(0, 0, 1) − ŝ
        w8, x8, y8, z8 = (mul(c, 1 << 27, 30, st) for c in q)
        terms = [[(y8, fa[0], -1), (x8, fa[1])],
                 [(z8, fa[0]), (w8, fa[1]), (x8, fa[2], -1), (x8, fa[2], -1)],
                 [(w8, fa[0], -1), (z8, fa[1]), (y8, fa[2], -1), (y8, fa[2], -1)],
                 [(x8, fa[0]), (y8, fa[1])]]
        if mh is not None:
            h = [mac([(rm[3 * i + j], mh[j]) for j in range(3)], 30, st) for i in range(3)]
            _, byk = cordic_vector(h[0], h[1], st, CORDIC_SHORT_ITERATIONS)
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


def engine_step(reg, kf):
    """Madgwick's filter as the engine model runs it (its record in ``filter_registry``)."""
    return MadgwickFixed(reg)
