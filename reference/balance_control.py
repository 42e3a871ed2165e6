"""The balance controller (issue #57): the float law it was designed with and its fixed-point
model, the statement the gateware is to match bit for bit.

The law: a PID on the tilt (pitch, or roll) from the attitude, its rate from the calibrated
gyro, and a term on the motor duty low-passed, which stands in for the wheels' speed (a DC
motor's speed follows its voltage within a mechanical time constant): without it a PID on the
tilt alone holds the body up while the wheels run away, until the duty saturates and the robot
falls (the twin shows it: ``sim/scenarios/twin.py``). No wheel encoder is needed, as in many
hobby balancing robots. Why not a state-space (LQR) law: its wheel states need the encoders
this board does not have; with the duty as their stand-in, the PID-plus-duty law is the
same loop with fewer registers.

    u = Kp·e + Kd·ω + Ki·∫e dt + Kv·w,  w = low-pass(u, τ_v),  e = tilt − set-point

u is the duty of both motors (−1 .. 1: forward, reverse), positive to drive the wheels
forward (the direction the body falls when its tilt is positive).

Fixed point, per result (``BalanceFixed.step``: every format, rounding and saturation):

- e = (angle − set-point·2¹⁶) mod 2³² >> 16 (arithmetic): signed 16 bits, 2¹⁶ = 360°
  (the angle is BAM32, the set-point in e's units).
- ω = g − ⌊b / 2¹⁶⌋, signed 17 bits (no saturation: the multiplier's operand has 18; a rate
  of the other sign: Kd's sign): g the gyro's raw count of the axis, b the engine's bias
  estimate of it (Q16.16 counts).
- Disarmed (at reset, by a command, or by a trip): u = 0, and the integral, the duty's
  low-pass and the last duty are 0. A trip (the same result: ``step`` returns the duty 0):
  |e| > cutoff (fallen over), a driver fault, or more than ``stale`` sample periods without a
  new result (``BalanceFixed.period``).
- i = i + e if |i + e| ≤ i_limit, else i (conditional integration: the anti-windup of a clamp
  without the clamp's bound), i_limit < 2²³ (24 bits). A write of i_limit sets i to 0
  (``BalanceFixed.write``: a limit lowered below |i| would hold it there).
- w = w + ((u₋₁·2⁸ − w) >> kv_shift) (arithmetic shift; |w| < 2¹⁸, 19 bits: u₋₁ the duty
  of the previous result, applied since).
- a = Kp·e + Kd·ω + Ki·(i >> 8) + Kv·(w >> 8): gains signed 18 bits, the operands 16 bits
  (ω 17, w >> 8 the duty's 11 bits), each product exact, the sum exact.
- u = clamp(a >> 8, ±out_limit) (arithmetic shift: towards −∞), |u| ≤ 1023: the duty in
  1/1024.
"""

import dataclasses
import math
from dataclasses import dataclass

from ..hdl.contract.balance_regs import (DUTY_FULL, GAIN_BITS, GAIN_SHIFT, INTEGRAL_BITS,
                                         INTEGRAL_SHIFT, W_FRACTION)
from .fixed_point import sat, wrap32


__all__ = ["BalanceGains", "BalanceFixedConfig", "BalanceFixed", "BalanceFloat", "E_PER_RAD"]


E_PER_RAD = 65536 / (2 * math.pi)   # e's units per radian


@dataclass(frozen=True)
class BalanceGains:
    """The law in physical units: ``kp`` duty per rad, ``kd`` duty per rad/s, ``ki`` duty
    per rad·s, ``kv`` duty per duty (the low-passed duty's weight), ``tau_v`` the low-pass's
    time constant (s). ``setpoint_deg`` the tilt held; ``cutoff_deg`` the tilt that trips;
    ``out_limit`` the largest duty (0 .. 1); ``i_limit`` the integral's bound (rad·s)."""
    kp: float = 20.0
    kd: float = 1.0
    ki: float = 0.0
    kv: float = 2.0
    tau_v: float = 0.2
    setpoint_deg: float = 0.0
    cutoff_deg: float = 30.0
    out_limit: float = 1.0
    i_limit: float = 0.5


