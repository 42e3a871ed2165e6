"""The per-axis filters as the engine model runs them (``reference/engine_model.py``, through
their records in ``hdl/contract/filter_registry.py``): the Kalman filter and the complementary
filter of ``reference/fixed_point.py`` on the angles they share, each giving the quaternion of
its angles (``euler_quat_fixed``), as the engine's angles-out tail does."""

from .fixed_point import _complementary_step
from .flagship_fixed import euler_quat_fixed


__all__ = ["kalman_step", "complementary_step"]


def _used(acc_ok, mag_ok):
    return ({"acc_used"} if acc_ok else set()) | ({"mag_used"} if mag_ok else set())


class _PerAxis:
    """``first`` set: the next sample is a first one (the Kalman filter takes ω₍ₖ₋₁₎ = ωₖ)."""

    def __init__(self, reg, kf):
        self.reg, self.kf = reg, kf

    @property
    def first(self):
        return self.kf.prev is None

    @first.setter
    def first(self, value):
        if value:
            self.kf.prev = None


class _KalmanStep(_PerAxis):
    def step(self, g, a, m, mag_valid, st, periods=1):
        kf = self.kf
        acc_ok, mag_ok = kf.step(g, a, m, mag_valid, st, periods)
        flags = _used(acc_ok, mag_ok) | ({"bias_updated"} if acc_ok or mag_ok else set())
        return euler_quat_fixed(kf.theta, st), kf.theta, flags


class _ComplementaryStep(_PerAxis):
    def step(self, g, a, m, mag_valid, st, periods=1):
        theta, acc_ok, mag_ok = _complementary_step(self.kf.theta, g, a, m, mag_valid,
                                                    self.reg, st, periods)
        return euler_quat_fixed(theta, st), theta, _used(acc_ok, mag_ok)


def kalman_step(reg, kf):
    """The per-axis Kalman filter's step on ``kf`` (the engine model's ``_KalmanFixed``)."""
    return _KalmanStep(reg, kf)


def complementary_step(reg, kf):
    """The complementary filter's step on ``kf``'s angles (its coefficient in ``reg``)."""
    return _ComplementaryStep(reg, kf)
