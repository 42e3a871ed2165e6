"""Co-simulation: the gateware in Amaranth's simulator talking to the Python sensor models.

``attach_mpu9250`` adds a simulator process that plays an ``MPU9250Model`` on the SPI pins: it
samples CS_n, SCLK and COPI as flip-flops would, hands edges to the model with time stamps
``cycle / clk_freq``, and drives CIPO (with the model's real output delay) and INT.

``run_frontend`` brings a ``SensorFrontEnd`` up against a model and collects samples; it is what
the tests and ``python -m mpu9250_ahrs simulate`` use.
"""

import math
import time
from dataclasses import dataclass, field, replace
from typing import List, Optional

from amaranth import Elaboratable, Signal
from amaranth.sim import Simulator

from ..hdl.primitives.clocking import SYSTEM_CLOCK_HZ
from ..hdl.contract.defaults import DEFAULT_BAUD
from ..hdl.sensor.mpu9250_driver import DriverTiming, MPU9250Config
from ..hdl.sensor.sensor_frontend import SensorFrontEnd
from .i2c_bus import I2CBusModel
from .mpu9250_model import MPU9250Model, MPU9250Timing
from ..hdl.contract import ak8963_regs as A
from .ak8963_model import AK8963Model, AK8963Timing
from .sources import counting_field, counting_source
from .compiled_design import NEVER
from .streams import Monitored
from .waveforms import RunTrace, TraceWindow, gtkw_beside
from ..host.protocol import to_python


__all__ = ["CosimHarness", "PinModels", "attach_models", "attach_mpu9250", "attach_stuck_miso",
           "SimSetup", "QUICK_CORE_BAUD", "quick_core_setup", "CosimResult", "run_frontend",
           "CoreRun", "core_harness", "run_core",
           "simulator_name", "gtkw_beside", "sample_matches", "expected_mag", "sample_read_cycles"]


class CosimHarness(Monitored):
    """Wraps a design for co-simulation with simulation-only helpers.

    ``cycle`` counts clock edges: the time base of the models. The model process drives
    ``cipo_model`` (SPI) straight onto the design's CIPO pin, with the level SDO has at the next
    clock edge (the model delays each bit by its output delay, ``MPU9250Timing.sdo_delay_s``, in
    simulated time); ``scl_model_low``/``sda_model_low`` (I2C) and ``int_model`` reach the
    design one clock later, so the process can run right after the edge it reacts to. The I2C
    lines ``scl``/``sda`` are the wired AND of the design's and the devices' drivers.
    ``wake_at`` is the cycle at which the models next want to run with
    no pin change; ``wake`` is high in it. ``monitor(stream, name)`` watches a stream of the
    design for the stream rules; ``check(ctx)`` at the end of the run (``Monitored``).
    ``early_sample``: the front end's pulse per early sample, counted in ``rate_errors`` (16
    bits, saturating, as the board's RATE_ERRORS counts them in the command decoder, which a
    front end alone does not have).
    """
    def __init__(self, dut, *, spi=None, i2c=None, int_pin=None, early_sample=None):
        super().__init__(dut)
        self.spi, self.i2c, self.int_pin = spi, i2c, int_pin
        self.early_sample = early_sample
        self.rate_errors = Signal(16)
        self.cycle = Signal(40)
        self.wake_at = Signal(40, init=(1 << 40) - 1)
        self.wake = Signal()
        self.cipo_model = Signal()
        self.int_model = Signal()
        self.scl_model_low = Signal()
        self.sda_model_low = Signal()
        self.scl = Signal(init=1)
        self.sda = Signal(init=1)

    def elaborate(self, platform):
        m = super().elaborate(platform)                 # the design and its monitors
        m.d.sync += self.cycle.eq(self.cycle + 1)
        m.d.comb += self.wake.eq(self.cycle == self.wake_at)
        if self.early_sample is not None:
            with m.If(self.early_sample & ~self.rate_errors.all()):
                m.d.sync += self.rate_errors.eq(self.rate_errors + 1)
        if self.spi is not None:
            # the pin itself: the model process drives the level it has at the next clock edge
            m.d.comb += self.spi.cipo.eq(self.cipo_model)
        if self.int_pin is not None:
            m.d.sync += self.int_pin.eq(self.int_model)
        if self.i2c is not None:
            scl_q, sda_q = Signal(), Signal()
            m.d.sync += [scl_q.eq(self.scl_model_low), sda_q.eq(self.sda_model_low)]
            m.d.comb += [self.scl.eq(~(self.i2c.scl_oe | scl_q)),
                         self.sda.eq(~(self.i2c.sda_oe | sda_q)),
                         self.i2c.scl_i.eq(self.scl), self.i2c.sda_i.eq(self.sda)]
        return m


