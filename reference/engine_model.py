"""The attitude engine in integers: ``EngineModel`` (one sample at a time, with the
run-time registers, the filter select and resets, exactly as the gateware acts on them) and
``attitude_fixed`` (the same over arrays), from the primitives of ``reference/fixed_point.py``
and each filter's integer step, found through its record (``hdl/contract/filter_registry.py``:
``reference/per_axis_fixed.py``, ``flagship_fixed.py``, ``madgwick_fixed.py``). The gateware's
attitude engine equals it bit for bit.
"""

import dataclasses
import importlib
from dataclasses import dataclass

import numpy as np

from ..hdl.contract.numeric_contract import (CalibrationFixed, KalmanFixedConfig, calibration_of,
                                             calibration_registers, control_fields)
from ..hdl.contract.filter_registry import (FILTER_NAMES, FILTERS as _RECORDS, filter_registers,
                                           module_name)
from .fixed_point import Status, _KalmanFixed, _calibrate_one


__all__ = ["FILTERS", "RESULT_FLAGS", "RESULT_FIELDS", "AttitudeFixed", "EngineModel",
           "attitude_fixed"]


# the engine's filters, by select code (the registry, ``hdl/contract/filter_registry.py``)
FILTERS = FILTER_NAMES
RESULT_FLAGS = ("acc_used", "mag_used", "mag_disturbed", "mag_new_ref", "at_rest",
                "bias_updated")
# the fields of a result that the gateware must reproduce, in the order they are compared
RESULT_FIELDS = ("quat", "angles", "bias", *RESULT_FLAGS, "saturated", "filter")


def fixed_step_maker(record):
    """The function that makes a filter's integer step (``reg``, ``kf``): its record's
    ``fixed_step``, ``"module:function"`` of this package (or a dotted module elsewhere)."""
    module, function = record.fixed_step.split(":")
    return getattr(importlib.import_module(module_name(module, __package__)), function)


@dataclass
class AttitudeFixed:
    """Per-sample outputs of ``attitude_fixed`` (arrays of N): the engine's result stream."""
    quat: np.ndarray             # (N, 4) Q2.30 body->ENU
    angles: np.ndarray           # (N, 3) BAM32 roll, pitch, yaw
    bias: np.ndarray             # (N, 3) Q16.16 gyro counts (shared by Kalman and flagship)
    acc_used: np.ndarray         # the accelerometer corrected the tilt
    mag_used: np.ndarray         # the magnetometer corrected the heading
    mag_disturbed: np.ndarray    # a valid field was rejected by the flagship's gates
    mag_new_ref: np.ndarray      # the flagship adopted a magnetic reference
    at_rest: np.ndarray          # the flagship's rest detector holds
    bias_updated: np.ndarray     # the bias estimate changed
    saturated: np.ndarray        # some result of this sample's update saturated
    filter: np.ndarray           # filter select code (FILTERS)

    def take(self, indices):
        """The results of the samples at ``indices`` (e.g. those the telemetry sent)."""
        return AttitudeFixed(*(np.asarray(getattr(self, f.name))[list(indices)]
                               for f in dataclasses.fields(self)))


