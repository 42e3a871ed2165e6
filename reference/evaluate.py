"""Run any filter of this project on a recording and score it with BROAD's metric.

``run_filter`` takes physical units (float filters); ``run_fixed`` takes raw counts and runs the
bit-exact fixed-point model of the engine's filters (``FIXED_FILTERS``, the registry's).
"""

import importlib

import numpy as np

from ..hdl.contract.filter_registry import (FILTER_NAMES, FILTERS as RECORDS, FLOAT_FILTERS,
                                           module_name, record)
from .frames import orientation_errors
from .kalman import KalmanParams


__all__ = ["FILTERS", "FIXED_FILTERS", "run_filter", "run_fixed", "engine_configs", "score"]

# the registry's (``hdl/contract/filter_registry.py``): the float filters, and the fixed-point ones
# (the gateware's)
FILTERS = FLOAT_FILTERS
FIXED_FILTERS = FILTER_NAMES


def run_filter(name, gyr, acc, mag, dt, **params):
    """gyr rad/s, acc m/s², mag µT (body frame) -> quaternions body->ENU (N,4): the float
    filter of ``name``'s record (``filter_registry``: its module's ``run_float``; an unknown
    name is a ValueError naming the filters)."""
    module = module_name(record(name).float_step, __package__)
    return importlib.import_module(module).run_float(gyr, acc, mag, dt, **params)


def engine_configs(name, dt, *, gyro_lsb_per_dps=16.4, accel_lsb_per_ms2=2048 / 9.80665,
                   **params):
    """The engine's configurations for filter ``name`` with this module's default parameters
    (or ``params``): one per filter by name (``filter_registry``), ``"kalman"`` the per-axis
    filters' ``KalmanFixedConfig``, each other from its record's configuration class
    (``from_params``)."""
    from .complementary import coefficient
    from ..hdl.contract.numeric_contract import KalmanFixedConfig
    if name not in FIXED_FILTERS:
        raise ValueError(f"no fixed-point model of {name!r} yet; there are: "
                         f"{', '.join(FIXED_FILTERS)}")
    p = params.get("kalman", KalmanParams())
    kalman = KalmanFixedConfig(dt=dt, gyro_lsb_per_dps=gyro_lsb_per_dps, q_angle=p.q_angle,
                               q_bias=p.q_bias, r=p.r, p0=p.p0,
                               a=coefficient(params.get("tau", 0.8), dt))
    return {"kalman": kalman,
            **{f.name: f.config.from_params(dt, gyro_lsb_per_dps=gyro_lsb_per_dps,
                                            accel_lsb_per_ms2=accel_lsb_per_ms2, **params)
               for f in RECORDS if f.config is not None}}


def run_fixed(name, gyr_counts, acc_counts, mag_counts, dt, *, gyro_lsb_per_dps=16.4,
              accel_lsb_per_ms2=2048 / 9.80665, mag_valid=None, **params):
    """Raw body-axis counts -> quaternions body->ENU from the bit-exact model of the engine
    running ``name`` (``engine_model.attitude_fixed``: the quaternion the gateware reports)."""
    from .engine_model import attitude_fixed
    from .flagship_fixed import q30_to_float
    from .frames import body_to_mag
    configs = engine_configs(name, dt, gyro_lsb_per_dps=gyro_lsb_per_dps,
                             accel_lsb_per_ms2=accel_lsb_per_ms2, **params)
    out = attitude_fixed(gyr_counts, acc_counts, body_to_mag(mag_counts), mag_valid,
                         configs=configs, select=name)
    return q30_to_float(out.quat)


def score(quat, truth, movement):
    """RMS errors in degrees over the movement samples where the truth is known."""
    mask = np.asarray(movement, bool) & np.all(np.isfinite(truth), axis=1)
    if not mask.any():
        # no error to average: null (JSON has no NaN) and the reason
        return {"total_rmse_deg": None, "heading_rmse_deg": None, "inclination_rmse_deg": None,
                "samples": 0, "rmse_note": "no movement sample with a known truth"}
    e = orientation_errors(quat[mask], truth[mask])
    rms = np.degrees(np.sqrt(np.mean(e ** 2, axis=0)))
    return {"total_rmse_deg": float(rms[0]), "heading_rmse_deg": float(rms[1]),
            "inclination_rmse_deg": float(rms[2]), "samples": int(mask.sum())}
