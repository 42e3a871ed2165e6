"""The bench (``sim.bench.bench.Bench``) on the compiled path: the design in Verilator
(``compiled_design``), the Python models (``harness.PinModels``) called only when a pin they
watch changes or at the time they asked for, the UART read back in Python.

The scenario's awaits return at once: each is a call that clocks the design until what it
waits for happens (``CompiledDesign.run`` stops at a change of a watched output, or at the
next model or UART event, whichever comes first), so a scenario written for Amaranth's
simulator runs here as it is, and sees the same values at the same cycles.
"""

from .bench import Bench, run_interruptible
from .compiled_design import NEVER, CompiledDesign


__all__ = ["CompiledBench", "board_ports", "UARTReader"]


def board_ports(harness, *, extra_inputs=None, extra_outputs=None):
    """The ports of a ``CosimHarness`` for the compiled path: the models' levels and
    ``extra_inputs`` in; the watched pins first (its SPI pins, or else its I2C lines, so
    they can be watched), then ``extra_outputs`` and the stream monitors' flags out."""
    inputs = {"cipo_model": harness.cipo_model, "int_model": harness.int_model,
              "scl_model_low": harness.scl_model_low, "sda_model_low": harness.sda_model_low}
    inputs.update(extra_inputs or {})
    if harness.spi is not None:
        outputs = {"pin_a": harness.spi.cs_n, "pin_b": harness.spi.sclk,
                   "copi": harness.spi.copi}
    else:
        outputs = {"pin_a": harness.scl, "pin_b": harness.sda}
    outputs.update(extra_outputs or {})
    for k, monitor in enumerate(harness.monitors):
        outputs[f"mon{k}_withdrawn"] = monitor.withdrawn
        outputs[f"mon{k}_changed"] = monitor.changed
    return inputs, outputs


class _MonitorFlags:
    """What ``StreamMonitor.check`` reads (``get(signal)``), from a compiled design's ports
    (``board_ports``'s ``mon{k}_*``)."""

    def __init__(self, design, harness):
        self.design = design
        self.ports = {}
        for k, monitor in enumerate(harness.monitors):
            self.ports[id(monitor.withdrawn)] = f"mon{k}_withdrawn"
            self.ports[id(monitor.changed)] = f"mon{k}_changed"

    def get(self, signal):
        return self.design.get(self.ports[id(signal)])


class _Models:
    """``PinModels`` on a compiled design: call ``poll(cycle)`` at every return of ``run``."""

    def __init__(self, design, models):
        self.design, self.models, self.spi = design, models, models.spi
        self.pins = None
        self.wake = 0
        self._apply(models.initial())

    def _apply(self, levels):
        for name, value in levels.items():
            self.design.set(name, value)

    def poll(self, cycle):
        d = self.design
        pins = (d.get("pin_a"), d.get("pin_b"))
        if pins != self.pins or cycle >= self.wake:
            self.pins = pins
            copi = d.get("copi") if self.spi else 0
            levels, self.wake = self.models.react(cycle, pins[0], pins[1], copi)
            self._apply(levels)


class UARTReader:
    """The UART receiver of ``sim.bench.uart`` on a compiled design's ``tx`` output: a byte's
    bits sampled in their middles (``divisor`` cycles a bit), appended to ``sink``."""

    def __init__(self, design, name, divisor, sink):
        self.design, self.name, self.divisor, self.sink = design, name, divisor, sink
        self.level = design.get(name)
        self.at = NEVER           # the next cycle to sample at
        self.bit = None           # None: waiting for a start bit; -1 start; 0..7 data; 8 stop
        self.byte = 0

    def poll(self, cycle):
        level = self.design.get(self.name)
        fell = self.level and not level
        self.level = level
        if self.bit is None:
            if fell:
                self.bit, self.at = -1, cycle + self.divisor // 2
            return
        if cycle < self.at:
            return
        if self.bit == -1:
            if level:
                self.bit, self.at = None, NEVER         # a glitch, not a start bit
                return
            self.byte = 0
        elif self.bit < 8:
            self.byte |= level << self.bit
        else:
            if not level:
                from .uart import FramingError
                raise FramingError(f"stop bit low after byte 0x{self.byte:02X}")
            self.sink.append(self.byte)
            self.bit, self.at = None, NEVER
            return
        self.bit += 1
        self.at = cycle + self.divisor


class CompiledBench(Bench):
    """``Bench`` on the compiled path. ``name``, ``key``, ``cached_only``, ``trace``: the
    ``CompiledDesign``'s (``NotBuilt`` with ``cached_only`` when the cache does not have
    it); ``models``: the ``PinModels`` (required: a stuck CIPO is Amaranth's simulator's);
    ``uart``: (output name, cycles a bit, sink). ``design``: the ``CompiledDesign``."""

    compiled = True

    def __init__(self, harness, inputs, outputs, clk_freq, *, name, key, cached_only=False,
                 models, uart=None, trace=False):
        super().__init__(harness, inputs, outputs, clk_freq)
        ins, outs = board_ports(harness, extra_inputs=inputs, extra_outputs=outputs)
        self.design = CompiledDesign(harness, ins, outs, name=name, key=key,
                                     cached_only=cached_only, trace=trace)
        self._pins = _Models(self.design, models)
        self._uart = None
        watched = ["pin_a", "pin_b"]
        if uart is not None:
            self._uart = UARTReader(self.design, *uart)
            watched.append(uart[0])
        self._watch = self.design.mask(*watched)
        self._cycle = 0

    @property
    def cycle(self):
        return self._cycle

    last_cycle = cycle

    def get(self, name):
        return self._decode(name, self.design.get(name))

    def set(self, name, value):
        self.design.set(name, self._encode(name, value))

    def _poll(self):
        self._pins.poll(self._cycle)
        if self._uart is not None:
            self._uart.poll(self._cycle)

    def _run(self, until, mask):
        wake = self._pins.wake if self._uart is None else min(self._pins.wake, self._uart.at)
        self._cycle = self.design.run(min(wake, until), mask)
        self._poll()

    async def changed(self, *names, until):
        mask = self._watch | self.design.mask(*names)
        seen = [self.design.get(n) for n in names]
        while self._cycle < until:
            self._run(until, mask)
            if [self.design.get(n) for n in names] != seen:
                return

    async def tick(self, cycles=1):
        end = self._cycle + cycles
        while self._cycle < end:
            self._run(end, self._watch)

    def check(self):
        self.harness.check(_MonitorFlags(self.design, self.harness))

    def run(self, scenario, *, keep_on_interrupt=False, trace=None):
        def drive():
            coro = scenario(self)
            try:
                coro.send(None)
            except StopIteration:
                return
            coro.close()
            raise RuntimeError("a scenario on the compiled bench awaited something that is "
                               "not the bench's: it cannot be run here")
        if trace:
            trace.start_compiled(self.design)
        self._poll()
        try:
            return run_interruptible(drive, keep_on_interrupt)
        finally:
            if trace:
                self.design.close()             # the waveform complete