class EngineModel:
    """The attitude engine in integers, one sample at a time: run-time registers by name
    (filter coefficients, flagship parameters, calibration), the filter select, a filter
    reset, and ``sample`` (raw counts in, one result out), exactly as the gateware acts on
    them. Switching to another filter makes the next sample a first sample (the Kalman filter
    takes ω₍ₖ₋₁₎ = ωₖ, the flagship starts afresh but keeps the bias, Madgwick aligns afresh);
    the per-axis filters continue from the angles of whichever filter ran last."""

    def __init__(self, config=None, cal=None, flagship=None, *, filter="flagship",
                 registers=None, madgwick=None, configs=None):
        # ``configs``: the configurations by filter name (``evaluate.engine_configs``; "kalman"
        # the per-axis filters'), over ``config``, ``flagship`` and ``madgwick``
        configs = {"flagship": flagship, "madgwick": madgwick, **(configs or {})}
        config = configs.pop("kalman", config)
        config = KalmanFixedConfig() if config is None else config
        self.reg = {**filter_registers(config, **configs),
                    **calibration_registers(CalibrationFixed() if cal is None else cal),
                    **(registers or {})}
        self.filter = FILTERS.index(filter)
        self.reset()

    def reset(self):
        """Filter state to its start (angles 0, bias 0, P = P0·I, flagship afresh); the
        registers keep their values."""
        self.kf = _KalmanFixed(KalmanFixedConfig(), self.reg)
        self.kf.reg = self.reg                      # one register dict for every filter
        # each filter's step, by code: the per-axis ones on ``kf``, the flagship sharing its bias
        self.steps = [fixed_step_maker(record)(self.reg, self.kf) for record in _RECORDS]

    def write(self, name, value):
        self.reg[name] = int(value)

    def control(self, value):
        """A host's write of ``value`` to the CONTROL register, as the gateware takes it
        (``numeric_contract.control_fields``): True if taken (the filter selected, the state
        reset if asked), False if refused (nothing changes; the gateware counts it in
        ``cfg_refused``)."""
        fields = control_fields(value, len(FILTERS))
        if fields is None:
            return False
        code, reset = fields
        if code is not None:
            self.select(code)
        if reset:
            self.reset()
        return True

    def select(self, filter):
        code = FILTERS.index(filter) if isinstance(filter, str) else int(filter)
        if not 0 <= code < len(FILTERS):
            raise ValueError(f"filter code {code} names no filter (0..{len(FILTERS) - 1})")
        if code != self.filter:
            for step in self.steps:                  # next sample is a first one
                step.first = True
        self.filter = code

    def sample(self, g_raw, a_raw, m_raw, mag_valid=True, asa=(128, 128, 128), skipped=0):
        """One sample (raw counts; the field in the AK8963's axes; ``skipped`` samples the
        sensor made since the previous one, integrated as elapsed time): a dict of the
        result."""
        periods = 1 + skipped
        st = Status()
        g, a, m = _calibrate_one(list(g_raw), list(a_raw), list(m_raw), asa,
                                 calibration_of(self.reg), st)
        kf = self.kf
        # the angles a filter leaves are where the per-axis filters continue, and this
        # sample's rate the Kalman filter's previous one
        quat, kf.theta, flags = self.steps[self.filter].step(g, a, m, mag_valid, st, periods)
        kf.prev = list(g)
        return {"quat": list(quat), "angles": list(kf.theta), "bias": list(kf.bias),
                **{f: f in flags for f in RESULT_FLAGS}, "saturated": st.saturated,
                "filter": self.filter}


def attitude_fixed(gyr_raw, acc_raw, mag_ak_raw, mag_valid=None, *, asa=(128, 128, 128),
                   cal=CalibrationFixed(), config=KalmanFixedConfig(), flagship=None,
                   madgwick=None, select="kalman", registers=None, resets=(), writes=None,
                   skipped=None, controls=None, configs=None):
    """The gateware's attitude engine in integers over arrays (``EngineModel`` per sample):
    calibration, then the filter ``select`` names (one name, or an array of names per
    sample); ``config``, ``flagship``, ``madgwick``: the filters' configurations (the last two
    match ``config`` when None). ``registers`` overrides register values by name (raw
    integers, e.g. {"R": 0}); ``resets``: sample indices before which the filter state is
    reset; ``writes``: {sample index: {name: value}}, register writes applied before that
    sample (after a reset there); ``skipped``: per sample, the sensor samples missed before
    it (0 if None);
    ``controls``: {sample index: [words]}, CONTROL words a host writes before that sample (after
    the writes), taken or refused as the gateware does (``EngineModel.control``); with them,
    ``select`` names only the filter at the start."""
    n = len(gyr_raw)
    sel = [select] * n if isinstance(select, str) else list(select)
    valid = [True] * n if mag_valid is None else [bool(v) for v in mag_valid]
    resets = set(resets)
    model = EngineModel(config, cal, flagship, filter=sel[0] if n else "kalman",
                        registers=registers, madgwick=madgwick, configs=configs)
    out = AttitudeFixed(np.empty((n, 4), np.int64), np.empty((n, 3), np.int64),
                        np.empty((n, 3), np.int64),
                        *(np.zeros(n, bool) for _ in range(len(RESULT_FLAGS) + 1)),
                        np.zeros(n, np.int64))
    for k, (g, a, h) in enumerate(zip(*(np.asarray(x, np.int64).tolist()
                                         for x in (gyr_raw, acc_raw, mag_ak_raw)))):
        if k in resets:
            model.reset()
        for name, value in (writes or {}).get(k, {}).items():
            model.write(name, value)
        if controls is None:
            model.select(sel[k])
        for word in (controls or {}).get(k, ()):
            model.control(word)
        r = model.sample(g, a, h, valid[k], asa, 0 if skipped is None else int(skipped[k]))
        for name in RESULT_FIELDS:
            getattr(out, name)[k] = r[name]
    return out
