"""The whole-board co-simulations on the compiled path: the design in Verilator
(``sim.compiled_design``), the Python models (``sim.cosim.PinModels``) called only when a pin
they watch changes or at the time they asked for, the UART read back in Python.

``frontend_loop`` and ``core_loop`` are the compiled twins of the testbenches of
``cosim.run_frontend`` and ``cosim.run_core``: same models, same observations (a sample or a
result recorded at the cycle it is seen), so both paths give the same samples, results, cycles
and frames (``tests/sim/test_compiled_board.py``). ``run_frontend``/``run_core`` take
``compiled``: True (this path), False (Amaranth's simulator), None (auto, the default: this
path when Verilator and g++ are there and the build is cached or the run's cycle budget is at
least ``WORTH_A_BUILD_CYCLES``), "prefer" (this path whenever it can run the job: what
``simulate`` and the simulated board use). A stuck CIPO stays with Amaranth's simulator; a
waveform (VCD or FST, ``sim.waveforms``) is written by a build of its own (``trace``), which
auto leaves to Amaranth's simulator.
``CosimResult.compiled`` / ``CoreRun.compiled`` say which path ran.

Speed (``python -m mpu9250_ahrs.sim.speed``): prints both paths' cycles per second on
the same short run of the core and the front end.
"""

from .compiled_design import NEVER, CompiledDesign, verilator_available


__all__ = ["frontend_loop", "core_loop", "board_ports", "verilator_available"]


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


def core_key(name, **kwargs):
    """The cache key of an ``AHRSCore`` made with ``kwargs``: those that differ from its
    defaults (a build asked for with its defaults spelt out is the same build)."""
    import inspect
    from ..hdl.board.top import AHRSCore
    defaults = {k: p.default for k, p in inspect.signature(AHRSCore.__init__).parameters.items()
                if p.default is not inspect.Parameter.empty}
    return (name, sorted((k, v) for k, v in kwargs.items()
                         if k not in defaults or defaults[k] != v))


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


def check_monitors(design, harness):
    """``harness.check`` (the stream rules of every monitored stream) on a compiled design."""
    harness.check(_MonitorFlags(design, harness))


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
    """The UART receiver of ``sim.uart`` on a compiled design's ``tx`` output: a byte's bits
    sampled in their middles (``divisor`` cycles a bit), appended to ``sink``."""

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


# Auto (``compiled=None``) builds a design only for a run this long (its cycle budget, which
# a run that ends on its samples or condition may use a half of): a build takes about 4 s
# (front end) or 14 s (whole core), what Amaranth's simulator does in about 10^5 cycles; a
# design already in the cache is always taken, and a build one process started is waited
# for by the others (``verilator.build_lock``)
WORTH_A_BUILD_CYCLES = 300_000


def frontend_design(harness, dut, *, key, cached_only=False, trace=False):
    """The compiled ``SensorFrontEnd`` in its harness (``CompiledDesign``; ``NotBuilt`` with
    ``cached_only`` when the cache does not have it; ``trace``: a build that writes
    waveforms, "vcd" or "fst")."""
    inputs, outputs = board_ports(
        harness, extra_inputs={"samples_ready": dut.samples.ready},
        extra_outputs={"samples_valid": dut.samples.valid, "status": dut.status,
                       "samples_payload": dut.samples.payload, "asa": dut.asa,
                       "rate_errors": harness.rate_errors, "who_am_i": dut.who_am_i,
                       "self_test": dut.self_test})
    wiring = "spi" if harness.spi is not None else "i2c"
    return CompiledDesign(harness, inputs, outputs, name="frontend-" + wiring,
                          key=key, cached_only=cached_only, trace=trace)


def core_design(harness, core, *, key, cached_only=False, trace=False):
    """The compiled ``AHRSCore`` in its harness (``frontend_design``'s rules)."""
    results = core.engine.results
    inputs, outputs = board_ports(
        harness,
        extra_inputs={"cfg_valid": core.cfg.valid, "cfg_payload": core.cfg.payload},
        extra_outputs={"r_valid": results.valid, "imu_int": core.imu_int,
                       "s_valid": core.engine.samples.valid,
                       "s_payload": core.engine.samples.payload,
                       "uart_tx": core.uart_tx, "cfg_ready": core.cfg.ready,
                       "r_payload": results.payload, "counters": core.counters,
                       "status": core.status, "asa": core.asa})
    return CompiledDesign(harness, inputs, outputs, name="core", key=key,
                          cached_only=cached_only, trace=trace)


