"""Top levels.

``AHRSCore`` is everything that is not a pin buffer: the sensor front end and the telemetry
framer with its UART. It is what ``build --verilog-only`` exports and what simulations of the
whole design drive. Ports: ``imu`` (SPI pins), ``imu_int``, ``uart_tx``, ``status``,
``samples_seen`` (toggles every sample, for a heartbeat LED).

``BoardTop`` puts ``lib.io`` buffers between ``AHRSCore`` and a ``MAX10Platform``'s pins and
shows the driver status on the LEDs:

====  ==================================================
LED   meaning
====  ==================================================
0     streaming (bring-up done, samples flowing)
1     WHO_AM_I wrong
2     no response (WHO_AM_I read 0x00 or 0xFF)
3     data-ready interrupt timed out
4     heartbeat: toggles every 256 samples
5-7   bring-up retries (low three bits)
====  ==================================================
"""

from amaranth import *
from amaranth.lib import io, wiring
from amaranth.lib.wiring import In, Out, connect, flipped

from .mpu9250_driver import DriverTiming, MPU9250Config
from .sample import DriverStatus
from .sensor_frontend import SensorFrontEnd
from .spi_controller import SPIPinsSignature
from .telemetry import TelemetryFramer
from .uart_tx import UARTTransmitter


__all__ = ["AHRSCore", "BoardTop"]


class AHRSCore(wiring.Component):
    def __init__(self, *, clk_freq, config=MPU9250Config(), timing=DriverTiming(),
                 baud=921_600):
        self.clk_freq = clk_freq
        self.frontend = SensorFrontEnd(clk_freq=clk_freq, config=config, timing=timing)
        self.framer = TelemetryFramer()
        self.uart = UARTTransmitter.for_baud(clk_freq, baud)
        super().__init__({
            "imu": Out(SPIPinsSignature()),
            "imu_int": In(1),
            "uart_tx": Out(1, init=1),
            "status": Out(DriverStatus),
            "samples_seen": Out(8),
        })

    def elaborate(self, platform):
        m = Module()
        m.submodules.frontend = fe = self.frontend
        m.submodules.framer = framer = self.framer
        m.submodules.uart = uart = self.uart

        connect(m, fe.pins, flipped(self.imu))
        m.d.comb += [fe.int_pin.eq(self.imu_int), self.status.eq(fe.status),
                     self.uart_tx.eq(uart.tx)]

        # Sample stream -> frame (sample + status at the moment it was taken) -> UART.
        m.d.comb += [
            framer.i_stream.valid.eq(fe.samples.valid),
            framer.i_stream.payload.sample.eq(fe.samples.payload),
            framer.i_stream.payload.status.eq(fe.status),
            fe.samples.ready.eq(framer.i_stream.ready),
        ]
        connect(m, framer.o_stream, uart.i_stream)
        with m.If(fe.samples.valid & fe.samples.ready):
            m.d.sync += self.samples_seen.eq(self.samples_seen + 1)
        return m


class BoardTop(Elaboratable):
    def __init__(self, **core_kwargs):
        self.core_kwargs = core_kwargs

    def elaborate(self, platform):
        m = Module()
        m.submodules.core = core = AHRSCore(clk_freq=platform.default_clk_frequency,
                                            **self.core_kwargs)

        imu = platform.request("imu_spi", 0, dir="-")
        uart = platform.request("uart", 0, dir="-")
        buffers = {
            "imu_cs": io.Buffer("o", imu.cs), "imu_sclk": io.Buffer("o", imu.clk),
            "imu_copi": io.Buffer("o", imu.copi), "imu_cipo": io.Buffer("i", imu.cipo),
            "imu_int": io.Buffer("i", imu.int), "uart_tx": io.Buffer("o", uart.tx),
        }
        for name, buf in buffers.items():
            m.submodules[name] = buf
        # The resource declares CS as PinsN, so the buffer's "o" is chip-select-active.
        m.d.comb += [
            buffers["imu_cs"].o.eq(~core.imu.cs_n),
            buffers["imu_sclk"].o.eq(core.imu.sclk),
            buffers["imu_copi"].o.eq(core.imu.copi),
            core.imu.cipo.eq(buffers["imu_cipo"].i),     # synchronised inside the SPI controller
            core.imu_int.eq(buffers["imu_int"].i),       # synchronised inside the driver
            buffers["uart_tx"].o.eq(core.uart_tx),
        ]

        status = core.status
        leds = [status.streaming, status.whoami_error, status.no_response, status.int_timeout,
                core.samples_seen[7], *status.retries[:3]]
        for i, value in enumerate(leds):
            led = io.Buffer("o", platform.request("led", i, dir="-"))
            m.submodules[f"led{i}"] = led
            m.d.comb += led.o.eq(value)
        return m
