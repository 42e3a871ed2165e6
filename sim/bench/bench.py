"""One bench interface for both simulators: a scenario is written once.

A scenario (``sim.scenarios``: a front end's samples, the whole core's results and frames, the
simulated board's bridge to a pseudo-terminal) is an ``async def scenario(bench)`` that reads
and drives the design's ports by name and waits on them through a ``Bench``. Two benches
implement it: ``PythonBench`` (Amaranth's simulator: the scenario is its testbench) and
``CompiledBench`` (Verilator: the scenario's awaits return at once, each one a call that
clocks the compiled design until what it waits for happens). Both play the sensor models on
the pins (``harness.PinModels``) and read the UART back between the scenario's wake-ups, so a
scenario sees the same values at the same cycles on either (``tests/sim/test_compiled_board.py``
checks it).

``open_bench.open_bench`` picks the simulator (``compiled_wanted``: True, False, None for
auto, "prefer") and makes the bench.
"""

from amaranth.lib import data

from ...host.protocol import unpack


__all__ = ["Bench", "simulator_name", "run_interruptible"]


class Bench:
    """A design in its ``CosimHarness``, the sensor models on its pins, on one simulator.

    Parameters
    ----------
    harness : CosimHarness
        The design and its co-simulation wiring.
    inputs, outputs : dict of str to Value
        The ports a scenario drives and reads, by name (the compiled design's port names).
    clk_freq : float
        The clock, for time-based waits.

    Members
    -------
    compiled : bool
        Which simulator runs (``simulator_name``).
    cycle : int
        Clock edges so far (the harness's counter).
    get(name), set(name, value)
        A port's value: an int, or for a port with a data layout nested dicts and lists
        (``host.protocol.to_python``); ``set`` takes an int or, for a layout, a dict.
    changed(*names, until) : awaitable
        Clocks until a port of ``names`` changes or ``cycle`` reaches ``until``.
    tick(cycles=1) : awaitable
        Clocks ``cycles`` edges.
    put(prefix, payload) : awaitable
        One stream transfer on the inputs ``<prefix>_valid``, ``<prefix>_payload`` and the
        output ``<prefix>_ready``: offered until taken.
    check()
        The stream rules of every stream the harness monitors (``AssertionError``).
    run(scenario, *, keep_on_interrupt=False, trace=None) : bool
        Runs ``scenario(bench)`` to its end; True if Ctrl-C ended it and ``keep_on_interrupt``
        (without it the interrupt goes on up). ``trace``: the run's ``RunTrace``.
    """

    compiled = False

    def __init__(self, harness, inputs, outputs, clk_freq):
        self.harness = harness
        self.ports = {**inputs, **outputs}
        self.clk_freq = clk_freq
        self._layouts = {}
        for name, port in self.ports.items():
            try:                            # a view's layout (a ``data.Struct`` too)
                self._layouts[name] = data.Layout.cast(port.shape())
            except TypeError:               # a plain value: an int
                pass

    def _decode(self, name, bits):
        layout = self._layouts.get(name)
        if layout is None:
            return bits
        return unpack(layout, bits)

    def _encode(self, name, value):
        layout = self._layouts.get(name)
        if isinstance(value, dict) and layout is not None:
            return layout.const(value).as_value().value
        return int(value)

    async def put(self, prefix, payload):
        self.set(f"{prefix}_payload", payload)
        self.set(f"{prefix}_valid", 1)
        while True:
            ready = self.get(f"{prefix}_ready")
            await self.tick()
            if ready:
                break
        self.set(f"{prefix}_valid", 0)


def run_interruptible(run, keep):
    """``run()`` (a simulator's run, a compiled scenario); True if Ctrl-C ended it and
    ``keep``: the caller keeps what was simulated (without ``keep`` the interrupt goes on)."""
    try:
        run()
    except KeyboardInterrupt:
        if not keep:
            raise
        return True
    return False


def simulator_name(compiled):
    """Which simulator ran, as summaries say it."""
    return "compiled (Verilator)" if compiled else "python (Amaranth)"
