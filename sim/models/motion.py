"""Motion with exact truth, and a sensor error model that turns it into MPU9250/AK8963 readings.

A ``Trajectory`` holds, at a fixed rate, the true body->ENU quaternion ``q`` (N,4), the body
angular rate ``gyr`` (N,3, rad/s) and the earth-frame linear acceleration ``lin_acc`` (N,3,
m/s²). Builders: ``static`` (a fixed pose, e.g. a 35° tilt), ``turntable`` (constant rate about
a body axis, e.g. 30°/s about x), ``turn`` (a rotation by an angle with a smooth rate profile,
e.g. 90° from East to North), ``random_motion`` (smooth random rates and accelerations), and
``concat``. Rates are integrated exactly (constant rate within a sample).

``SensorModel`` measures a trajectory: per axis white noise, bias and bias random walk, scale
factor, cross-axis misalignment (a 3×3 matrix), for gyro and accelerometer; a local magnetic
field (intensity, inclination, declination) with hard-iron offset, soft-iron matrix and noise.
``counts`` quantises to MPU9250 counts at the chosen full scales (saturating) and AK8963 16-bit
counts, ready for the sensor models (``accel_gyro_source``, ``mag_source``; the AK8963 reads in
its own axes, converted here).
"""

from dataclasses import dataclass, field

import numpy as np

from ...reference.frames import (body_to_mag, euler_to_quat, quat_conj, quat_from_rotvec, quat_mul,
    quat_normalize, quat_to_matrix)
from ...reference.recording import G, Scales, quantise
from .sources import SensorSample


__all__ = ["Trajectory", "static", "turntable", "turn", "random_motion", "concat",
           "earth_field", "SensorModel", "accel_gyro_source", "mag_source"]


@dataclass
class Trajectory:
    rate: float
    q: np.ndarray
    gyr: np.ndarray
    lin_acc: np.ndarray

    @property
    def dt(self):
        return 1 / self.rate

    def __len__(self):
        return len(self.q)


def _integrate(q0, gyr, dt):
    """q[k+1] = q[k] ⊗ exp(ω[k]·dt): exact for a rate held over each sample."""
    steps = quat_from_rotvec(np.asarray(gyr, float) * dt)
    q = np.empty((len(gyr), 4))
    cur = quat_normalize(np.asarray(q0, float))
    for k in range(len(gyr)):
        q[k] = cur
        cur = quat_normalize(quat_mul(cur, steps[k]))
    return q


def static(euler_deg=(0, 0, 0), duration=5.0, rate=100.0):
    n = int(round(duration * rate))
    q = np.tile(euler_to_quat(np.radians(euler_deg)), (n, 1))
    return Trajectory(rate, q, np.zeros((n, 3)), np.zeros((n, 3)))


def turntable(axis=(1, 0, 0), rate_dps=30.0, duration=12.0, rate=100.0, start_deg=(0, 0, 0)):
    n = int(round(duration * rate))
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    gyr = np.tile(axis * np.radians(rate_dps), (n, 1))
    return Trajectory(rate, _integrate(euler_to_quat(np.radians(start_deg)), gyr, 1 / rate),
                      gyr, np.zeros((n, 3)))


def turn(axis=(0, 0, 1), angle_deg=90.0, duration=3.0, rate=100.0, start_deg=(0, 0, 0)):
    """A rotation by ``angle_deg`` about a body axis with a raised-cosine rate profile
    (e.g. start_deg=(0, 0, 0), angle 90° about z: from facing East to facing North)."""
    n = int(round(duration * rate))
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    t = (np.arange(n) + 0.5) / n
    profile = 1 - np.cos(2 * np.pi * t)                 # mean 1 over the turn
    scale = np.radians(angle_deg) / (profile.sum() / rate)
    gyr = axis * (profile * scale)[:, None]
    return Trajectory(rate, _integrate(euler_to_quat(np.radians(start_deg)), gyr, 1 / rate),
                      gyr, np.zeros((n, 3)))


def random_motion(duration=30.0, rate=100.0, *, seed=0, max_rate_dps=200.0, max_acc=3.0,
                  smooth_s=0.5, start_deg=(0, 0, 0)):
    """Smooth random rotation and translation (low-passed Gaussian noise, scaled)."""
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate))
    alpha = 1 / (smooth_s * rate)

    def smooth(x):
        y = np.empty_like(x)
        s = np.zeros(x.shape[1])
        for _ in range(2):                              # two passes: a 2nd-order low-pass
            for k in range(len(x)):
                s += alpha * (x[k] - s)
                y[k] = s
            x = y.copy()
        return y / max(np.abs(y).max(), 1e-12)
    gyr = smooth(rng.standard_normal((n, 3))) * np.radians(max_rate_dps)
    lin = smooth(rng.standard_normal((n, 3))) * max_acc
    lin -= lin.mean(0)
    q = _integrate(euler_to_quat(np.radians(start_deg)), gyr, 1 / rate)
    return Trajectory(rate, q, gyr, lin)


