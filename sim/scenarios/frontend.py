"""The front end's scenario: a ``SensorFrontEnd`` brought up against the sensor models, its
samples collected (``run_frontend``), on either simulator (``sim.bench``); what the tests and
``python -m mpu9250_ahrs simulate`` use. Beside it the checks of a sample against the models
(``sample_matches``, ``expected_mag``) and the bus time of a read (``sample_read_cycles``).
"""

import time
from dataclasses import dataclass, field
from typing import List, Optional

from ...hdl.contract import ak8963_regs as A
from ..bench.open_bench import open_bench
from ..bench.harness import CosimHarness, PinModels
from ..bench.waveforms import RunTrace, TraceWindow
from ..models.i2c_bus import I2CBusModel
from ..models.mpu9250_model import MPU9250Model
from .setup import SimSetup, primary_bus


__all__ = ["CosimResult", "run_frontend", "sample_matches", "expected_mag", "status_fields",
           "sample_read_cycles", "finish_trace"]


@dataclass
class CosimResult:
    samples: List[dict]
    status: dict
    cycles: int
    bring_up_cycles: Optional[int]
    wall_s: float
    model: Optional[MPU9250Model]
    bus: Optional[I2CBusModel] = None                       # I2C wiring
    status_log: List[tuple] = field(default_factory=list)   # (cycle, status dict) on change
    asa: List[int] = field(default_factory=list)            # the driver's asa port at the end
    sample_cycles: List[int] = field(default_factory=list)  # when each sample was taken
    rate_errors: int = 0                                    # early samples (its pulses counted)
    who_am_i: Optional[int] = None                          # its who_am_i port at the end
    self_test: dict = field(default_factory=dict)           # its self_test port at the end
    compiled: bool = False                                  # the compiled path ran
    interrupted: bool = False               # Ctrl-C ended the run: what it had simulated
    level: dict = field(default_factory=dict)   # its level port at the end (read levelling)
    level_log: List[tuple] = field(default_factory=list)    # (cycle, level dict) on change,
                                                            # as seen at each wake

    @property
    def cycles_per_s(self):
        return self.cycles / self.wall_s if self.wall_s else float("inf")


def sample_matches(design_sample, model_sample):
    """True if a sample out of the gateware carries exactly the model's accel/temp/gyro."""
    return (tuple(design_sample["accel"]) == model_sample.accel and
            design_sample["temp"] == model_sample.temp and
            tuple(design_sample["gyro"]) == model_sample.gyro)


def expected_mag(ak_bytes, mag_ok=True, previous=None):
    """Magnetometer fields and flags a sample must carry, from the AK8963 bytes ST1..ST2 the
    sensor read returned and those of the read before (``previous``: None if there was none),
    independent of the gateware's own parsing: new needs ST1.DRDY, and either no DRDY in the
    previous read or field bytes (HX..HZ, ST2) other than its."""
    if not mag_ok:
        return [0, 0, 0], {"mag_valid": 0, "mag_overflow": 0, "mag_new": 0, "mag_dor": 0}
    st1, st2 = ak_bytes[0], ak_bytes[7]
    mag = [int.from_bytes(ak_bytes[1 + 2 * i:3 + 2 * i], "little", signed=True)
           for i in range(3)]
    repeated = previous is not None and bool(previous[0] & A.ST1_DRDY) and \
        bytes(previous[1:8]) == bytes(ak_bytes[1:8])
    new = bool(st1 & A.ST1_DRDY) and not repeated
    hofl = bool(st2 & A.ST2_HOFL)
    return mag, {"mag_valid": int(new and not hofl), "mag_overflow": int(new and hofl),
                 "mag_new": int(new), "mag_dor": int(new and bool(st1 & A.ST1_DOR))}


def status_fields(status):
    """The fields of a status port (a ``View`` of a struct): (name, width) each, as a
    waveform's save file shows them."""
    from amaranth import Shape
    from amaranth.lib import data
    return [(name, Shape.cast(field.shape).width)
            for name, field in data.Layout.cast(status.shape())]


