"""The attitude engine's filters: one record each, in select-code order. Everything that
dispatches on a filter reads its record here: the engine's microcode, the reference's float and
integer steps, the configuration of its run-time registers, the command line's choices, the host.

A record names its parts by module, each in the wing that owns it (the contract imports none of
them: ``tests/test_imports.py``):

- ``microcode``: ``hdl/engine/filters/<microcode>.py``, its routine (``emit``) and registers;
- ``float_step``: ``reference/<module>.py``'s ``run_float(gyr, acc, mag, dt, **params)``, the
  float filter (rad/s, m/s², µT -> quaternions body->ENU);
- ``fixed_step``: ``"<module>:<function>"`` of ``reference/``: ``function(reg, kf)`` makes the
  integer step the engine model runs (``reference/engine_model.py``: ``step(g, a, m,
  mag_valid, st, periods)`` -> quaternion, angles, flags; ``first``);
- ``config``: its run-time registers' configuration (a class of the contract with
  ``matching(kalman)``, the defaults at a ``KalmanFixedConfig``'s sample period,
  ``from_params(dt, gyro_lsb_per_dps=, accel_lsb_per_ms2=, **params)``, the registers for a
  recording and the float filter's parameters, and ``registers()``), or None: registers of the
  per-axis filters' ``KalmanFixedConfig``. The configurations travel as one mapping by filter
  name (``"kalman"``: the per-axis filters'; ``reference.evaluate.engine_configs``), which
  ``filter_registers``, ``EngineModel``/``attitude_fixed`` (``configs=``) and the bench's
  ``configuration_writes`` take whole.

A new filter is its three modules and a record here (``tests/hdl/test_filter_record.py`` sketches
a fifth). Its code is its position; CONTROL carries it in bits 1:0 and, beyond four filters, in
bits 5:4 above them (``numeric_contract.control_fields``), the engine's select and the results'
``filter`` field as wide as the codes need (``FILTER_CODE_BITS``: 2 for four filters).
"""

from dataclasses import dataclass
from typing import Optional

from .numeric_contract import FlagshipFixedConfig, MadgwickFixedConfig, control_code_bits


__all__ = ["FilterRecord", "FILTERS", "FILTER_NAMES", "FILTER_CODES", "FLOAT_FILTERS",
           "FILTER_CODE_BITS", "record", "module_name", "filter_registers"]


@dataclass(frozen=True)
class FilterRecord:
    """One filter of the engine (see the module's docstring for each part)."""
    name: str
    microcode: str
    float_step: str
    fixed_step: str
    config: Optional[type] = None


FILTERS = (
    FilterRecord("kalman", microcode="kalman", float_step="kalman",
                 fixed_step="per_axis_fixed:kalman_step"),
    FilterRecord("complementary", microcode="complementary", float_step="complementary",
                 fixed_step="per_axis_fixed:complementary_step"),
    FilterRecord("flagship", microcode="flagship", float_step="flagship",
                 fixed_step="flagship_fixed:engine_step", config=FlagshipFixedConfig),
    FilterRecord("madgwick", microcode="madgwick", float_step="madgwick",
                 fixed_step="madgwick_fixed:engine_step", config=MadgwickFixedConfig),
)
FILTER_NAMES = tuple(f.name for f in FILTERS)
FILTER_CODES = {name: code for code, name in enumerate(FILTER_NAMES)}
FILTER_CODE_BITS = control_code_bits(len(FILTERS))
# the reference's float filters (``reference/evaluate.py``, ``replay``): the engine's, the
# flagship last (the tables' order)
FLOAT_FILTERS = (*(name for name in FILTER_NAMES if name != "flagship"), "flagship")


def record(name):
    """The record of the filter ``name`` (a ValueError naming the filters if none)."""
    for f in FILTERS:
        if f.name == name:
            return f
    raise ValueError(f"unknown filter {name!r}; choose from {', '.join(FILTER_NAMES)}")


def module_name(part, package):
    """The module a record's part names (``microcode``, ``float_step``, or ``fixed_step``'s
    module): a module of ``package`` (the wing that owns it), or, dotted, one elsewhere."""
    return part if "." in part else f"{package}.{part}"


def filter_registers(kalman, flagship=None, madgwick=None, **configs):
    """Every filter's run-time registers by name (the engine's reset values, the reference's
    and what a host writes): the per-axis filters' (``kalman``, a ``KalmanFixedConfig``),
    then those of each filter with a configuration class, given by its name (``flagship``,
    ``madgwick``, ``configs``) or, when None, matching ``kalman``."""
    configs = {"flagship": flagship, "madgwick": madgwick, **configs}
    registers = dict(kalman.registers())
    for f in FILTERS:
        if f.config is not None:
            config = configs.get(f.name)
            registers.update((f.config.matching(kalman) if config is None else config)
                             .registers())
    return registers
