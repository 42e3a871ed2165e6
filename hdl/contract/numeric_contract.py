"""The numeric contract between the gateware and the reference: what both must agree on, in one
place that both import (the gateware imports nothing else from ``reference/``).

- The CORDIC's ROM: ``CORDIC_ITERATIONS``, ``ATAN_TABLE`` (atan 2⁻ⁱ in BAM32, rounded to
  nearest) and ``INV_GAIN_Q30`` (1/K in Q1.30), written out as the gateware holds them. The
  reference computes its own from ``math.atan`` (``reference.fixed_point``) and a test checks
  that the two agree, so neither is a copy of the other.
- The run-time registers of the filters and the calibration, from values in physical units:
  ``KalmanFixedConfig`` (per-step values of the per-axis filters), ``FilterRates`` (the same in
  rates, valid at any sample rate), ``FlagshipParams`` / ``FlagshipFixedConfig`` (the flagship
  filter) and ``CalibrationFixed``. Each ``registers()`` gives the integer each register holds,
  by its name in the engine's register map (``hdl/engine/register_map.py``); the formats are
  ``reference/FIXED_POINT.md``'s.

Plain Python (no Amaranth): the host tools and the reference import it too.
"""

import math
from dataclasses import dataclass


__all__ = ["CONTROL_RESET", "CONTROL_KEEP", "CONTROL_BITS", "control_code_bits", "control_fields",
           "CORDIC_ITERATIONS", "CORDIC_SHORT_ITERATIONS", "ATAN_TABLE", "INV_GAIN_Q30",
           "CalibrationFixed", "calibration_registers", "calibration_of",
           "KalmanFixedConfig", "FilterRates", "FlagshipParams", "svf_gain", "sample_counts",
           "AK8963_RATE_HZ", "mag_period", "FlagshipFixedConfig", "CORDIC_GAIN_SQUARED",
           "MadgwickFixedConfig", "MADGWICK_UNIT_BOUNDS"]


# The engine's CONTROL register (0xFF): bits 1:0 the filter's code, bit 2 reset the filter
# state, bit 3 keep the filter (the code ignored); beyond four filters the code's higher bits in
# bits 5:4 (``control_code_bits``); the bits above are reserved and must be 0.
CONTROL_RESET = 1 << 2
CONTROL_KEEP = 1 << 3
CONTROL_BITS = 4


def control_code_bits(filter_count):
    """The bits of a filter code for ``filter_count`` filters: 2 (CONTROL bits 1:0) up to
    four, then one more per doubling (in CONTROL bits 4, 5, ...)."""
    return max(2, (filter_count - 1).bit_length())


def control_fields(value, filter_count):
    """What the engine does with a CONTROL word ``value`` (an integer as the host writes it,
    signed or not) when it has ``filter_count`` filters: ``(code, reset)`` with ``code`` the
    filter selected (None: keep the present one), or None when the word is refused (counted
    in ``cfg_refused``, nothing changes): a reserved bit set, or, without keep, a code that
    names no filter. The gateware (``hdl/engine/host_port.py``) implements the same rule."""
    value &= 0xFFFF_FFFF
    high = control_code_bits(filter_count) - 2          # the code's bits in CONTROL 4 and up
    if value >> (CONTROL_BITS + high):
        return None
    keep = bool(value & CONTROL_KEEP)
    code = (value & 0b11) | (value >> CONTROL_BITS) << 2
    if not keep and code >= filter_count:
        return None
    return (None if keep else code), bool(value & CONTROL_RESET)


# ones in the register formats Q2.14, Q8.24 and Q2.30
_Q14, _Q24, _Q30 = 1 << 14, 1 << 24, 1 << 30

# 16 iterations leave at most atan(2⁻¹⁵) = 0.0018° of angle: far below the sensors' noise, and
# a shift amount of 4 bits and a 16-entry table in the gateware
CORDIC_ITERATIONS = 16
# a short VEC (a length, its angle unused) stops after 8: within 3·10⁻⁵ of the length
CORDIC_SHORT_ITERATIONS = 8
ATAN_TABLE = (0x20000000, 0x12e4051e, 0x09fb385b, 0x051111d4, 0x028b0d43, 0x0145d7e1,
              0x00a2f61e, 0x00517c55, 0x0028be53, 0x00145f2f, 0x000a2f98, 0x000517cc,
              0x00028be6, 0x000145f3, 0x0000a2fa, 0x0000517d)