class PinModels:
    """What the models do at one wake-up: given the cycle and the watched pins' levels, they
    take the edges, and say which levels they drive (``cipo_model``, ``int_model``,
    ``scl_model_low``, ``sda_model_low``: the ``CosimHarness`` signal names) and at which cycle
    they next want to run with no pin change. Shared by Amaranth's simulator
    (``attach_models``) and the compiled path (``sim.compiled_board``), so both play the
    models alike. ``bus``: the ``I2CBusModel`` of a design with I2C lines; None: it has SPI
    pins (``spi``)."""

    def __init__(self, clk_freq, *, mpu, bus=None, injector=None):
        self.clk_freq = clk_freq
        self.mpu, self.bus, self.injector, self.spi = mpu, bus, injector, bus is None
        self.cs_prev, self.sclk_prev = 1, 1
        self.driven = {}

    def _drive(self, name, value):
        if self.driven.get(name) != value:
            self.driven[name] = value
            return {name: value}
        return {}

    def initial(self):
        """What the models drive before anything happens (a bus stuck from the start, say)."""
        out = {}
        bus, mpu = self.bus, self.mpu
        if bus is not None:
            out.update(self._drive("scl_model_low", int(bus.scl_low)))
            out.update(self._drive("sda_model_low", int(bus.sda_low)))
        if mpu is not None:
            out.update(self._drive("int_model", mpu.int_level))
        return out

    def react(self, cycle, a, b, copi=0):
        """At ``cycle``: ``a``, ``b`` = CS_n, SCLK (SPI; ``copi`` too) or SCL, SDA (I2C).
        Returns (levels changed, the next cycle to wake at or ``NEVER``)."""
        mpu, bus, injector, clk_freq = self.mpu, self.bus, self.injector, self.clk_freq
        out = {}
        t = cycle / clk_freq
        if injector is not None:
            injector.advance(t)
        absent = injector is not None and injector.mpu_absent
        if mpu is not None:
            mpu.advance(t)
        if self.spi and absent:
            self.cs_prev, self.sclk_prev = a, b
            out.update(self._drive("cipo_model", 1))
        elif self.spi:
            cs_n, sclk = a, b
            if cs_n != self.cs_prev and not cs_n:
                mpu.cs_edge(t, cs_n)
            if sclk != self.sclk_prev:
                mpu.sclk_edge(t, sclk, copi)
            if cs_n != self.cs_prev and cs_n:
                mpu.cs_edge(t, cs_n)
            self.cs_prev, self.sclk_prev = cs_n, sclk
            mpu.advance(t)
            # the level SDO has when the design's first CIPO flip-flop next samples it
            level = mpu.sdo_at(t + 1 / clk_freq)
            if injector is not None and injector.cipo is not None:
                level = injector.cipo
            out.update(self._drive("cipo_model", level))
        if bus is not None:
            bus.lines(t, a, b)
            out.update(self._drive("scl_model_low", int(bus.scl_low)))
            out.update(self._drive("sda_model_low", int(bus.sda_low)))
        if mpu is not None:
            level = 0 if absent else mpu.int_level
            if injector is not None and injector.int_level is not None:
                level = injector.int_level
            out.update(self._drive("int_model", level))
        events = [e for e in (mpu and mpu.next_event, bus and bus.next_event,
                              injector and injector.next_event) if e is not None]
        change = mpu.sdo_change_at if self.spi and not absent else None
        if change is not None:          # wake the cycle before the edge that will see it
            events.append(change - 1 / clk_freq)
        wake = NEVER if not events else \
            max(cycle + 1, math.ceil(min(events) * clk_freq - 1e-6))
        return out, wake


