"""The whole core's scenario: an ``AHRSCore`` (driver, engine, telemetry) against the sensor
models, its results, the samples it was given and the frames its UART carried (``run_core``),
on either simulator (``sim.bench``)."""

import time
from dataclasses import dataclass, field
from typing import List, Optional

from amaranth import Elaboratable

from ...hdl.contract.defaults import DEFAULT_BAUD
from ..bench.open_bench import open_bench
from ..bench.harness import CosimHarness, PinModels
from ..bench.waveforms import RunTrace
from ..models.i2c_bus import I2CBusModel
from ..models.mpu9250_model import MPU9250Model
from .frontend import finish_trace, status_fields
from .setup import SimSetup, primary_bus


__all__ = ["CoreRun", "core_harness", "core_key", "core_ports", "run_core"]


@dataclass
class CoreRun:
    """What ``run_core`` saw: every engine result (``Attitude`` dicts, in order), the cycle of
    each, the data-ready (INT) edge before each, the frames the UART carried (decoded), the
    core's counters and driver status at the end, the model and the core, every sample
    offered to the engine (``Sample`` dicts, in order) and, I2C wiring, the bus model."""
    results: List[dict]
    result_cycles: List[int]
    int_cycles: List[int]
    frames: List[dict]
    counters: dict
    status: dict
    cycles: int
    wall_s: float
    model: Optional[MPU9250Model]
    asa: List[int] = field(default_factory=list)
    core: Optional[Elaboratable] = None
    compiled: bool = False                  # the compiled path ran
    samples: List[dict] = field(default_factory=list)   # the engine's inputs (``Sample``s)
    bus: Optional[I2CBusModel] = None                       # I2C wiring
    interrupted: bool = False               # Ctrl-C ended the run: what it had simulated
    ports: dict = field(default_factory=dict)   # the attitude port's at the end, if built

    def latencies_us(self, clk_freq):
        """Data-ready edge (INT at the pin) to the result leaving the engine, per result."""
        return [(r - i) / clk_freq * 1e6 for r, i in zip(self.result_cycles, self.int_cycles)]


def core_key(name, **kwargs):
    """The cache key of an ``AHRSCore`` made with ``kwargs``: those that differ from its
    defaults (a build asked for with its defaults spelt out is the same build)."""
    import inspect
    from ...hdl.board.top import AHRSCore
    defaults = {k: p.default for k, p in inspect.signature(AHRSCore.__init__).parameters.items()
                if p.default is not inspect.Parameter.empty}
    return (name, sorted((k, v) for k, v in kwargs.items()
                         if k not in defaults or defaults[k] != v))


def core_harness(setup, *, baud=DEFAULT_BAUD, core_kwargs=None):
    """The ``AHRSCore`` that ``run_core`` simulates (``setup``'s clock, configuration and
    timing), in its co-simulation harness, and the cache key of its compiled build:
    ``(core, harness, key)``."""
    from ...hdl.board.top import AHRSCore
    core = AHRSCore(clk_freq=setup.clk_freq, config=setup.config, timing=setup.driver_timing(),
                    baud=baud, **(core_kwargs or {}))
    spi = setup.config.wiring == "spi"
    harness = CosimHarness(core, spi=core.imu if spi else None, i2c=None if spi else core.imu,
                           int_pin=core.imu_int)
    harness.monitor(core.engine.results, "results")
    harness.monitor(core.arbiter.o_stream, "frame bytes")
    key = core_key("core", clk_freq=setup.clk_freq, config=setup.config,
                   timing=setup.driver_timing(), baud=baud, **(core_kwargs or {}))
    return core, harness, key


def core_ports(core):
    """The ports ``run_core``'s scenario reads and drives: (inputs, outputs) by name; with
    the core's ``attitude`` port, its stream too (``attitude_*``; its ready held low)."""
    results, offered = core.engine.results, core.engine.samples
    outputs = {"r_valid": results.valid, "imu_int": core.imu_int, "s_valid": offered.valid,
               "uart_tx": core.uart_tx, "cfg_ready": core.cfg.ready, "r_ready": results.ready,
               "s_payload": offered.payload, "r_payload": results.payload,
               "counters": core.counters, "status": core.status, "asa": core.asa}
    if core.attitude_port:
        outputs.update(attitude_valid=core.attitude.valid,
                       attitude_payload=core.attitude.payload,
                       attitude_dropped=core.attitude_dropped,
                       attitude_sample_valid=core.sample.valid,
                       attitude_sample_payload=core.sample.payload,
                       attitude_sample_dropped=core.sample_dropped)
    return {"cfg_valid": core.cfg.valid, "cfg_payload": core.cfg.payload}, outputs