# 1/K, K = ∏ √(1 + 2⁻²ⁱ) over the 16 iterations: rotation mode starts from (1/K, 0) so cos and
# sin come out unscaled; vectoring magnitudes are multiplied by it for the true length
INV_GAIN_Q30 = 0x26dd3b6a


# -- calibration ------------------------------------------------------------------------------

@dataclass(frozen=True)
class CalibrationFixed:
    """Run-time calibration registers (integers; FIXED_POINT.md, "Calibration").

    gyro_offset: counts; accel_offset: counts; accel_scale: Q2.14 (16384 = 1);
    hard_iron: counts in body axes, after the ASA adjustment; soft_iron: 3×3 row-major, Q2.14.
    """
    gyro_offset: tuple = (0, 0, 0)
    accel_offset: tuple = (0, 0, 0)
    accel_scale: tuple = (_Q14, _Q14, _Q14)
    hard_iron: tuple = (0, 0, 0)
    soft_iron: tuple = (_Q14, 0, 0, 0, _Q14, 0, 0, 0, _Q14)

    @classmethod
    def from_units(cls, *, gyro_offset=(0, 0, 0), accel_offset=(0, 0, 0),
                   accel_scale=(1, 1, 1), hard_iron=(0, 0, 0), soft_iron=None):
        """From calibration results in counts (``reference.calibration``): offsets rounded,
        scale factors and the soft-iron matrix to Q2.14. ``accel_scale`` multiplies (use
        1/scale from ``accel_six_pose``); ``soft_iron`` 3 × 3, the identity if None."""
        import numpy as np              # only here: the gateware's elaboration needs none
        soft_iron = np.eye(3) if soft_iron is None else soft_iron
        r = lambda v: tuple(int(round(x)) for x in np.ravel(v))
        return cls(gyro_offset=r(gyro_offset), accel_offset=r(accel_offset),
                   accel_scale=r(np.asarray(accel_scale, float) * _Q14),
                   hard_iron=r(hard_iron), soft_iron=r(np.asarray(soft_iron, float) * _Q14))


def calibration_registers(cal):
    """A ``CalibrationFixed`` as register values by name (the engine's register map)."""
    regs = {}
    for i in range(3):
        regs[f"GYRO_OFF{i}"], regs[f"ACC_OFF{i}"] = cal.gyro_offset[i], cal.accel_offset[i]
        regs[f"ACC_SCALE{i}"], regs[f"HARD{i}"] = cal.accel_scale[i], cal.hard_iron[i]
        for j in range(3):
            regs[f"SOFT{i}{j}"] = cal.soft_iron[3 * i + j]
    return regs


def calibration_of(regs):
    """The ``CalibrationFixed`` that register values by name hold (``calibration_registers``
    backwards)."""
    return CalibrationFixed(
        gyro_offset=tuple(regs[f"GYRO_OFF{i}"] for i in range(3)),
        accel_offset=tuple(regs[f"ACC_OFF{i}"] for i in range(3)),
        accel_scale=tuple(regs[f"ACC_SCALE{i}"] for i in range(3)),
        hard_iron=tuple(regs[f"HARD{i}"] for i in range(3)),
        soft_iron=tuple(regs[f"SOFT{i}{j}"] for i in range(3) for j in range(3)))


# -- the per-axis filters ---------------------------------------------------------------------

