"""The co-simulation harness: a design wrapped with what the sensor models need, and the
models played on its pins.

``CosimHarness`` counts cycles and wires the models' levels onto the design's SPI pins or I2C
lines and INT; ``PinModels`` is what the models do at one wake-up, shared by both simulators
(``sim.bench.python_bench`` through ``attach_models``, ``sim.bench.compiled_bench``), so both
play them alike.
"""

import math

from amaranth import Signal

from .compiled_design import NEVER
from .streams import Monitored


__all__ = ["CosimHarness", "PinModels", "attach_models", "attach_mpu9250", "attach_stuck_miso"]


class CosimHarness(Monitored):
    """Wraps a design for co-simulation with simulation-only helpers.

    ``cycle`` counts clock edges: the time base of the models. The model process drives
    ``cipo_model`` (SPI) straight onto the design's CIPO pin, with the level SDO has at the next
    clock edge (the model delays each bit by its output delay and the board's,
    ``MPU9250Timing``, in simulated time); ``scl_model_low``/``sda_model_low`` (I2C) and ``int_model`` reach the
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
    (``attach_models``) and the compiled bench (``sim.bench.compiled_bench``), so both play the
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