@dataclass(frozen=True)
class BalanceFixedConfig:
    """The controller's registers (the gateware's, ``BalanceFixed``'s). ``from_gains`` makes
    them from a ``BalanceGains`` for a gyro scale and a sample rate."""
    kp: int = 0
    kd: int = 0
    ki: int = 0
    kv: int = 0
    kv_shift: int = 8
    setpoint: int = 0
    cutoff: int = 0
    out_limit: int = 0
    i_limit: int = 0
    stale: int = 5
    watchdog: int = 500

    def __post_init__(self):
        for name in ("kp", "kd", "ki", "kv"):
            value = getattr(self, name)
            if sat(value, GAIN_BITS) != value:
                raise ValueError(f"{name} = {value} does not fit {GAIN_BITS} signed bits")
        if not 0 <= self.out_limit < DUTY_FULL:
            raise ValueError(f"out_limit {self.out_limit} is not in 0 .. {DUTY_FULL - 1}")
        if not 1 <= self.kv_shift <= 24:
            raise ValueError(f"kv_shift {self.kv_shift} is not in 1 .. 24")
        if not 0 <= self.i_limit < 1 << (INTEGRAL_BITS - 1):
            raise ValueError(f"i_limit {self.i_limit} is not in 0 .. 2^{INTEGRAL_BITS - 1} - 1")

    @classmethod
    def from_gains(cls, gains=BalanceGains(), *, gyro_lsb_per_dps=16.4, sample_hz=1000.0,
                   stale=5):
        scale = DUTY_FULL << GAIN_SHIFT                  # a duty of 1 in the sum's units
        rad_per_lsb = math.radians(1.0 / gyro_lsb_per_dps)
        dt = 1.0 / sample_hz
        # the low-pass's time constant: w moves 2^-kv_shift of the way each sample
        kv_shift = max(1, min(24, round(math.log2(max(1.0, gains.tau_v * sample_hz)))))
        return cls(
            kp=round(gains.kp * scale / E_PER_RAD),
            kd=round(gains.kd * scale * rad_per_lsb),
            ki=round(gains.ki * scale * dt / E_PER_RAD * (1 << INTEGRAL_SHIFT)),
            kv=round(gains.kv * (1 << GAIN_SHIFT)),
            kv_shift=kv_shift,
            setpoint=round(math.radians(gains.setpoint_deg) * E_PER_RAD),
            cutoff=round(math.radians(gains.cutoff_deg) * E_PER_RAD),
            out_limit=min(DUTY_FULL - 1, round(gains.out_limit * DUTY_FULL)),
            i_limit=min((1 << (INTEGRAL_BITS - 1)) - 1,
                        round(gains.i_limit * sample_hz * E_PER_RAD)),
            stale=stale)


class BalanceFixed:
    """The fixed-point controller, one ``step`` per attitude result, ``period`` per sample
    period. ``armed`` (``by_host``: the watchdog applies); ``tripped``: the reason of the last
    trip (``balance_regs.TRIPS``) or None; ``duty``: the last duty (signed, 1/1024)."""

    def __init__(self, config):
        self.config = config
        self.armed = self.by_host = False
        self.tripped = None
        self._clear()

    def _clear(self):
        self.integral = 0
        self.w = 0
        self.duty = 0
        # the sample periods left before a trip, from the registers' values then
        self.stale_left, self.idle_left = self.config.stale, self.config.watchdog

    def arm(self, by_host=False):
        if not self.armed:
            self._clear()
        self.armed, self.by_host, self.tripped = True, by_host, None

    def disarm(self, reason=None):
        self.armed = self.by_host = False
        self.tripped = reason
        self._clear()

    def write(self, **fields):
        """Registers written (``BalanceFixedConfig``'s fields): the integral restarts at 0 when
        ``i_limit`` is among them."""
        self.config = dataclasses.replace(self.config, **fields)
        if "i_limit" in fields:
            self.integral = 0

    def kick(self):
        """A command accepted: the watchdog starts again (from ``watchdog`` as it is now)."""
        self.idle_left = self.config.watchdog

    def period(self):
        """A sample period passed: more than ``stale`` in a row without a result trip it
        ("stale"), and, armed by the host, more than ``watchdog`` without a command
        ("watchdog"; 0: never). Each counts down from its value at the last result (command)
        or arming: a trip in the period that finds 0."""
        if not self.armed:
            self._clear()                   # the counts follow the registers while disarmed
            return self.duty
        if self.stale_left == 0:
            self.disarm("stale")
        elif self.by_host and self.config.watchdog and self.idle_left == 0:
            self.disarm("watchdog")
        else:
            self.stale_left -= 1
            self.idle_left = max(0, self.idle_left - 1)
        return self.duty

    def step(self, angle, gyro, bias_q16, fault=False):
        """One result: ``angle`` (BAM32) and the gyro count and bias (Q16.16) of its axis;
        ``fault``: the driver flags one. Returns the duty (0 while disarmed)."""
        c = self.config
        e = wrap32(angle - (c.setpoint << 16)) >> 16
        rate = gyro - (bias_q16 >> 16)
        if not self.armed:
            return 0
        if fault:
            self.disarm("fault")
            return 0
        if abs(e) > c.cutoff:
            self.disarm("fallen")
            return 0
        self.stale_left = c.stale
        if abs(self.integral + e) <= c.i_limit:
            self.integral += e
        self.w = self.w + (((self.duty << W_FRACTION) - self.w) >> c.kv_shift)
        a = c.kp * e + c.kd * rate + c.ki * (self.integral >> INTEGRAL_SHIFT) + \
            c.kv * (self.w >> W_FRACTION)
        self.duty = max(-c.out_limit, min(c.out_limit, a >> GAIN_SHIFT))
        return self.duty


class BalanceFloat:
    """The law in floating point (the design's; the twin's ``--loop model`` reference):
    ``step(tilt_rad, rate_rad_s)`` every ``dt`` seconds returns the duty (−1 .. 1)."""

    def __init__(self, gains=BalanceGains(), dt=1e-3):
        self.g, self.dt = gains, dt
        self.integral = self.w = self.u = 0.0

    def step(self, tilt, rate):
        g = self.g
        e = tilt - math.radians(g.setpoint_deg)
        if abs(self.integral + e * self.dt) <= g.i_limit:     # as BalanceFixed
            self.integral += e * self.dt
        self.w += self.dt / (g.tau_v + self.dt) * (self.u - self.w)
        u = g.kp * e + g.kd * rate + g.ki * self.integral + g.kv * self.w
        self.u = max(-g.out_limit, min(g.out_limit, u))
        return self.u
