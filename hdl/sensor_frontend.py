"""Sensor front end: the MPU9250 driver wired to its SPI controller.

Interface
    ``pins`` (``SPIPinsSignature``): SCLK, COPI, CS_n out; CIPO in (raw).
    ``int_pin`` (in): sensor INT, raw.
    ``samples`` (out, ``Sample`` stream) and ``status`` (out, ``DriverStatus``): from the driver.

This is the unit the simulations drive and the one ``build --verilog-only`` exports; the board
top level adds I/O buffers around it.
"""

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out, connect, flipped

from .mpu9250_driver import DriverTiming, MPU9250Config, MPU9250Driver
from .sample import DriverStatus, Sample
from .register_port import SPIRegisterPort
from .spi_controller import SPIController, SPIPinsSignature, SPITiming


__all__ = ["SensorFrontEnd"]


class SensorFrontEnd(wiring.Component):
    def __init__(self, *, clk_freq, config=MPU9250Config(), timing=DriverTiming(),
                 spi_timing=None):
        self.clk_freq = clk_freq
        self.spi_timing = spi_timing or SPITiming.for_clock(clk_freq)
        self.driver = MPU9250Driver(clk_freq=clk_freq, config=config, timing=timing)
        self.spi = SPIController(self.spi_timing)
        self.port = SPIRegisterPort()
        super().__init__({
            "pins": Out(SPIPinsSignature()),
            "int_pin": In(1),
            "samples": Out(stream.Signature(Sample)),
            "status": Out(DriverStatus),
            "asa": Out(data.ArrayLayout(8, 3)),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.driver = driver = self.driver
        m.submodules.spi = spi = self.spi
        m.submodules.port = port = self.port
        connect(m, driver.port, port.port)
        connect(m, port.spi_o, spi.i_stream)
        connect(m, spi.o_stream, port.spi_i)
        connect(m, spi.pins, flipped(self.pins))
        connect(m, driver.samples, flipped(self.samples))
        m.d.comb += [driver.int_pin.eq(self.int_pin), self.status.eq(driver.status),
                     self.asa.eq(driver.asa)]
        return m
