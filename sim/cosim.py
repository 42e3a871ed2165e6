"""Co-simulation: the gateware in Amaranth's simulator talking to the Python sensor models.

``attach_mpu9250`` adds a simulator process that plays an ``MPU9250Model`` on the SPI pins: each
system clock it samples CS_n, SCLK and COPI as flip-flops would, hands edges to the model with
time stamps ``cycle / clk_freq``, and drives CIPO and INT from the model. The model therefore
answers one clock after it sees an edge, like a real part with its output delay.

``run_frontend`` brings a ``SensorFrontEnd`` up against a model and collects samples; it is what
the tests and ``python -m mpu9250_ahrs simulate`` use.
"""

import math
import time
from dataclasses import dataclass, field
from typing import List, Optional

from amaranth import Elaboratable, Module, Signal
from amaranth.sim import Simulator

from ..hdl.mpu9250_driver import DriverTiming, MPU9250Config
from ..hdl.sensor_frontend import SensorFrontEnd
from .mpu9250_model import MPU9250Model, MPU9250Timing
from ..hdl import ak8963_regs as A
from .ak8963_model import AK8963Model, AK8963Timing
from .sources import counting_field, counting_source
from .telemetry import to_python


__all__ = ["CosimHarness", "attach_mpu9250", "attach_stuck_miso", "SimSetup", "CosimResult", "run_frontend",
           "sample_matches", "expected_mag"]


class CosimHarness(Elaboratable):
    """Wraps a design for co-simulation with simulation-only helpers.

    ``cycle`` counts clock edges: the time base of the models. A model process drives
    ``cipo_model`` and ``int_model``; each reaches the design one clock later (the device's
    output delay), so the process can run right after the edge it reacts to. ``wake_at`` is the
    cycle at which the model next wants to run with no pin change; ``wake`` is high in it.
    """
    def __init__(self, dut, pins, int_pin):
        self.dut, self.pins, self.int_pin = dut, pins, int_pin
        self.cycle = Signal(40)
        self.wake_at = Signal(40, init=(1 << 40) - 1)
        self.wake = Signal()
        self.cipo_model = Signal()
        self.int_model = Signal()

    def elaborate(self, platform):
        m = Module()
        m.submodules.dut = self.dut
        m.d.sync += [self.cycle.eq(self.cycle + 1), self.pins.cipo.eq(self.cipo_model),
                     self.int_pin.eq(self.int_model)]
        m.d.comb += self.wake.eq(self.cycle == self.wake_at)
        return m


def attach_mpu9250(sim, model, harness, clk_freq):
    """Play ``model`` on the harness's SPI pins; wakes only on pin changes and model events."""
    pins = harness.pins
    never = (1 << 40) - 1

    async def process(ctx):
        cs_prev, sclk_prev = 1, 1
        miso_prev = int_prev = None
        wake_prev = never
        async for cs_n, sclk, _wake, copi, cycle in ctx.changed(pins.cs_n, pins.sclk, harness.wake) \
                .sample(pins.copi, harness.cycle):
            t = cycle / clk_freq
            if cs_n != cs_prev and not cs_n:
                model.cs_edge(t, cs_n)
            if sclk != sclk_prev:
                model.sclk_edge(t, sclk, copi)
            if cs_n != cs_prev and cs_n:
                model.cs_edge(t, cs_n)
            cs_prev, sclk_prev = cs_n, sclk
            model.advance(t)
            if model.miso != miso_prev:
                miso_prev = model.miso
                ctx.set(harness.cipo_model, miso_prev)
            level = model.int_level
            if level != int_prev:
                int_prev = level
                ctx.set(harness.int_model, level)
            event = model.next_event
            wake = never if event is None else max(cycle + 1, math.ceil(event * clk_freq - 1e-6))
            if wake != wake_prev:
                wake_prev = wake
                ctx.set(harness.wake_at, wake)
    sim.add_process(process)


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
    interrupt timeout follows).
    """
    clk_freq: float = 12e6
    config: MPU9250Config = field(default_factory=MPU9250Config)
    delay_scale: float = 1e-3
    odr_scale: float = 0.2

    @property
    def sample_period_s(self):
        return self.odr_scale / self.config.output_data_rate

    def driver_timing(self):
        return DriverTiming(time_scale=self.delay_scale,
                            int_timeout_s=4 * self.sample_period_s + 0.05 * self.delay_scale)

    def model_timing(self):
        return MPU9250Timing().scaled(delays=self.delay_scale, odr=self.odr_scale)

    def frontend(self, **kwargs):
        return SensorFrontEnd(clk_freq=self.clk_freq, config=self.config,
                              timing=self.driver_timing(), **kwargs)

    def ak8963(self, **kwargs):
        kwargs.setdefault("source", counting_field())
        return AK8963Model(timing=AK8963Timing().scaled(odr=self.odr_scale), **kwargs)

    def model(self, *, magnetometer=True, **kwargs):
        """An MPU9250 model (counting sensor values) with an AK8963 on its auxiliary bus
        (``model.aux_devices[0x0C]``) unless ``magnetometer`` is False."""
        kwargs.setdefault("source", counting_source())
        if magnetometer:
            kwargs.setdefault("aux_devices", {A.I2C_ADDRESS: self.ak8963()})
        return MPU9250Model(timing=self.model_timing(), **kwargs)


@dataclass
class CosimResult:
    samples: List[dict]
    status: dict
    cycles: int
    bring_up_cycles: Optional[int]
    wall_s: float
    model: Optional[MPU9250Model]
    status_log: List[tuple] = field(default_factory=list)   # (cycle, status dict) on change
    asa: List[int] = field(default_factory=list)            # the driver's asa port at the end

    @property
    def cycles_per_s(self):
        return self.cycles / self.wall_s if self.wall_s else float("inf")


def sample_matches(design_sample, model_sample):
    """True if a sample out of the gateware carries exactly the model's accel/temp/gyro."""
    return (tuple(design_sample["accel"]) == model_sample.accel and
            design_sample["temp"] == model_sample.temp and
            tuple(design_sample["gyro"]) == model_sample.gyro)