def sample_read_cycles(result, setup):
    """Median cycles the bus spends reading one sample: the SPI burst from INT_STATUS (CS fall
    to CS rise), or on I2C the MPU9250 read's START to the AK8963 read's STOP."""
    import statistics
    from ...hdl.contract import mpu9250_regs as R
    f = setup.clk_freq
    if result.bus is None:
        spans = [end - start for start, end, first, n, read in result.model.transactions
                 if read and first == R.INT_STATUS]
    else:
        bus = result.bus
        spans = []
        for k, (start, stop, first) in enumerate(bus.frames):
            entry = bus.log[first] if first < len(bus.log) else None
            if entry and entry[1] == setup.config.i2c_address and entry[3] == R.INT_STATUS:
                end = stop
                nxt = bus.frames[k + 1] if k + 1 < len(bus.frames) else None
                if nxt and nxt[2] < len(bus.log) and bus.log[nxt[2]][1] == A.I2C_ADDRESS:
                    end = nxt[1]
                spans.append(end - start)
    return round(statistics.median(spans) * f) if spans else None


class _SampleWatch:
    """What ``run_frontend`` looks at as the run goes: the samples taken and their cycles, the
    status on every change, bring-up's end; ``observe`` says when the run is done (its
    count, ``until`` or ``stop`` met, or the budget spent: a ``TimeoutError`` unless
    ``until`` or ``stop`` was given)."""

    def __init__(self, *, n_samples, until, stop, max_cycles, model, trace, progress):
        self.n_samples, self.until, self.stop, self.max_cycles = n_samples, until, stop, \
            max_cycles
        self.model, self.trace, self.progress = model, trace, progress
        self.samples, self.sample_cycles, self.log, self.level_log = [], [], [], []
        self.status, self.cycles, self.bring_up, self.seen = None, 0, None, 0
        self.end = {"asa": [], "rate_errors": 0, "who_am_i": None, "self_test": {},
                    "level": {}}

    def observe(self, cycle, taken, payload, status, level=None):
        self.seen = cycle                   # the last cycle looked at (an interrupted run's end)
        if level is not None and (not self.level_log or self.level_log[-1][1] != level):
            self.level_log.append((cycle, level))
        if status != self.status:
            self.log.append((cycle, status))
            self.status = status
        if status["streaming"] and self.bring_up is None:
            self.bring_up = cycle
        if taken:
            self.samples.append(payload)
            self.sample_cycles.append(cycle)
            if self.trace:
                self.trace.at_sample(len(self.samples), cycle)
        if self.progress is not None:
            self.progress.set_postfix_str(f"cycle {cycle:,}", refresh=False)
            self.progress.update(1 if taken else 0)
        done = (self.n_samples and len(self.samples) >= self.n_samples) or \
            (self.until and self.until(status)) or \
            (self.stop and self.stop(cycle, status, self.sample_cycles, self.samples))
        if done or cycle >= self.max_cycles:
            self.cycles = cycle
            if not done and self.until is None and self.stop is None:
                model = self.model
                raise TimeoutError(
                    f"{len(self.samples)} of {self.n_samples} samples after {cycle} cycles; "
                    f"status {status}" + (f"; model violations: {model.violations[:3]}"
                                          if model is not None and model.violations else ""))
            return True
        return False

    async def scenario(self, bench, ready):
        """Take samples until done: always ready (woken only by changes of the sample
        stream's valid or the status), or ``ready(cycle)`` per cycle (each transfer seen)."""
        if ready is None:
            bench.set("samples_ready", 1)
            while not self.observe(bench.cycle, bench.get("samples_valid"),
                                   bench.get("samples_payload"), bench.get("status"),
                                   bench.get("level")):
                await bench.changed("samples_valid", "status", until=self.max_cycles)
        else:
            bench.set("samples_ready", ready(0))
            while True:
                cycle = bench.cycle
                valid, status = bench.get("samples_valid"), bench.get("status")
                level = bench.get("level")
                payload = bench.get("samples_payload") if valid else None
                await bench.tick()
                taken = valid and ready(cycle)
                bench.set("samples_ready", ready(cycle + 1))
                if self.observe(cycle + 1, taken, payload, status, level):
                    break
        self.end = {name: bench.get(name) for name in self.end}
        bench.check()


