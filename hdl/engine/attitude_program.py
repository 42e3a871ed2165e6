"""The attitude engine's program: the reset program, then per sample the calibration, the
zero tests, the dispatch on the selected filter and the filters' routines (``hdl/engine/filters/``,
one module each, in the registry's order: ``hdl/contract/filter_registry.py``), and the per-axis
filters' angles-out tail.

The microcode computes exactly ``reference.engine_model.EngineModel`` (formats in
``reference/FIXED_POINT.md``); it is written from those formulas, step by step, and the tests
compare the gateware with the reference sample by sample. The register map (names, addresses,
formats, reset values) is ``hdl/engine/register_map.py``.
"""

from .attitude_isa import Assembler, Cond
from .filters import routines
from .filters.shared import angles_out, calibrate, init, zero_tests
from .register_map import REGS, TEMPS


__all__ = ["build_program"]


def build_program():
    """(instructions, entry points {"init", "sample"})."""
    asm, r = Assembler(scratch_pool=tuple(TEMPS)), REGS
    asm.label("init")
    init(asm, r)
    asm.label("sample")
    calibrate(asm, r)
    # every filter's ACC_OK and MAG_OK, once here (a copy in each filter's routine took
    # words of a ROM that is nearly full)
    zero_tests(asm, r, "s")
    filters = routines()
    for f in filters[1:]:
        asm.br(f.name, Cond.FILTER, code=f.code)
    for f in filters:
        asm.label(f.name)
        f.emit(asm, r)
    asm.label("angles_out")
    angles_out(asm, r)
    return asm.resolve(), {"init": asm.labels["init"], "sample": asm.labels["sample"]}