def expected_mag(ak_bytes, mag_ok=True):
    """Magnetometer fields and flags a sample must carry, from the AK8963 bytes ST1..ST2 the
    sensor read returned (independent of the gateware's own parsing)."""
    if not mag_ok:
        return [0, 0, 0], {"mag_valid": 0, "mag_overflow": 0, "mag_new": 0, "mag_dor": 0}
    st1, st2 = ak_bytes[0], ak_bytes[7]
    mag = [int.from_bytes(ak_bytes[1 + 2 * i:3 + 2 * i], "little", signed=True)
           for i in range(3)]
    new, hofl = st1 & A.ST1_DRDY, bool(st2 & A.ST2_HOFL)
    return mag, {"mag_valid": int(bool(new) and not hofl), "mag_overflow": int(hofl),
                 "mag_new": int(bool(new)), "mag_dor": int(bool(st1 & A.ST1_DOR))}


def run_frontend(setup=None, *, n_samples=0, model=None, stuck_miso=None, max_cycles=None,
                 until=None, vcd=None, ready=None):
    """Simulate until ``n_samples`` samples came out, ``until(status_dict)`` is true, or
    ``max_cycles`` (an error unless ``until`` was given and is merely never met).

    ``ready(cycle)`` gives the consumer's ready per cycle (default: always ready).
    ``vcd``: path of a VCD file to write; a GTKWave save file is written beside it.
    """
    setup = setup or SimSetup()
    dut = setup.frontend()
    if model is None and stuck_miso is None:
        model = setup.model()
    if max_cycles is None:
        period = setup.sample_period_s * setup.clk_freq
        # Three bring-up attempts' waits, plus the magnetometer's SLV4 transfers (each waits
        # for a sample tick of the MPU9250's I2C master).
        bring_up = 3 * (dut.driver.power_up_cycles + dut.driver.reset_cycles) + \
            40 * period + 20_000
        max_cycles = int(bring_up + (n_samples + 3) * period * 1.5)

    harness = CosimHarness(dut, dut.pins, dut.int_pin)
    sim = Simulator(harness)
    sim.add_clock(1 / setup.clk_freq)
    if model is not None:
        attach_mpu9250(sim, model, harness, setup.clk_freq)
    else:
        attach_stuck_miso(sim, harness, stuck_miso)

    out = {"samples": [], "status": None, "cycles": 0, "bring_up": None, "log": [], "asa": []}

    class Done(Exception):
        pass

    last = {"status": None}

    def observe(cycle, taken, payload, status):
        st = to_python(status)
        if st != last["status"]:
            out["log"].append((cycle, st))
            last["status"] = st
        if st["streaming"] and out["bring_up"] is None:
            out["bring_up"] = cycle
        if taken:
            out["samples"].append(to_python(payload))
        done = (n_samples and len(out["samples"]) >= n_samples) or (until and until(st))
        if done or cycle >= max_cycles:
            out["status"], out["cycles"] = st, cycle
            if not done and until is None:
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
    sim.add_testbench(testbench)

    start = time.perf_counter()
    if vcd:
        gtkw = str(vcd).rsplit(".", 1)[0] + ".gtkw"
        traces = [dut.pins.cs_n, dut.pins.sclk, dut.pins.copi, dut.pins.cipo, dut.int_pin,
                  dut.samples.valid, dut.status]
        with sim.write_vcd(str(vcd), gtkw, traces=traces):
            sim.run()
    else:
        sim.run()
    wall = time.perf_counter() - start
    return CosimResult(out["samples"], out["status"], out["cycles"], out["bring_up"], wall,
                       model, out["log"], out["asa"])