def frontend_bench(setup, dut, model, *, stuck_miso, injector, bus_kw, compiled, max_cycles,
                   trace):
    """The bench of ``run_frontend`` (``sim.bench.open_bench``) and the bus model of I2C
    wiring (None for SPI): ``(bench, bus)``."""
    bus = None
    if setup.config.wiring == "spi":
        harness = CosimHarness(dut, spi=dut.pins, int_pin=dut.int_pin,
                               early_sample=dut.early_sample)
    else:
        harness = CosimHarness(dut, i2c=dut.pins, int_pin=dut.int_pin,
                               early_sample=dut.early_sample)
        bus = primary_bus(setup, model, injector=injector, bus_kw=bus_kw)
    if injector is not None:
        injector.mpu, injector.bus = model, bus
    harness.monitor(dut.samples, "samples")
    models = None if model is None and bus is None else \
        PinModels(setup.clk_freq, mpu=model, bus=bus, injector=injector)
    bench = open_bench(
        harness, {"samples_ready": dut.samples.ready},
        {"samples_valid": dut.samples.valid, "status": dut.status,
         "samples_payload": dut.samples.payload, "asa": dut.asa,
         "rate_errors": harness.rate_errors, "who_am_i": dut.who_am_i,
         "self_test": dut.self_test, "level": dut.level},
        setup.clk_freq, compiled=compiled, max_cycles=max_cycles,
        name="frontend-" + setup.config.wiring,
        key=("frontend", setup.clk_freq, setup.config, setup.driver_timing(), setup.levelling),
        models=models, stuck_miso=stuck_miso, trace=trace)
    return bench, bus


def run_frontend(setup=None, *, n_samples=0, model=None, stuck_miso=None, max_cycles=None,
                 until=None, vcd=None, ready=None, bus_kw=None, injector=None, stop=None,
                 progress=None, compiled=None, keep_on_interrupt=False):
    """Simulate until ``n_samples`` samples came out, ``until(status_dict)`` is true,
    ``stop(cycle, status_dict, sample_cycles, samples)`` is true, or ``max_cycles`` (an error
    unless ``until`` or ``stop`` was given and is merely never met). ``injector``: a fault
    (``sim.scenarios.faults.FaultInjector``), handed the models.

    The wiring follows ``setup.config.wiring``. ``stuck_miso`` (0 or 1) simulates an unplugged
    sensor: SPI: CIPO stuck at that level; I2C: nothing on the bus acknowledges. ``bus_kw``: extra
    ``I2CBusModel`` arguments (clock stretching, a stuck bus).

    ``ready(cycle)`` gives the consumer's ready per cycle (default: always ready).
    ``vcd``: the waveform to write (a path, ``.vcd`` or ``.fst``, or a
    ``sim.bench.waveforms.Waveform`` with a window); a GTKWave save file is written beside it.
    ``progress``: a bar (``mpu9250_ahrs.progress``: ``update``, ``set_postfix_str``) told of
    each sample and the cycle reached.
    ``compiled``: run the design compiled (``sim.bench.compiled_wanted``;
    ``CosimResult.compiled`` says which path ran). ``keep_on_interrupt``: Ctrl-C
    (KeyboardInterrupt) during the run returns what was simulated (``CosimResult.interrupted``)
    rather than raising.
    """
    setup = setup or SimSetup()
    dut = setup.frontend()
    trace = vcd and RunTrace(vcd, setup.clk_freq, "frontend", setup.config.wiring,
                             status_fields(dut.status))
    if model is None and stuck_miso is None:
        model = setup.model()
    if max_cycles is None:
        period = setup.sample_period_s * setup.clk_freq
        max_cycles = int(setup.bring_up_budget_cycles() + 20_000 +
                         (n_samples + 3) * period * 1.5)
    bench, bus = frontend_bench(setup, dut, model, stuck_miso=stuck_miso, injector=injector,
                                bus_kw=bus_kw, compiled=compiled, max_cycles=max_cycles,
                                trace=trace)
    watch = _SampleWatch(n_samples=n_samples, until=until, stop=stop, max_cycles=max_cycles,
                         model=model, trace=trace, progress=progress)
    start = time.perf_counter()
    interrupted = bench.run(lambda b: watch.scenario(b, ready),
                            keep_on_interrupt=keep_on_interrupt, trace=trace)
    traced_to = watch.cycles
    if interrupted:
        watch.cycles = watch.seen
        # Amaranth's simulator went on past the last cycle looked at: its file is kept
        traced_to = bench.last_cycle if bench.compiled else TraceWindow.NEVER
    if trace:
        finish_trace(trace, model, bus, traced_to, len(watch.samples), interrupted)
    wall = time.perf_counter() - start
    end = watch.end
    return CosimResult(watch.samples, watch.status, watch.cycles, watch.bring_up, wall,
                       model, bus, watch.log, end["asa"], watch.sample_cycles,
                       end["rate_errors"], end["who_am_i"], end["self_test"], bench.compiled,
                       interrupted, end["level"], watch.level_log)


def finish_trace(trace, model, bus, end_cycle, samples, interrupted):
    """``trace.finish``; after Ctrl-C a window the run never reached is no error (no file)."""
    try:
        trace.finish(model, bus, end_cycle, samples)
    except ValueError:
        if not interrupted:
            raise
