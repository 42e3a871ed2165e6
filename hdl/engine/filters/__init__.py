"""The attitude engine's filters: one microcode module each, ``hdl/engine/filters/<name>.py``, for
each name of the registry (``hdl/contract/filter_registry.py``), in its order; the microcode they
share in ``shared.py``.

A filter module (its record's ``microcode``: a module of this package, or a dotted name for one
elsewhere) has ``emit(asm, r)`` (its routine: from the calibrated sample — G, A and the zero
test's ACC_OK, made before the dispatch; M and MAG_OK after its call of
``shared.magnetometer_in(asm, name)``, which every path of the routine makes exactly once, a
routine that never reads the field too: the early start's SYNC is there — to QOUT, THETA and
BIAS, ending in END or a branch to the ``angles_out`` tail), ``CONFIG_REGISTERS`` (its run-time
registers, placed from 0x70 in the registry's order: ``hdl/engine/register_map.py``) and
``REGISTERS`` (its own state and working registers, allocated after the shared ones). Adding a
filter: its module here, its float and integer steps in ``reference/`` and its record in the
registry (``hdl/contract/filter_registry.py``: what each part is).
"""

import importlib
from dataclasses import dataclass
from typing import Callable

from ...contract.filter_registry import FILTERS, module_name


__all__ = ["FilterRoutine", "routines", "config_registers", "state_registers"]


@dataclass(frozen=True)
class FilterRoutine:
    """One filter of the engine: its ``name``, its ``code`` (CONTROL's filter code and
    ``AttitudeFlags.filter``) and ``emit(asm, regs)``, its routine."""
    name: str
    code: int
    emit: Callable


def _modules():
    return [importlib.import_module(module_name(f.microcode, __name__)) for f in FILTERS]


def routines():
    """The filters in ROM order (the first is reached by falling through the dispatch)."""
    return tuple(FilterRoutine(f.name, code, module.emit)
                 for code, (f, module) in enumerate(zip(FILTERS, _modules())))


def config_registers():
    """Every filter's run-time registers (names), in the registry's order: from 0x70."""
    return [name for module in _modules() for name in module.CONFIG_REGISTERS]


def state_registers():
    """Every filter's own registers (names), in the registry's order."""
    return [name for module in _modules() for name in module.REGISTERS]
