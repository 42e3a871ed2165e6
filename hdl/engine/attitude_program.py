"""The attitude engine's program: the reset program, then per sample the calibration, the
zero tests, the dispatch on the selected filter and the filters' routines (``hdl/engine/filters/``,
one module each, in the registry's order: ``hdl/contract/filter_registry.py``), the per-axis
filters' angles-out tail and the magnetometer's part, which every filter reaches before it reads
the field (SYNC: the early start, ``attitude_isa``).

The microcode computes exactly ``reference.engine_model.EngineModel`` (formats in
``reference/FIXED_POINT.md``); it is written from those formulas, step by step, and the tests
compare the gateware with the reference sample by sample. The register map (names, addresses,
formats, reset values) is ``hdl/engine/register_map.py``.
"""

from .attitude_isa import Assembler, Cond
from .filters import routines
from .filters.shared import angles_out, calibrate, init, magnetometer, zero_tests
from .register_map import REGS, TEMPS


__all__ = ["build_program"]


def build_program():
    """(instructions, entry points {"init", "sample"})."""
    asm, r = Assembler(scratch_pool=tuple(TEMPS)), REGS
    asm.label("init")
    init(asm, r)
    asm.label("sample")
    calibrate(asm, r)
    # every filter's ACC_OK, once here (a copy in each filter's routine took words of a ROM
    # that is nearly full); MAG_OK in ``magnetometer``
    zero_tests(asm, r, "s", ("ACC_OK",))
    filters = routines()
    for f in filters[1:]:
        asm.br(f.name, Cond.FILTER, code=f.code)
    for f in filters:
        asm.label(f.name)
        f.emit(asm, r)
    asm.label("angles_out")
    angles_out(asm, r)
    # The early start (``attitude_isa``): each filter branches here before it reads the field
    # (``magnetometer_in``), where SYNC waits for the AK8963's words, and comes back by a
    # dispatch on the filter (the reset default's, the flagship's, first: a word not taken
    # costs a cycle)
    missing = [f.name for f in filters if f"{f.name}_mag" not in asm.labels]
    if missing:
        raise ValueError(f"filter routine(s) {', '.join(missing)} without magnetometer_in: "
                         f"every routine passes the SYNC once (hdl/engine/filters/__init__.py)")
    asm.label("magnetometer")
    magnetometer(asm, r)
    order = sorted(filters, key=lambda f: f.name != "flagship")
    for f in order[:-1]:
        asm.br(f"{f.name}_mag", Cond.FILTER, code=f.code)
    asm.br(f"{order[-1].name}_mag")
    return asm.resolve(), {"init": asm.labels["init"], "sample": asm.labels["sample"]}