def attach_models(sim, harness, clk_freq, *, mpu, bus=None, injector=None):
    """Play ``mpu`` (an ``MPU9250Model``) on the harness's SPI pins, or ``bus`` (an
    ``I2CBusModel`` holding the MPU9250 and what its bypass exposes) on its I2C lines, plus the
    INT pin. The process wakes only on pin changes and on the models' own events
    (``PinModels``). ``injector`` (``sim.faults.FaultInjector``): a fault switched on and off
    in time, with its pin overrides (CIPO, INT) and an MPU9250 that is not there (SPI: it sees
    no pin changes, CIPO floats high, INT low)."""
    spi = harness.spi
    watched = [harness.wake]
    sampled = [harness.cycle]
    if spi is not None:
        watched += [spi.cs_n, spi.sclk]
        sampled += [spi.copi]
    if bus is not None:
        watched += [harness.scl, harness.sda]
    models = PinModels(clk_freq, mpu=mpu, bus=bus, injector=injector)

    async def process(ctx):
        wake_prev = NEVER

        def apply(levels):
            for name, value in levels.items():
                ctx.set(getattr(harness, name), value)

        apply(models.initial())
        async for values in ctx.changed(*watched).sample(*sampled):
            a, b = values[1:len(watched)]
            cycle = values[len(watched)]
            copi = values[len(watched) + 1] if spi is not None else 0
            levels, wake = models.react(cycle, a, b, copi)
            apply(levels)
            if wake != wake_prev:
                wake_prev = wake
                ctx.set(harness.wake_at, wake)
    sim.add_process(process)


def attach_mpu9250(sim, model, harness, clk_freq):
    """SPI wiring: ``model`` on the harness's SPI pins and INT."""
    attach_models(sim, harness, clk_freq, mpu=model)


def attach_stuck_miso(sim, harness, level):
    """An unplugged sensor: CIPO held at ``level``, INT never asserted."""
    async def process(ctx):
        ctx.set(harness.cipo_model, level)
    sim.add_process(process)