class _ResultWatch:
    """What ``run_core`` looks at as the run goes: each result as it leaves the engine (the
    telemetry takes every one) with its cycle and the INT edge before it, each sample offered
    to the engine, the frames decoded from the UART's bytes (``received``)."""

    def __init__(self, *, n_results, n_frames, until, max_cycles, trace, progress):
        from ...host.protocol import FrameDecoder
        self.n_results, self.n_frames, self.until = n_results, n_frames, until
        self.max_cycles, self.trace, self.progress = max_cycles, trace, progress
        self.results, self.cycles, self.ints, self.frames, self.samples = [], [], [], [], []
        self.received = bytearray()
        self.decoder = FrameDecoder()
        self.end = None
        self.ports = {}                 # the attitude port's at the end (``core_ports``)

    def more_wanted(self):
        self.frames += [f for _, _, f in self.decoder.feed(self.received)]
        self.received.clear()
        if self.until is not None:
            if self.until():
                return False
            if self.n_results is None and self.n_frames is None:
                return True                 # no count: until() alone ends the run
        return (len(self.results) < (self.n_results or 0) or
                len(self.frames) < (self.n_frames or 0))

    async def scenario(self, bench, writes):
        for addr, value in writes:
            await bench.put("cfg", {"addr": addr, "data": value})
        last_int, level, s_prev, progress = None, 0, 0, self.progress
        while self.more_wanted():
            cycle = bench.cycle
            if cycle >= self.max_cycles:
                raise TimeoutError(f"{len(self.results)} results, {len(self.frames)} "
                                   f"frames after {cycle} cycles; status "
                                   f"{bench.get('status')}")
            if progress is not None:
                progress.set_postfix_str(f"cycle {cycle:,}", refresh=False)
                progress.update(0)
            pin = bench.get("imu_int")
            if pin and not level:
                last_int = cycle
            level = pin
            s_valid = bench.get("s_valid")
            if s_valid and not s_prev:
                # a sample offered to the engine: it holds until taken
                self.samples.append(bench.get("s_payload"))
                if self.trace:
                    self.trace.at_sample(len(self.samples), cycle)
            s_prev = s_valid
            if bench.get("r_valid"):
                # the result as it leaves the engine; recorded once, when it is taken
                payload, first_cycle = bench.get("r_payload"), cycle
                while not bench.get("r_ready"):
                    await bench.tick()
                self.results.append(payload)
                self.cycles.append(first_cycle)
                self.ints.append(last_int)
                if progress is not None:
                    progress.update(1)
                await bench.tick()
                continue
            await bench.changed("r_valid", "imu_int", "s_valid", until=self.max_cycles)
        self.end = (bench.cycle, *(bench.get(n) for n in ("counters", "status", "asa")))
        self.ports = {n: bench.get(n) for n in bench.ports if n.startswith("attitude_")}
        bench.check()


def run_core(setup=None, *, n_results=None, n_frames=None, model=None, max_cycles=None,
             baud=DEFAULT_BAUD, core_kwargs=None, writes=(), vcd=None, progress=None,
             compiled=None, until=None, keep_on_interrupt=False):
    """The whole ``AHRSCore`` (driver, engine, telemetry) against the models until the engine
    has produced ``n_results`` results and the UART has carried ``n_frames`` frames (either
    may be None). The wiring follows ``setup.config.wiring`` (I2C: the models on an
    ``I2CBusModel``, ``CoreRun.bus``). Each result is recorded as it leaves the engine (the
    telemetry scheduler takes every one) with the cycle of the INT edge that announced its
    sample, so ``CoreRun.latencies_us`` is the data-ready-to-attitude latency. ``writes``:
    (address, value) register writes through the ``cfg`` port at the start. ``progress``: a bar
    told of each result and the cycle reached (``run_frontend``). ``compiled``: as
    ``run_frontend``'s (``CoreRun.compiled`` says which path ran). ``until()``: asked at each
    result and data-ready edge; True ends the run (instead of, or before, the counts).
    ``keep_on_interrupt``: as ``run_frontend``'s (``CoreRun.interrupted``)."""
    if n_results is None and n_frames is None and until is None:
        raise ValueError("run_core needs n_results, n_frames or until")
    setup = setup or SimSetup()
    core, harness, key = core_harness(setup, baud=baud, core_kwargs=core_kwargs)
    model = model or setup.model(magnetometer=setup.config.magnetometer)
    bus = None if setup.config.wiring == "spi" else primary_bus(setup, model)
    if max_cycles is None:
        period = setup.sample_period_s * setup.clk_freq
        frame_s = 10 * core.framer.frame_bytes / baud * core.telemetry_divider
        samples = max(n_results or 0, (n_frames or 0) * max(1, frame_s / setup.sample_period_s))
        max_cycles = int(setup.bring_up_budget_cycles() + 40_000 +
                         (samples + 3) * period * 1.5)
    trace = vcd and RunTrace(vcd, setup.clk_freq, "core", setup.config.wiring,
                             status_fields(core.status))
    watch = _ResultWatch(n_results=n_results, n_frames=n_frames, until=until,
                         max_cycles=max_cycles, trace=trace, progress=progress)
    bench = open_bench(harness, *core_ports(core), setup.clk_freq, compiled=compiled,
                       name="core", key=key, max_cycles=max_cycles,
                       models=PinModels(setup.clk_freq, mpu=model, bus=bus),
                       uart=("uart_tx", core.uart.divisor, watch.received), trace=trace)
    start = time.perf_counter()
    interrupted = bench.run(lambda b: watch.scenario(b, writes),
                            keep_on_interrupt=keep_on_interrupt, trace=trace)
    if watch.end is None:               # Ctrl-C: the last cycle looked at
        # (the compiled design is still there to read; Amaranth's simulator has ended)
        watch.end = (bench.last_cycle, *((bench.get(n) for n in ("counters", "status", "asa"))
                                          if bench.compiled else ({}, {}, [])))
    if trace:
        finish_trace(trace, model, bus, watch.end[0], len(watch.samples), interrupted)
    wall = time.perf_counter() - start
    watch.more_wanted()                 # the bytes that came after the last look
    cycles, counters, status, asa = watch.end
    return CoreRun(watch.results, watch.cycles, watch.ints, watch.frames, counters, status,
                   cycles, wall, model, asa, core, bench.compiled, watch.samples, bus,
                   interrupted, watch.ports)