def concat(*parts):
    """Join trajectories: each later part restarts its rotation from where the previous ended."""
    rate = parts[0].rate
    qs, gyrs, lins = [], [], []
    last = None
    for p in parts:
        if p.rate != rate:
            raise ValueError("trajectories to join must share a rate")
        q = p.q
        if last is not None:
            q = quat_mul(quat_mul(last, quat_conj(p.q[0]))[None, :], q)
        qs.append(q)
        gyrs.append(p.gyr)
        lins.append(p.lin_acc)
        last = quat_mul(q[-1], quat_from_rotvec(p.gyr[-1] / rate))
    return Trajectory(rate, np.vstack(qs), np.vstack(gyrs), np.vstack(lins))


def earth_field(intensity_ut=50.0, inclination_deg=60.0, declination_deg=0.0):
    """The local field in ENU: pointing North (turned East by the declination) and down by the
    inclination (dip)."""
    inc, dec = np.radians(inclination_deg), np.radians(declination_deg)
    h = intensity_ut * np.cos(inc)
    return np.array([h * np.sin(dec), h * np.cos(dec), -intensity_ut * np.sin(inc)])


@dataclass
class SensorModel:
    gyro_noise: float = 0.0          # rad/s per sample (σ)
    gyro_bias: tuple = (0.0, 0.0, 0.0)
    gyro_bias_walk: float = 0.0      # rad/s/√s
    gyro_scale: tuple = (1.0, 1.0, 1.0)
    gyro_misalignment: np.ndarray = field(default_factory=lambda: np.eye(3))
    accel_noise: float = 0.0         # m/s² (σ)
    accel_bias: tuple = (0.0, 0.0, 0.0)
    accel_scale: tuple = (1.0, 1.0, 1.0)
    accel_misalignment: np.ndarray = field(default_factory=lambda: np.eye(3))
    earth_field_ut: np.ndarray = field(default_factory=earth_field)
    hard_iron: tuple = (0.0, 0.0, 0.0)     # µT, body frame
    soft_iron: np.ndarray = field(default_factory=lambda: np.eye(3))
    mag_noise: float = 0.0           # µT (σ)
    seed: int = 0

    def measure(self, traj):
        """Physical readings in the body frame: gyr rad/s, acc m/s², mag µT."""
        rng = np.random.default_rng(self.seed)
        n = len(traj)
        R = quat_to_matrix(traj.q)
        walk = np.cumsum(rng.standard_normal((n, 3)) * self.gyro_bias_walk * np.sqrt(traj.dt),
                         axis=0)
        gyr = (traj.gyr * self.gyro_scale) @ np.asarray(self.gyro_misalignment).T + \
            self.gyro_bias + walk + rng.standard_normal((n, 3)) * self.gyro_noise
        f_earth = traj.lin_acc + np.array([0.0, 0.0, G])
        f_body = np.einsum("nji,nj->ni", R, f_earth)
        acc = (f_body * self.accel_scale) @ np.asarray(self.accel_misalignment).T + \
            self.accel_bias + rng.standard_normal((n, 3)) * self.accel_noise
        m_body = np.einsum("nji,j->ni", R, np.asarray(self.earth_field_ut, float))
        mag = m_body @ np.asarray(self.soft_iron).T + self.hard_iron + \
            rng.standard_normal((n, 3)) * self.mag_noise
        return gyr, acc, mag

    def counts(self, traj, scales=Scales()):
        """Readings quantised to MPU9250 (gyro, accel) and AK8963 16-bit (mag, body axes)."""
        return quantise(*self.measure(traj), scales)


def accel_gyro_source(gyr_counts, acc_counts, temp=0):
    """A source for ``MPU9250Model``: sample k from the count arrays (held at the end)."""
    def source(index, t):
        k = min(index, len(gyr_counts) - 1)
        return SensorSample(accel=tuple(int(v) for v in acc_counts[k]), temp=temp,
                            gyro=tuple(int(v) for v in gyr_counts[k]))
    return source


def mag_source(mag_counts_body):
    """A source for ``AK8963Model``: body-frame counts turned into the AK8963's own axes
    (x_ak = y_body, y_ak = x_body, z_ak = −z_body)."""
    mag_ak = body_to_mag(mag_counts_body)

    def source(index, t):
        return tuple(int(v) for v in mag_ak[min(index, len(mag_ak) - 1)])
    return source