@dataclass
class SimSetup:
    """Scaled real time for simulation: same behaviour, fewer cycles.

    Start-up and reset delays are multiplied by ``delay_scale`` in both the driver and the
    model; the sample period and INT pulse by ``odr_scale`` in the model (the driver's
    interrupt timeout and self-test waits follow); the self-test runs only with
    ``self_test`` and then sums ``self_test_samples``.
    """
    clk_freq: float = SYSTEM_CLOCK_HZ
    config: MPU9250Config = field(default_factory=MPU9250Config)
    delay_scale: float = 1e-3
    odr_scale: float = 0.2
    mag_power_down_s: float = 100e-6       # the driver's AK8963 power-down wait
    # The AK8963 runs on its own oscillator: a period this much longer than nominal keeps its
    # measurements from locking to an exact multiple of the sample period (in which a
    # measurement can land in every read's data protection and be skipped, for ever).
    ak_clock_error: float = 0.0
    # The self-tests at bring-up (``MPU9250Config.self_test``) add their waits to every
    # bring-up (with SPI about 3 times the cycles, with I2C 7 times): simulations leave them
    # out unless they ask (``self_test=True``, as ``simulate`` does), and then sum
    # ``self_test_samples`` samples (None: the config's 128, 2 x 128 reads at 1 kHz)
    self_test: bool = False
    self_test_samples: Optional[int] = 2

    def __post_init__(self):
        if not self.self_test:
            self.config = replace(self.config, self_test=False)
        elif not self.config.self_test:
            # e.g. ``dataclasses.replace(setup, self_test=True)`` of a set-up made without
            # them: its config has lost them, and would run none, silently
            raise ValueError("SimSetup(self_test=True) needs a config with self_test")
        elif self.self_test_samples is not None:
            self.config = replace(self.config, self_test_samples=self.self_test_samples)

    @staticmethod
    def default_odr_scale(config, clk_freq):
        """The sample-period scale ``simulate`` and ``report`` use for ``config`` at
        ``clk_freq``: 0.2 where the shortened period still gives the design twice the cycles
        a sample needs (``rate_budget``: its read, or the engine's update), else 1 (real
        time). So 0.2 with SPI up to 1 kHz at the board's clock; 1 with I2C at 1 kHz (its
        400 kHz bus takes ~0.7 ms per nine-axis read), at 8 kHz (its period is short
        already), and at a clock too slow for the shortened period (a period shorter than
        the read would lose samples the design keeps at the real rate)."""
        from ..hdl.board.top import rate_budget
        scale = 0.2
        period_cycles = scale * clk_freq / config.output_data_rate
        fits = period_cycles >= 2 * rate_budget(config, clk_freq)["cycles_per_sample"]
        return scale if fits else 1.0

    @property
    def sample_period_s(self):
        return self.odr_scale / self.config.output_data_rate

    def telemetry_divider(self, baud):
        """The telemetry divider a build would have if the sample period were this set-up's
        (``telemetry_divider_for`` at ``1 / sample_period_s``): a build's default fits the
        real period, and a shortened one would leave most results no time on the UART."""
        from ..hdl.board.top import telemetry_divider_for
        return telemetry_divider_for(self.config, baud, rate=1 / self.sample_period_s)

    def driver_timing(self):
        return DriverTiming(time_scale=self.delay_scale, mag_power_down_s=self.mag_power_down_s,
                            sample_period_s=self.sample_period_s,
                            # the AK8963's period is scaled like the MPU9250's
                            mag_timeout_s=DriverTiming.mag_timeout_s * self.odr_scale)

    def bring_up_budget_cycles(self):
        """Cycles that cover three bring-up attempts' waits plus the magnetometer's SLV4
        transfers (each waits for a sample tick of the MPU9250's I2C master): the start of
        every simulation's cycle budget."""
        timing = self.driver_timing()
        power_up, reset, _ = timing.cycles(self.clk_freq, self.config)
        return 3 * (power_up + reset + self.self_test_cycles()) + \
            40 * self.sample_period_s * self.clk_freq

    def self_test_cycles(self):
        """A bound on the cycles the self-tests add to a bring-up: their waits, and their reads
        at 400 kHz (the slowest bus: 9 bits a byte)."""
        cfg = self.config
        if not cfg.self_test:
            return 0
        waits = self.driver_timing().self_test_waits(self.clk_freq, cfg)
        reads = 2 * cfg.self_test_samples
        byte = 9 / 400e3 * self.clk_freq
        return (3 * waits.settle + reads * (waits.interval + 16 * byte) + 20 * byte +
                (waits.mag + 10 * byte if cfg.magnetometer else 0))

    def model_timing(self):
        return MPU9250Timing().scaled(delays=self.delay_scale, odr=self.odr_scale)

    def frontend(self, **kwargs):
        return SensorFrontEnd(clk_freq=self.clk_freq, config=self.config,
                              timing=self.driver_timing(), **kwargs)

    def ak8963(self, **kwargs):
        kwargs.setdefault("source", counting_field())
        return AK8963Model(timing=AK8963Timing().scaled(
            odr=self.odr_scale * (1 + self.ak_clock_error)), **kwargs)

    def model(self, *, magnetometer=True, **kwargs):
        """An MPU9250 model (counting sensor values) with an AK8963 on its auxiliary bus
        (``model.aux_devices[0x0C]``) unless ``magnetometer`` is False."""
        kwargs.setdefault("source", counting_source())
        if magnetometer:
            kwargs.setdefault("aux_devices", {A.I2C_ADDRESS: self.ak8963()})
        return MPU9250Model(timing=self.model_timing(), **kwargs)


# The whole core's quick set-up (``quick_core_setup``) and its UART's baud (a quarter of its
# clock, so that frames come quickly)
QUICK_CORE_BAUD = 3_000_000


def quick_core_setup():
    """The whole core's quick set-up: the default configuration (SPI, the magnetometer, 1 kHz)
    at a 12 MHz clock (a quarter of the board's cycles for the same bring-up and samples),
    the sample period scaled by 0.4 (a frame at ``QUICK_CORE_BAUD``, 3,680 cycles, fits in
    one). One set-up for the tests that run the whole core and the fault catalogue's
    ``host_garbage``, so that they share one compiled build (keyed by the set-up, the core's
    parameters and the baud); ``tests/sim/test_compiled_board.py`` checks it against
    Amaranth's simulator on this set-up."""
    return SimSetup(clk_freq=12e6, odr_scale=0.4)


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


def simulator_name(compiled):
    """Which simulator ran, as summaries say it."""
    return "compiled (Verilator)" if compiled else "python (Amaranth)"


def compiled_wanted(compiled, *, vcd=None, supported=True):
    """Whether a co-simulation takes the compiled path (``sim.compiled_board``):
    ``compiled`` True asks for it (an error if it cannot be had), False for Amaranth's
    simulator, None (auto): the compiled path when Verilator and g++ are there, the run is
    one it supports (no VCD, no stuck CIPO) and its build is cached
    or pays for itself (``_auto_build``); "prefer": the compiled path whenever it can run
    this (built if need be), else Amaranth's simulator (what ``simulate`` does). Returns
    True, False or None (still auto). A VCD on the compiled path needs a build of its own
    (Verilator's ``--trace``): auto leaves waveforms to Amaranth's simulator."""
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


