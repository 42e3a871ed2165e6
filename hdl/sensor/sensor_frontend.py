"""Sensor front end: the MPU9250 driver, its register port and bus controller."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import Out, connect, flipped

from .mpu9250_driver import DriverTiming, MPU9250Config, MPU9250Driver, driver_members
from .i2c_controller import I2CController, I2CPinsSignature, I2CTiming
from .register_port import I2CRegisterPort, SPIRegisterPort
from .sample_reader import MPU_BYTES, SAMPLE_BYTES
from .spi_controller import SPIController, SPIPinsSignature, SPITiming


__all__ = ["SensorFrontEnd", "sample_read_cycles", "spi_timing_for"]


def spi_timing_for(clk_freq, levelling=True):
    """The SPI controller's timing at ``clk_freq``: ``SPITiming.for_clock``, with the trained
    rate (``SPITiming.with_trained``: read levelling, issue #58) where it is faster than the
    safe fast rate and ``levelling``."""
    safe = SPITiming.for_clock(clk_freq)
    trained = safe.with_trained(clk_freq)
    if levelling and trained.trained_period() < safe.period(fast=True):
        return trained
    return safe


def sample_read_cycles(config, clk_freq, bus_timing=None):
    """An upper bound of the cycles from a data-ready edge to the sample leaving the driver:
    the synchroniser and the driver's hand-offs, plus the bus: one fast SPI burst of
    ``SAMPLE_BYTES`` + 1 bytes (each 8 SCLK periods without a pause, the driver taking every
    byte at once; the last byte's capture delay and hand-off; CS setup, hold and gap), or on I2C the
    MPU9250 read and the AK8963 read (9 SCL periods a byte plus START, repeated START, STOP).
    ``simulate``'s measured ``sample_read_us`` stays below it (a test checks)."""
    overhead = 16
    if config.wiring == "spi":
        t = bus_timing or SPITiming.for_clock(clk_freq)
        burst = (SAMPLE_BYTES + 1) * 8 * t.period(fast=True) + t.capture_delay + 3
        return overhead + burst + t.fast_half + t.cs_hold + t.cs_gap
    t = bus_timing or I2CTiming.for_clock(clk_freq)
    period = t.low + t.high
    def read(n):       # START, address+W, register, repeated START, address+R, n bytes, STOP
        return (3 + 9 * (3 + n)) * period
    return overhead + read(MPU_BYTES) + (read(8) if config.magnetometer else 0)


class SensorFrontEnd(wiring.Component):
    """Sensor front end: the MPU9250 driver, its register port and bus controller.

    ``config.wiring`` picks the bus: "spi" (``SPIRegisterPort`` + ``SPIController``, the AK8963
    through the MPU9250's I2C master; its timing ``spi_timing``, by default ``spi_timing_for``:
    with a trained rate where the clock makes one faster, and then the driver's read
    levelling) or "i2c" (``I2CRegisterPort`` + ``I2CController``, the AK8963
    through the bypass multiplexer).

    Interface
        ``pins``: ``SPIPinsSignature`` (SCLK, COPI, CS_n out; CIPO in, raw) or ``I2CPinsSignature``
            (SCL/SDA pull-down enables out; line levels in, raw).
        ``int_pin`` (in): sensor INT, raw.
        ``samples`` (out, ``Sample`` stream) and ``status`` (out, ``DriverStatus``): from the
            driver; with I2C wiring ``status.bus_*`` come from the I2C controller.
        ``store``, ``sample_slot`` (out): the sample store's writes and the offered sample's
            slot (``hdl/sensor/sample_store.py``), from the driver; ``imu_ready`` (out): the
            early start's (``SampleReader``: the next sample's gyro and accelerometer are in
            its slot, its field still coming); ``tick`` (out): the sample
            reader's free-running tick (``data_ready_timer.tick_cycles``), which the core's
            command decoder counts its time-out in.

    This is the unit the simulations drive and the one ``build --verilog-only`` exports; the board
    top level adds I/O buffers around it.
    Latency: a sample leaves at most ``sample_read_cycles(config, clk_freq)`` cycles after its
    data-ready edge (the bus read dominates). Throughput: one sample per data-ready edge.
    """
    def __init__(self, *, clk_freq, config=MPU9250Config(), timing=DriverTiming(),
                 spi_timing=None, i2c_timing=None):
        self.clk_freq = clk_freq
        self.config = config
        if config.wiring == "spi":
            self.bus_timing = spi_timing or spi_timing_for(clk_freq)
            self.bus = SPIController(self.bus_timing)
            self.port = SPIRegisterPort()
            pins = SPIPinsSignature()
        else:
            self.bus_timing = i2c_timing or I2CTiming.for_clock(clk_freq)
            self.bus = I2CController(self.bus_timing)
            self.port = I2CRegisterPort(mpu_address=config.i2c_address)
            pins = I2CPinsSignature()
        levelled = config.wiring == "spi" and self.bus_timing.has_trained
        self.driver = MPU9250Driver(
            clk_freq=clk_freq, config=config, timing=timing,
            max_sample_delay=self.bus_timing.max_sample_delay if levelled else None)
        super().__init__({"pins": Out(pins), **driver_members()})

    def elaborate(self, platform):
        m = Module()
        m.submodules.driver = driver = self.driver
        m.submodules.bus = bus = self.bus
        m.submodules.port = port = self.port
        connect(m, driver.port, port.port)
        if self.config.wiring == "spi":
            if self.bus_timing.has_trained:
                m.d.comb += bus.sample_delay.eq(driver.sample_delay)
            connect(m, port.spi_o, bus.i_stream)
            connect(m, bus.o_stream, port.spi_i)
        else:
            connect(m, port.i2c_o, bus.i_stream)
            connect(m, bus.o_stream, port.i2c_i)
        connect(m, bus.pins, flipped(self.pins))
        connect(m, driver.samples, flipped(self.samples))
        connect(m, driver.store, flipped(self.store))
        m.d.comb += [driver.int_pin.eq(self.int_pin), self.status.eq(driver.status),
                     self.asa.eq(driver.asa), self.early_sample.eq(driver.early_sample),
                     self.who_am_i.eq(driver.who_am_i), self.self_test.eq(driver.self_test),
                     self.sample_slot.eq(driver.sample_slot), self.tick.eq(driver.tick),
                     self.imu_ready.eq(driver.imu_ready),
                     self.level.eq(driver.level)]
        if self.config.wiring == "i2c":
            # the controller's own view of a failure, which the driver sees only as an error
            m.d.comb += [self.status.bus_timeout.eq(bus.status.timeout),
                         self.status.bus_stuck.eq(bus.status.bus_stuck),
                         self.status.bus_arbitration.eq(bus.status.arbitration)]
        return m