def frontend_loop(design, models, observe, max_cycles, *, ready=None):
    """``run_frontend``'s testbench on the compiled path (``design``: ``frontend_design``'s):
    ``observe(cycle, taken, payload_bits, status_bits)`` at every change of the sample
    stream's valid or of the status (it raises to end the run). ``ready(cycle)``: the
    consumer's ready per cycle (a slow consumer: the loop then steps a cycle at a time, and
    observes each transfer); None: always ready."""
    pins = _Models(design, models)
    if ready is not None:
        last = None
        cycle = 0
        while True:
            r = ready(cycle)
            design.set("samples_ready", r)
            pins.poll(cycle)
            valid, status = design.get("samples_valid"), design.get("status")
            payload = design.get("samples_payload") if valid else 0
            cycle = design.run(cycle + 1)
            taken = bool(valid and r)
            if taken or (valid, status) != last or cycle >= max_cycles:
                last = (valid, status)
                observe(cycle, taken, payload, status)
                if cycle >= max_cycles:
                    raise AssertionError("observe did not end the run at max_cycles")
    design.set("samples_ready", 1)
    mask = design.mask("pin_a", "pin_b", "samples_valid", "status")
    last = None
    cycle = 0
    while True:
        pins.poll(cycle)
        seen = (design.get("samples_valid"), design.get("status"))
        if seen != last or cycle >= max_cycles:
            last = seen
            observe(cycle, seen[0], design.get("samples_payload"), seen[1])
            if cycle >= max_cycles:
                raise AssertionError("observe did not end the run at max_cycles")
        cycle = design.run(min(pins.wake, max_cycles), mask)


def core_loop(design, core, models, *, divisor, received, record, more_wanted, max_cycles,
              writes=(), progress=None, offered=None):
    """``run_core``'s testbench on the compiled path: every engine result passed to
    ``record(payload_bits, cycle, int_cycle)`` as it is first seen valid, with the cycle of
    the INT edge before it; every sample offered to the engine to ``offered(payload_bits)``
    (it holds until taken); the UART's bytes appended to ``received``; ``more_wanted()``
    asked at the testbench's wake-ups (a result, an INT edge). Returns the end cycle;
    ``design``: ``core_design``'s."""
    pins = _Models(design, models)
    uart = UARTReader(design, "uart_tx", divisor, received)
    cycle = 0
    layout = core.cfg.payload.shape()
    for addr, value in writes:                # stream_put, a cycle at a time
        design.set("cfg_payload", layout.const({"addr": addr, "data": value}).as_value().value)
        design.set("cfg_valid", 1)
        while True:
            ready = design.get("cfg_ready")
            pins.poll(cycle)
            uart.poll(cycle)
            cycle = design.run(cycle + 1)
            if ready:
                break
        design.set("cfg_valid", 0)
    mask = design.mask("pin_a", "pin_b", "r_valid", "imu_int", "uart_tx", "s_valid")
    last_int, level, valid_prev, results, s_prev = None, 0, 0, 0, 0
    while True:
        pins.poll(cycle)
        uart.poll(cycle)
        pin, valid = design.get("imu_int"), design.get("r_valid")
        woken = pin != level or valid != valid_prev
        if woken:
            if not more_wanted():
                break
            if progress is not None:
                progress.set_postfix_str(f"cycle {cycle:,}", refresh=False)
                progress.update(0)
        if pin and not level:
            last_int = cycle
        level = pin
        if valid and not valid_prev:
            record(design.get("r_payload"), cycle, last_int)
            results += 1
            if progress is not None:
                progress.update(1)
        valid_prev = valid
        s_valid = design.get("s_valid")
        if s_valid and not s_prev and offered is not None:
            offered(design.get("s_payload"))
        s_prev = s_valid
        if cycle >= max_cycles:
            raise TimeoutError(f"{results} results after {cycle} cycles (compiled)")
        cycle = design.run(min(pins.wake, uart.at, max_cycles), mask)
    return cycle