def _auto_build(compiled, max_cycles, make):
    """The compiled design ``make(cached_only)`` for ``compiled`` True, or for None (auto)
    when the cache has it or the run's budget (``max_cycles``) pays for a build; else (and
    for False, ``compiled_wanted``'s no) None: Amaranth's simulator."""
    from .compiled_board import WORTH_A_BUILD_CYCLES
    from .compiled_design import NotBuilt
    if compiled is False:
        return None
    if compiled or max_cycles >= WORTH_A_BUILD_CYCLES:
        return make(False)
    try:
        return make(True)
    except NotBuilt:
        return None


def primary_bus(setup, model, *, injector=None, bus_kw=None):
    """I2C wiring: the ``I2CBusModel`` of the board's bus, ``model`` (an ``MPU9250Model``, or
    None: nothing answers) at ``setup``'s address with what its bypass exposes; nobody while
    ``injector`` (a fault) has the MPU9250 absent. ``bus_kw``: ``I2CBusModel``'s other
    arguments (clock stretching, a stuck bus)."""
    address = setup.config.i2c_address

    def lookup(a):
        if model is None or (injector is not None and injector.mpu_absent):
            return None
        return model.primary_bus_device(a, address)
    return I2CBusModel(lookup, **(bus_kw or {}))


def run_frontend(setup=None, *, n_samples=0, model=None, stuck_miso=None, max_cycles=None,
                 until=None, vcd=None, ready=None, bus_kw=None, injector=None, stop=None,
                 progress=None, compiled=None, keep_on_interrupt=False):
    """Simulate until ``n_samples`` samples came out, ``until(status_dict)`` is true,
    ``stop(cycle, status_dict, sample_cycles, samples)`` is true, or ``max_cycles`` (an error
    unless ``until`` was given and is merely never met). ``injector``: a fault
    (``sim.faults.FaultInjector``), handed the models.

    The wiring follows ``setup.config.wiring``. ``stuck_miso`` (0 or 1) simulates an unplugged
    sensor: SPI: CIPO stuck at that level; I2C: nothing on the bus acknowledges. ``bus_kw``: extra
    ``I2CBusModel`` arguments (clock stretching, a stuck bus).

    ``ready(cycle)`` gives the consumer's ready per cycle (default: always ready).
    ``vcd``: the waveform to write (a path, ``.vcd`` or ``.fst``, or a ``sim.waveforms.Waveform``
    with a window); a GTKWave save file is written beside it.
    ``progress``: a bar (``mpu9250_ahrs.progress``: ``update``, ``set_postfix_str``) told of
    each sample and the cycle reached.
    ``compiled``: run the design compiled (``compiled_wanted``; ``CosimResult.compiled``
    says which path ran). ``keep_on_interrupt``: Ctrl-C (KeyboardInterrupt) during the run
    returns what was simulated (``CosimResult.interrupted``) rather than raising.
    """
    setup = setup or SimSetup()
    compiled = compiled_wanted(compiled, vcd=vcd, supported=stuck_miso is None)
    dut = setup.frontend()
    trace = vcd and RunTrace(vcd, setup.clk_freq, "frontend", setup.config.wiring,
                             status_fields(dut.status))
    if model is None and stuck_miso is None:
        model = setup.model()
    if max_cycles is None:
        period = setup.sample_period_s * setup.clk_freq
        max_cycles = int(setup.bring_up_budget_cycles() + 20_000 +
                         (n_samples + 3) * period * 1.5)

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
    from .compiled_board import frontend_design
    design = _auto_build(compiled, max_cycles, lambda cached_only: frontend_design(
        harness, dut, cached_only=cached_only, trace=trace and trace.wave.format,
        key=("frontend", setup.clk_freq, setup.config, setup.driver_timing())))
    compiled = design is not None
    if compiled and trace:
        trace.start_compiled(design)
    sim = None
    if not compiled:
        sim = Simulator(harness)
        sim.add_clock(1 / setup.clk_freq)
        if model is not None or bus is not None:
            attach_models(sim, harness, setup.clk_freq, mpu=model, bus=bus,
                          injector=injector)
        else:
            attach_stuck_miso(sim, harness, stuck_miso)

    out = {"samples": [], "status": None, "cycles": 0, "bring_up": None, "log": [], "asa": [],
           "sample_cycles": [], "rate_errors": 0, "who_am_i": None, "self_test": {}}

    class Done(Exception):
        pass

    last = {"status": None}

    def observe(cycle, taken, payload, status):
        out["seen"] = cycle                 # the last cycle looked at (an interrupted run's end)
        st = to_python(status)
        if st != last["status"]:
            out["log"].append((cycle, st))
            last["status"] = st
        if st["streaming"] and out["bring_up"] is None:
            out["bring_up"] = cycle
        if taken:
            out["samples"].append(to_python(payload))
            out["sample_cycles"].append(cycle)
            if trace:
                trace.at_sample(len(out["samples"]), cycle)
        if progress is not None:
            progress.set_postfix_str(f"cycle {cycle:,}", refresh=False)
            progress.update(1 if taken else 0)
        done = (n_samples and len(out["samples"]) >= n_samples) or (until and until(st)) or \
            (stop and stop(cycle, st, out["sample_cycles"], out["samples"]))
        if done or cycle >= max_cycles:
            out["status"], out["cycles"] = st, cycle
            if not done and until is None and stop is None:
                raise TimeoutError(
                    f"{len(out['samples'])} of {n_samples} samples after {cycle} cycles; "
                    f"status {st}" + (f"; model violations: {model.violations[:3]}"
                                      if model is not None and model.violations else ""))
            raise Done

    async def testbench(ctx):
        try:
            if ready is None:
                # Always ready: each sample is valid for one cycle; wake only on changes.
                ctx.set(dut.samples.ready, 1)
                period = 1 / setup.clk_freq
                while True:
                    cycle = ctx.get(harness.cycle)
                    valid = ctx.get(dut.samples.valid)
                    observe(cycle, valid, ctx.get(dut.samples.payload), ctx.get(dut.status))
                    await ctx.changed(dut.samples.valid, dut.status.as_value()) \
                        .delay((max_cycles - cycle) * period)
            else:
                ctx.set(dut.samples.ready, ready(0))
                async for _, _, cycle, valid, payload, status in ctx.tick().sample(
                        harness.cycle, dut.samples.valid, dut.samples.payload, dut.status):
                    taken = valid and ready(cycle)
                    ctx.set(dut.samples.ready, ready(cycle + 1))
                    observe(cycle + 1, taken, payload, status)
        except Done:
            out["asa"] = to_python(ctx.get(dut.asa))
            out["rate_errors"] = ctx.get(harness.rate_errors)
            out["who_am_i"] = ctx.get(dut.who_am_i)
            out["self_test"] = to_python(ctx.get(dut.self_test))
            harness.check(ctx)
    if sim is not None:
        sim.add_testbench(testbench)

    start = time.perf_counter()
    if compiled:
        from amaranth.lib import data
        from .compiled_board import check_monitors, frontend_loop
        models = PinModels(setup.clk_freq, mpu=model, bus=bus, injector=injector)
        payload_layout = data.Layout.cast(dut.samples.payload.shape())
        status_layout = data.Layout.cast(dut.status.shape())
        try:
            out["interrupted"] = _run_interruptible(lambda: frontend_loop(
                design, models,
                lambda c, v, p, st: observe(c, v, data.Const(payload_layout, p),
                                            data.Const(status_layout, st)),
                max_cycles, ready=ready), keep_on_interrupt)
        except Done:
            from ..host.protocol import unpack
            out["asa"] = unpack(dut.asa.shape(), design.get("asa"))
            out["rate_errors"] = design.get("rate_errors")
            out["who_am_i"] = design.get("who_am_i")
            out["self_test"] = unpack(dut.self_test.shape(), design.get("self_test"))
            check_monitors(design, harness)
        if out.get("interrupted"):
            out["status"], out["cycles"] = last["status"], design.cycle
        if trace:
            design.close()                  # the waveform complete
    elif trace:
        with trace.python_writer(sim):
            out["interrupted"] = _run_interruptible(sim.run, keep_on_interrupt)
    else:
        out["interrupted"] = _run_interruptible(sim.run, keep_on_interrupt)
    traced_to = out["cycles"]
    if out.get("interrupted") and not compiled:
        out["status"], out["cycles"] = last["status"], out.get("seen", 0)
        # Amaranth's simulator went on past the last cycle looked at: its file is kept
        traced_to = TraceWindow.NEVER
    if trace:
        _finish_trace(trace, model, bus, traced_to, len(out["samples"]),
                      out.get("interrupted"))
    wall = time.perf_counter() - start
    return CosimResult(out["samples"], out["status"], out["cycles"], out["bring_up"], wall,
                       model, bus, out["log"], out["asa"], out["sample_cycles"],
                       out["rate_errors"], out["who_am_i"], out["self_test"], compiled,
                       bool(out.get("interrupted")))


