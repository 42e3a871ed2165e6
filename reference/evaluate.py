"""Run any filter of this project on a recording and score it with BROAD's metric."""

import math

import numpy as np

from .complementary import complementary_filter
from .flagship import FlagshipParams, flagship_filter
from .frames import orientation_errors
from .kalman import KalmanParams, kalman_filter
from .madgwick import madgwick_filter


__all__ = ["FILTERS", "run_filter", "score"]

FILTERS = ("kalman", "complementary", "madgwick", "flagship")


def run_filter(name, gyr, acc, mag, dt, **params):
    """gyr rad/s, acc m/s², mag µT (body frame) -> quaternions body->ENU (N,4)."""
    if name == "kalman":
        return kalman_filter(np.degrees(gyr), acc, mag, dt, params.get("kalman", KalmanParams()))[2]
    if name == "complementary":
        return complementary_filter(np.degrees(gyr), acc, mag, dt,
                                    tau=params.get("tau", 0.8))[1]
    if name == "madgwick":
        return madgwick_filter(gyr, acc, mag, dt, beta=params.get("beta", 0.1))
    if name == "flagship":
        return flagship_filter(gyr, acc, mag, dt, params.get("flagship", FlagshipParams()))
    raise ValueError(f"unknown filter {name!r}; choose from {', '.join(FILTERS)}")


def score(quat, truth, movement):
    """RMS errors in degrees over the movement samples where the truth is known."""
    mask = np.asarray(movement, bool) & np.all(np.isfinite(truth), axis=1)
    e = orientation_errors(quat[mask], truth[mask])
    rms = np.degrees(np.sqrt(np.mean(e ** 2, axis=0)))
    return {"total_rmse_deg": float(rms[0]), "heading_rmse_deg": float(rms[1]),
            "inclination_rmse_deg": float(rms[2]), "samples": int(mask.sum())}