@dataclass(frozen=True)
class KalmanFixedConfig:
    """Run-time registers of the filters (values in real units; ``registers`` gives their
    integer encodings, see FIXED_POINT.md)."""
    dt: float = 0.01
    gyro_lsb_per_dps: float = 16.4
    q_angle: float = 0.2         # deg²
    q_bias: float = 0.1          # (deg/s)²
    r: float = 2.0               # deg²
    p0: float = 1.0
    a: float = 0.98              # complementary filter coefficient
    euler_rates: bool = False    # propagate with Euler-angle rates, not body rates (the preset)

    def registers(self):
        regs = {
            # BAM per gyro count per sample period, Q14: Δθ = (ω_counts · RATE) >> 14
            "RATE": int(round(self.dt * 2 ** 32 / (360.0 * self.gyro_lsb_per_dps) * 2 ** 14)),
            "T": int(round(self.dt * _Q24)),                         # Q0.24 seconds
            "Q_ANGLE": int(round(self.q_angle * _Q24)),              # Q8.24 deg²
            "Q_BIAS": int(round(self.q_bias * _Q24)),                 # Q8.24 (deg/s)²
            "R": int(round(self.r * _Q24)),                          # Q8.24 deg²
            "P0": int(round(self.p0 * _Q24)),
            # Δb [Q16 counts] = (t [BAM/s] · BIAS_SCALE) >> 24: 360/2³² deg/BAM · LSB · 2¹⁶
            "BIAS_SCALE": int(round(360.0 * self.gyro_lsb_per_dps / 2 ** 16 * _Q24)),
            "ONE_MINUS_A": int(round((1 - self.a) * _Q24)),         # Q0.24
            "EULER_RATES": int(bool(self.euler_rates)),
        }
        if not 0 < regs["RATE"] < 2 ** 31:
            raise ValueError(f"RATE {regs['RATE']} does not fit 31 bits: dt "
                             f"{self.dt} s is too long for {self.gyro_lsb_per_dps} LSB/(°/s)")
        return regs


@dataclass(frozen=True)
class FilterRates:
    """The per-axis filters' coefficients in physical units, valid at any sample rate.

    ``q_angle`` (deg²/s) and ``q_bias`` ((°/s)²/s) are the process-noise densities of the
    Kalman filter's angle and gyro-bias states: per step they are multiplied by the sample
    period. ``r`` (deg²) is the variance of one accelerometer angle measurement and ``p0``
    (deg², (°/s)²) the initial covariance: both per measurement, whatever the rate. ``tau``
    (s) is the complementary filter's time constant: a = τ / (τ + dt).

    The defaults are the published per-step preset (Q angle 0.2 deg², Q bias 0.1 (°/s)²,
    R 2 deg², a = 0.98) at the rate it was published for, 100 Hz: ``at(0.01, ...)`` gives its
    registers exactly. ``euler_rates``: the per-axis filters propagate their angles with
    Euler-angle rates (right at any attitude short of ±90° pitch) instead of the published
    body rates.
    """
    q_angle: float = 20.0
    q_bias: float = 10.0
    r: float = 2.0
    p0: float = 1.0
    tau: float = 0.49
    euler_rates: bool = False

    def at(self, dt, gyro_lsb_per_dps=16.4):
        """The ``KalmanFixedConfig`` (per-step values) for sample period ``dt``."""
        if dt <= 0 or self.tau <= 0:
            raise ValueError("FilterRates.at: dt and tau must be positive")
        return KalmanFixedConfig(dt=dt, gyro_lsb_per_dps=gyro_lsb_per_dps,
                                 q_angle=self.q_angle * dt, q_bias=self.q_bias * dt, r=self.r,
                                 p0=self.p0, a=self.tau / (self.tau + dt),
                                 euler_rates=self.euler_rates)

    @classmethod
    def from_step(cls, config):
        """The physical values a per-step ``KalmanFixedConfig`` stands for at its own dt."""
        dt = config.dt
        return cls(q_angle=config.q_angle / dt, q_bias=config.q_bias / dt, r=config.r,
                   p0=config.p0, tau=config.a * dt / (1 - config.a),
                   euler_rates=config.euler_rates)


# -- the flagship filter ----------------------------------------------------------------------