def _run_interruptible(run, keep):
    """``run()`` (a simulator's run, a compiled loop); True if Ctrl-C ended it and ``keep``:
    the caller keeps what was simulated (without ``keep`` the interrupt goes on up)."""
    try:
        run()
    except KeyboardInterrupt:
        if not keep:
            raise
        return True
    return False


def _finish_trace(trace, model, bus, end_cycle, samples, interrupted):
    """``trace.finish``; after Ctrl-C a window the run never reached is no error (no file)."""
    try:
        trace.finish(model, bus, end_cycle, samples)
    except ValueError:
        if not interrupted:
            raise


def sample_read_cycles(result, setup):
    """Median cycles the bus spends reading one sample: the SPI burst from INT_STATUS (CS fall
    to CS rise), or on I2C the MPU9250 read's START to the AK8963 read's STOP."""
    import statistics
    from ..hdl.contract import mpu9250_regs as R
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

    def latencies_us(self, clk_freq):
        """Data-ready edge (INT at the pin) to the result leaving the engine, per result."""
        return [(r - i) / clk_freq * 1e6 for r, i in zip(self.result_cycles, self.int_cycles)]


def core_harness(setup, *, baud=DEFAULT_BAUD, core_kwargs=None):
    """The ``AHRSCore`` that ``run_core`` simulates (``setup``'s clock, configuration and
    timing), in its co-simulation harness, and the cache key of its compiled build:
    ``(core, harness, key)``."""
    from ..hdl.board.top import AHRSCore
    from .compiled_board import core_key
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


