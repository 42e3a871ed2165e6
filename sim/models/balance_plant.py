"""A two-wheeled inverted pendulum, the plant of the balance controller's digital twin (issue
#57): a body on an axle, two wheels driven by DC gear motors through H-bridges, in the pitch
plane (both wheels alike: no turning).

Parameters: the LEGO NXTway-GS's, as Y. Yamamoto's "NXTway-GS Model-Based Design" (2008)
states them (body 0.6 kg, its centre of mass 72 mm above the axle, 40 mm wheels of 30 g, the
NXT motor's winding 6.69 Ω, back-EMF 0.468 V·s/rad, torque 0.317 N·m/A, measured by R.
Watanabe; friction between body and motor 0.0022 N·m·s/rad), with an 8 V battery: a hobby
robot of the size the project's users build, with published, measured motor figures. The
equations are that model's (Lagrange, linear in the accelerations, solved each step), without
the motor inductance (its time constant is far below a sample period).

State: ``theta`` the wheels' mean angle (rad, forward positive), ``psi`` the body's tilt from
vertical (rad, positive leaning forward), their rates. Inputs: the duty of both motors
(−1 .. 1, the H-bridge's mean voltage over the battery's: forward positive) and a horizontal
push (N, forward positive) at the body's centre of mass. Integrated by RK4 in steps of
``dt`` (0.1 ms by default: 10 per 1 kHz sample).
"""

import math
from dataclasses import dataclass


__all__ = ["PlantParams", "BalancePlant", "G"]

G = 9.81


@dataclass(frozen=True)
class PlantParams:
    body_mass: float = 0.6          # kg
    com_height: float = 0.072       # m, axle to the body's centre of mass
    wheel_mass: float = 0.03        # kg, each
    wheel_radius: float = 0.04      # m
    motor_inertia: float = 1e-5     # kg·m², each
    motor_resistance: float = 6.69  # Ω
    back_emf: float = 0.468         # V·s/rad
    torque_constant: float = 0.317  # N·m/A
    gear_ratio: float = 1.0         # the NXT motor's figures are at its output shaft
    motor_friction: float = 0.0022  # N·m·s/rad, body to motor
    wheel_friction: float = 0.0     # N·m·s/rad, wheel to floor
    battery_v: float = 8.0          # V
    sensor_height: float = 0.10     # m, the IMU above the axle, on the body's axis

    @property
    def body_inertia(self):
        """About the centre of mass: a uniform bar, M·L²/3 (Yamamoto's)."""
        return self.body_mass * self.com_height ** 2 / 3

    @property
    def wheel_inertia(self):
        return self.wheel_mass * self.wheel_radius ** 2 / 2


class BalancePlant:
    """The plant; ``step(dt, duty, push)`` advances it, ``imu()`` gives what an IMU on the
    body measures: the angular rate about the axle (rad/s) and the specific force in the
    body's frame (m/s²; x forward along the body's normal, z up along the body)."""

    def __init__(self, params=PlantParams(), tilt=0.0):
        self.p = params
        self.theta = self.dtheta = self.dpsi = 0.0
        self.psi = tilt
        self.ddtheta = self.ddpsi = 0.0

    def accelerations(self, psi, dtheta, dpsi, duty, push):
        p = self.p
        M, L, m, R = p.body_mass, p.com_height, p.wheel_mass, p.wheel_radius
        Jw, Jpsi, Jm, n = p.wheel_inertia, p.body_inertia, p.motor_inertia, p.gear_ratio
        relative = dtheta - dpsi                    # each motor's shaft against the body
        volts = max(-1.0, min(1.0, duty)) * p.battery_v
        torque = n * p.torque_constant * (volts - n * p.back_emf * relative) / \
            p.motor_resistance - p.motor_friction * relative
        a11 = (2 * m + M) * R * R + 2 * Jw + 2 * n * n * Jm
        a12 = M * L * R * math.cos(psi) - 2 * n * n * Jm
        a22 = M * L * L + Jpsi + 2 * n * n * Jm
        f1 = 2 * torque - 2 * p.wheel_friction * dtheta + \
            M * L * R * dpsi * dpsi * math.sin(psi) + push * R
        f2 = -2 * torque + M * G * L * math.sin(psi) + push * L * math.cos(psi)
        det = a11 * a22 - a12 * a12
        return (a22 * f1 - a12 * f2) / det, (a11 * f2 - a12 * f1) / det

    def step(self, dt, duty, push=0.0):
        def rates(s):
            ddtheta, ddpsi = self.accelerations(s[1], s[2], s[3], duty, push)
            return (s[2], s[3], ddtheta, ddpsi)
        s = (self.theta, self.psi, self.dtheta, self.dpsi)
        k1 = rates(s)
        k2 = rates(tuple(x + dt / 2 * k for x, k in zip(s, k1)))
        k3 = rates(tuple(x + dt / 2 * k for x, k in zip(s, k2)))
        k4 = rates(tuple(x + dt * k for x, k in zip(s, k3)))
        self.theta, self.psi, self.dtheta, self.dpsi = (
            x + dt / 6 * (a + 2 * b + 2 * c + d) for x, a, b, c, d in zip(s, k1, k2, k3, k4))
        self.ddtheta, self.ddpsi = self.accelerations(self.psi, self.dtheta, self.dpsi, duty,
                                                      push)

    @property
    def position(self):
        """The axle's travel (m)."""
        return self.theta * self.p.wheel_radius

    def imu(self):
        """(rate about the axle, rad/s; specific force (x, z) in the body's frame, m/s²) at
        the IMU, from the last step's accelerations."""
        h, psi = self.p.sensor_height, self.psi
        ax = self.ddtheta * self.p.wheel_radius + \
            h * (self.ddpsi * math.cos(psi) - self.dpsi ** 2 * math.sin(psi))
        az = -h * (self.ddpsi * math.sin(psi) + self.dpsi ** 2 * math.cos(psi))
        fx, fz = ax, az + G                         # specific force: acceleration less gravity
        return self.dpsi, (fx * math.cos(psi) - fz * math.sin(psi),
                           fx * math.sin(psi) + fz * math.cos(psi))
