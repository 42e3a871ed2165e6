"""Which simulator runs a co-simulation, and its bench: ``open_bench`` (``compiled_wanted``
says what a caller's ``compiled`` asks for)."""


__all__ = ["open_bench", "compiled_wanted", "WORTH_A_BUILD_CYCLES"]


# Auto (``compiled=None``) builds a design only for a run this long (its cycle budget, which
# a run that ends on its samples or condition may use a half of): a build takes about 4 s
# (front end) or 14 s (whole core), what Amaranth's simulator does in about 10^5 cycles; a
# design already in the cache is always taken, and a build one process started is waited
# for by the others (``verilator.build_lock``)
WORTH_A_BUILD_CYCLES = 300_000


def compiled_wanted(compiled, *, vcd=None, supported=True):
    """Whether a co-simulation takes the compiled path (``CompiledBench``): ``compiled``
    True asks for it (an error if it cannot be had), False for Amaranth's simulator, None
    (auto): the compiled path when Verilator and g++ are there, the run is one it supports
    (no VCD, no stuck CIPO) and its build is cached or pays for itself (``open_bench``);
    "prefer": the compiled path whenever it can run this (built if need be), else Amaranth's
    simulator (what ``simulate`` does). Returns True, False or None (still auto). A VCD on
    the compiled path needs a build of its own (Verilator's ``--trace``): auto leaves
    waveforms to Amaranth's simulator."""
    from .compiled_design import verilator_available
    from .verilator import HINT
    if compiled == "prefer":
        return bool(supported and verilator_available())
    if compiled:
        if not supported:
            raise ValueError("the compiled path does not take this run (a stuck CIPO): run it "
                             "in Amaranth's simulator (simulate --simulator python, or "
                             "compiled=False)")
        if not verilator_available():
            raise RuntimeError(f"the compiled co-simulation needs verilator, g++ and make; {HINT}")
        return True
    if compiled is None:
        # auto: the caller takes the compiled path if the build is cached or the run long
        return None if supported and not vcd and verilator_available() else False
    return False


def open_bench(harness, inputs, outputs, clk_freq, *, compiled, name, key, max_cycles=None,
               models=None, uart=None, stuck_miso=None, trace=None):
    """The bench of one run: ``compiled`` as ``compiled_wanted`` takes it; auto (None) takes
    the compiled design when the cache has it or the run's budget (``max_cycles``; None: no
    budget, a build always pays) is at least ``WORTH_A_BUILD_CYCLES``, else Amaranth's
    simulator. ``name``, ``key``: the compiled build's cache folder prefix and parameters.
    ``models``: the ``PinModels`` on the pins; ``stuck_miso``: CIPO held at that level
    instead (Amaranth's simulator only). ``uart``: (output name, cycles a bit, sink) of a
    UART receiver appending bytes to the sink. ``trace``: a ``RunTrace`` (a compiled build
    that traces)."""
    from .compiled_design import NotBuilt
    compiled = compiled_wanted(compiled, vcd=trace, supported=stuck_miso is None)
    if compiled is not False:
        from .compiled_bench import CompiledBench
        cached_only = not compiled and max_cycles is not None and \
            max_cycles < WORTH_A_BUILD_CYCLES
        try:
            return CompiledBench(harness, inputs, outputs, clk_freq, name=name, key=key,
                                 cached_only=cached_only, models=models, uart=uart,
                                 trace=trace and trace.wave.format)
        except NotBuilt:
            pass
    from .python_bench import PythonBench
    return PythonBench(harness, inputs, outputs, clk_freq, models=models, uart=uart,
                       stuck_miso=stuck_miso)