def run_core(setup=None, *, n_results=None, n_frames=None, model=None, max_cycles=None,
             baud=DEFAULT_BAUD, core_kwargs=None, writes=(), vcd=None, progress=None,
             compiled=None, until=None, keep_on_interrupt=False):
    """The whole ``AHRSCore`` (driver, engine, telemetry) against the models until the engine
    has produced ``n_results`` results and the UART has carried ``n_frames`` frames (either
    may be None). The wiring follows ``setup.config.wiring`` (I2C: the models on an
    ``I2CBusModel``, ``CoreRun.bus``). Each result is recorded as it leaves the engine (the
    telemetry scheduler takes every one) with the cycle of the INT edge that announced its
    sample, so ``CoreRun.latencies_us`` is the data-ready-to-attitude latency. ``writes``:
    (address, value) register writes through the ``cfg`` port at the start. ``progress``: a bar told
    of each result and the cycle reached (``run_frontend``). ``compiled``: as
    ``run_frontend``'s (``CoreRun.compiled`` says which path ran). ``until()``: asked at each
    result and data-ready edge; True ends the run (instead of, or before, the counts).
    ``keep_on_interrupt``: as ``run_frontend``'s (``CoreRun.interrupted``)."""
    from .streams import stream_put
    from ..host.protocol import FrameDecoder
    from .uart import attach_uart_receiver
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
    compiled = compiled_wanted(compiled, vcd=vcd)
    trace = vcd and RunTrace(vcd, setup.clk_freq, "core", setup.config.wiring,
                             status_fields(core.status))
    from .compiled_board import core_design
    design = _auto_build(compiled, max_cycles, lambda cached_only: core_design(
        harness, core, cached_only=cached_only, trace=trace and trace.wave.format, key=key))
    compiled = design is not None
    if compiled and trace:
        trace.start_compiled(design)
    received = bytearray()
    if not compiled:
        sim = Simulator(harness)
        sim.add_clock(1 / setup.clk_freq)
        attach_models(sim, harness, setup.clk_freq, mpu=model, bus=bus)
        attach_uart_receiver(sim, core.uart_tx, core.uart.divisor, received)
    out = {"results": [], "cycles": [], "ints": [], "frames": [], "end": None, "samples": []}
    results = core.engine.results
    offered = core.engine.samples
    decoder = FrameDecoder()

    def more_wanted():
        out["frames"] += [f for _, _, f in decoder.feed(received)]
        received.clear()
        if until is not None:
            if until():
                return False
            if n_results is None and n_frames is None:
                return True                 # no count: until() alone ends the run
        return (len(out["results"]) < (n_results or 0) or
                len(out["frames"]) < (n_frames or 0))

    async def testbench(ctx):
        for addr, value in writes:
            await stream_put(ctx, core.cfg, {"addr": addr, "data": value})
        last_int = None
        level = 0
        s_prev = 0
        period = 1 / setup.clk_freq
        while more_wanted():
            cycle = ctx.get(harness.cycle)
            if cycle >= max_cycles:
                raise TimeoutError(f"{len(out['results'])} results, {len(out['frames'])} "
                                   f"frames after {cycle} cycles; status "
                                   f"{to_python(ctx.get(core.status))}")
            if progress is not None:
                progress.set_postfix_str(f"cycle {cycle:,}", refresh=False)
                progress.update(0)
            pin = ctx.get(core.imu_int)
            if pin and not level:
                last_int = cycle
            level = pin
            s_valid = ctx.get(offered.valid)
            if s_valid and not s_prev:
                # a sample offered to the engine: it holds until taken
                out["samples"].append(to_python(ctx.get(offered.payload)))
                if trace:
                    trace.at_sample(len(out["samples"]), cycle)
            s_prev = s_valid
            if ctx.get(results.valid):
                # the result as it leaves the engine; recorded once, when it is taken
                payload, first_cycle = to_python(ctx.get(results.payload)), cycle
                while not ctx.get(results.ready):
                    await ctx.tick()
                out["results"].append(payload)
                out["cycles"].append(first_cycle)
                out["ints"].append(last_int)
                if progress is not None:
                    progress.update(1)
                await ctx.tick()
                continue
            await ctx.changed(results.valid, core.imu_int, offered.valid).delay(
                (max_cycles - cycle) * period)
        out["end"] = (ctx.get(harness.cycle), to_python(ctx.get(core.counters)),
                      to_python(ctx.get(core.status)), to_python(ctx.get(core.asa)))
        harness.check(ctx)
    if not compiled:
        sim.add_testbench(testbench)
    start = time.perf_counter()
    if compiled:
        from ..host.protocol import unpack
        from .compiled_board import check_monitors, core_loop

        def record(bits, cycle, int_cycle):
            out["results"].append(unpack(results.payload.shape(), bits))
            out["cycles"].append(cycle)
            out["ints"].append(int_cycle)

        def offered_sample(bits):
            out["samples"].append(unpack(offered.payload.shape(), bits))
            if trace:
                trace.at_sample(len(out["samples"]), design.cycle)
        ended = []                          # the loop's last cycle, unless interrupted
        out["interrupted"] = _run_interruptible(lambda: ended.append(core_loop(
            design, core, PinModels(setup.clk_freq, mpu=model, bus=bus),
            divisor=core.uart.divisor, received=received, record=record,
            more_wanted=more_wanted, max_cycles=max_cycles, writes=writes, progress=progress,
            offered=offered_sample)), keep_on_interrupt)
        end = ended[0] if ended else design.cycle
        out["end"] = (end, *(unpack(v.shape(), design.get(name)) for name, v in
                             (("counters", core.counters), ("status", core.status),
                              ("asa", core.asa))))
        if not out.get("interrupted"):
            check_monitors(design, harness)
        if trace:
            design.close()                  # the waveform complete
    elif trace:
        with trace.python_writer(sim):
            out["interrupted"] = _run_interruptible(sim.run, keep_on_interrupt)
    else:
        out["interrupted"] = _run_interruptible(sim.run, keep_on_interrupt)
    if out["end"] is None:              # Ctrl-C in Amaranth's simulator: its last result
        out["end"] = (max(out["cycles"], default=0), {}, {}, [])
    if trace:
        _finish_trace(trace, model, bus, out["end"][0], len(out["samples"]),
                      out.get("interrupted"))
    wall = time.perf_counter() - start
    more_wanted()                       # the bytes that came after the last look
    cycles, counters, status, asa = out["end"]
    return CoreRun(out["results"], out["cycles"], out["ints"], out["frames"], counters, status,
                   cycles, wall, model, asa, core, compiled, out["samples"], bus,
                   bool(out.get("interrupted")))