@dataclass(frozen=True)
class FlagshipParams:
    """The flagship filter's parameters (``reference.flagship`` says what each does)."""
    tau_acc: float = 3.0            # s, second-order low-pass of the specific force (inertial)
    tau_mag: float = 15.0           # s, heading correction
    mag_fast_s: float = 3.0         # s of fast heading convergence at start-up
    mag_ref_s: float = 2.0          # s over which the reference field is learnt
    tau_ref: float = 0.5            # s, low-pass of the field's norm and dip while it is learnt
    # relative; VQF's 10 % let most of a magnet fixed to the board through (trial 33). A new
    # field counts as steady while its norm stays within this of its first value
    mag_norm_gate: float = 0.05
    mag_dip_gate: float = 10.0      # degrees
    mag_new_s: float = 20.0
    rest_gyro: float = math.radians(2.0)   # rad/s, the gyro's deviation from its low-pass
    # rad/s: at rest the low-passed gyro reads the bias, which may be this large (the MPU9250
    # allows ±5 °/s an axis, 8.7 °/s on all three); a steady turn faster than it is no rest
    rest_bias: float = math.radians(10.0)
    rest_acc: float = 0.5           # m/s²
    rest_s: float = 1.5
    tau_rest: float = 3.0


def svf_gain(tau, dt):
    """The gain f = 2·sin(π·f_c·T) of a state-variable (Chamberlin) low-pass with VQF's cut-off
    for a time constant ``tau``, f_c = √2/(2π·tau), at sample period ``dt`` (``T``). With the
    damping √2 it is a second-order Butterworth low-pass: low += f·band; band += f·(x − low −
    √2·band)."""
    return 2 * math.sin(math.pi * math.sqrt(2) / (2 * math.pi * tau) * dt)


def sample_counts(params, dt):
    """The flagship's times as whole sample counts, shared by the float and the fixed-point
    filter so that both switch at the same sample: (K_REST, K_REF, K_FAST, K_NEW)."""
    k = lambda seconds: max(1, int(round(seconds / dt)))
    return k(params.rest_s), k(params.mag_ref_s), k(params.mag_fast_s), k(params.mag_new_s)


# The AK8963's measurement rate in the mode the driver runs it (continuous mode 2).
AK8963_RATE_HZ = 100.0


def mag_period(dt, magnetometer=True):
    """The time between two new magnetometer fields at sample period ``dt``: the AK8963
    measures at ``AK8963_RATE_HZ``, so at a faster sample rate only one sample in
    ``dt``/(1/100 s) brings a new field (``None`` without a magnetometer)."""
    return max(dt, 1 / AK8963_RATE_HZ) if magnetometer else None


@dataclass(frozen=True)
class FlagshipFixedConfig:
    """Run-time registers of the fixed-point flagship, from the float parameters.
    ``mag_dt``: the time between two new magnetometer fields (``mag_period``); the heading's
    gains (``A_MAG``, ``A_MAG_FAST``) and the field reference's (``A_REF``) act once per new
    field, so they are set for it: its time constants are then ``tau_mag``, ``tau_ref`` in
    seconds whatever the sample rate. None: a field every sample (``dt``), as in a recording
    that has one."""
    dt: float = 0.01
    gyro_lsb_per_rad: float = 16.4 * 180 / math.pi
    accel_lsb_per_ms2: float = 2048 / 9.80665
    params: FlagshipParams = FlagshipParams()
    mag_dt: float = None

    @classmethod
    def from_params(cls, dt, *, gyro_lsb_per_dps, accel_lsb_per_ms2, **params):
        """The registers for a recording's sample period and sensor scales with the float
        filter's parameters (``params``: ``flagship``, a ``FlagshipParams``; ``mag_dt``), as
        ``reference.evaluate.engine_configs`` asks every filter's configuration."""
        return cls(dt, gyro_lsb_per_dps * 180 / math.pi, accel_lsb_per_ms2,
                   params.get("flagship", FlagshipParams()), mag_dt=params.get("mag_dt"))

    @classmethod
    def matching(cls, kalman):
        """The published parameters at a ``KalmanFixedConfig``'s sample period and gyro LSB
        (the default beside a per-axis configuration)."""
        return cls(dt=kalman.dt, gyro_lsb_per_rad=kalman.gyro_lsb_per_dps * 180 / math.pi)

    def registers(self):
        p, dt = self.params, self.dt
        mag_dt = dt if self.mag_dt is None else self.mag_dt
        gain = lambda tau, t=dt: int(round((1 - math.exp(-t / tau)) * _Q30))     # Q0.30
        # rest tests: deviations in Q.6 counts (x / 2¹⁰ of Q16.16), squared and summed with
        # shift 14: thresholds in counts² / 4
        rest_gyro = p.rest_gyro * self.gyro_lsb_per_rad
        rest_bias = p.rest_bias * self.gyro_lsb_per_rad
        rest_acc = p.rest_acc * self.accel_lsb_per_ms2
        k_rest, k_ref, k_fast, k_new = sample_counts(p, dt)
        regs = {
            # v [Q2.30 rad] = mul(ω·2¹⁶ − b, K_RAD, 30): T / LSB_per_rad · 2⁴⁴
            "K_RAD": int(round(dt / self.gyro_lsb_per_rad * 2 ** 44)),
            "A_DET": gain(0.5), "A_REST": gain(p.tau_rest),
            # the inclination's second-order Butterworth low-pass (a state-variable filter):
            # f = 2·sin(π·f_c·T), f_c = √2/(2π·tau_acc), as VQF's cut-off for its tau_acc
            "A_ACC": int(round(svf_gain(p.tau_acc, dt) * _Q30)),
            # once per new field: for the field's period
            "A_MAG": gain(p.tau_mag, mag_dt), "A_MAG_FAST": gain(min(p.tau_mag, 0.2), mag_dt),
            "A_REF": gain(p.tau_ref, mag_dt),
            "REST_GYRO2": int(round(rest_gyro ** 2 / 4)),
            "REST_ACC2": int(round(rest_acc ** 2 / 4)),
            "REST_BIAS2": int(round(rest_bias ** 2 / 4)),
            "GATE_NORM": int(round(p.mag_norm_gate * _Q30)),
            "GATE_DIP": int(round(p.mag_dip_gate / 360 * 2 ** 32)),
            "K_REST": k_rest, "K_REF": k_ref, "K_FAST": k_fast, "K_NEW": k_new,
        }
        for name, value in regs.items():
            if not 0 <= value < 2 ** 31:
                raise ValueError(f"flagship register {name} = {value} does not fit 31 bits "
                                 f"(dt {dt} s, {self.gyro_lsb_per_rad:.1f} LSB/rad)")
        return regs


# -- Madgwick's gradient descent ----------------------------------------------------------------

# K² of the CORDIC (K = ∏ √(1 + 2⁻²ⁱ) over its iterations): the fixed-point Madgwick step takes
# the gradient's length from two vectoring stages (|g|·K²) and folds K² into its gain
CORDIC_GAIN_SQUARED = math.prod(1 + 2.0 ** (-2 * i) for i in range(CORDIC_ITERATIONS))


# Madgwick's quick normalisation (``reference.madgwick_fixed._unit``) is taken while |v·y|², in
# Q.14, lies within these bounds: 1 ∓ 1/16 (the engine's constant registers UNIT_LO, UNIT_HI)
MADGWICK_UNIT_BOUNDS = (15 << 10, 17 << 10)


@dataclass(frozen=True)
class MadgwickFixedConfig:
    """Run-time register of the fixed-point Madgwick filter (``reference.madgwick_fixed``):
    ``BETA_K`` = β·T·K²·2³⁰, the gradient step per sample period (β in rad/s as
    ``reference.madgwick``'s, T = ``dt``) with the CORDIC's K² folded in. Its gyro scale is the
    flagship's ``K_RAD`` (the same quantity: radians per count and period)."""
    dt: float = 0.01
    beta: float = 0.1

    @classmethod
    def from_params(cls, dt, **params):
        """The register for a sample period and the float filter's ``beta`` (``params``;
        ``FlagshipFixedConfig.from_params``'s rule)."""
        return cls(dt, params.get("beta", cls.beta))

    @classmethod
    def matching(cls, kalman):
        """The float filter's default β at a ``KalmanFixedConfig``'s sample period."""
        return cls(dt=kalman.dt)

    def registers(self):
        value = int(round(self.beta * self.dt * CORDIC_GAIN_SQUARED * _Q30))
        if not 0 < value < 2 ** 31:
            raise ValueError(f"Madgwick's BETA_K = {value} does not fit 31 bits "
                             f"(beta {self.beta}, dt {self.dt} s)")
        return {"BETA_K": value}
