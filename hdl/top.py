"""Top levels.

``AHRSCore`` is everything that is not a pin buffer: the sensor front end, the attitude engine
(calibration and filters, ``attitude=True``), and the telemetry framer with its UART. It is what
``build --verilog-only`` exports and what simulations of the whole design drive. Ports:
``imu`` (SPI pins, or I2C pins with ``config.wiring == "i2c"``), ``imu_int``, ``uart_tx``,
``status``, ``asa``, ``samples_seen`` (counts samples, for a heartbeat LED), and with the
engine ``cfg`` (register writes to the engine; tie ``valid`` low to keep the reset values)
and ``cfg_read`` / ``cfg_read_data`` (read-back).

Telemetry: with the engine, one ``AttitudeFrame`` (type 0x02: the result, the raw sample it
came from and the driver status) per sample; without it, one ``SensorFrame`` (0x01). The
engine's filters are set up for the sensor configuration: T = 1/ODR, gyro LSB per °/s from
the full scale, the published Q, R, P₀.

On an I2C-wired board the MPU9250's SCL/SDA are the pins SCLK/SDI use with SPI; ``BoardTop``
then holds NCS high (I2C mode) and drives AD0 (SDO) to select 0x68 or 0x69.

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
from amaranth.lib import data, io, stream, wiring
from amaranth.lib.wiring import In, Out, connect, flipped

from .mpu9250_driver import DriverTiming, MPU9250Config
from .attitude_isa import REG_BITS
from .attitude_engine import AttitudeEngine, default_filter_config, default_flagship_config
from .sample import ConfigWrite, DriverStatus, Sample
from .sensor_frontend import SensorFrontEnd
from .i2c_controller import I2CPinsSignature
from .spi_controller import SPIPinsSignature
from .telemetry import AttitudeFrame, TelemetryFramer
from .uart_tx import UARTTransmitter


__all__ = ["AHRSCore", "BoardTop"]


class AHRSCore(wiring.Component):
    def __init__(self, *, clk_freq, config=MPU9250Config(), timing=DriverTiming(),
                 baud=921_600, attitude=True, filter_config=None, calibration=None,
                 flagship_config=None, filter="flagship", blackbox_hard_blocks=False):
        self.clk_freq = clk_freq
        self.config = config
        self.attitude = attitude
        self.frontend = SensorFrontEnd(clk_freq=clk_freq, config=config, timing=timing)
        if attitude:
            if filter_config is None:
                filter_config = default_filter_config(config)
            if flagship_config is None:
                flagship_config = default_flagship_config(config)
            self.engine = AttitudeEngine(filter_config, calibration, flagship_config,
                                         filter=filter,
                                         blackbox_hard_blocks=blackbox_hard_blocks)
            self.framer = TelemetryFramer(AttitudeFrame, 0x02)
        else:
            self.framer = TelemetryFramer()
        self.uart = UARTTransmitter.for_baud(clk_freq, baud)
        ports = {
            "imu": Out(SPIPinsSignature() if config.wiring == "spi" else I2CPinsSignature()),
            "imu_int": In(1),
            "uart_tx": Out(1, init=1),
            "status": Out(DriverStatus),
            "asa": Out(data.ArrayLayout(8, 3)),
            "samples_seen": Out(8),
        }
        if attitude:
            ports["cfg"] = In(stream.Signature(ConfigWrite))
            ports["cfg_read"] = In(stream.Signature(REG_BITS))
            ports["cfg_read_data"] = Out(stream.Signature(signed(32)))
        super().__init__(ports)

    def elaborate(self, platform):
        m = Module()
        m.submodules.frontend = fe = self.frontend
        m.submodules.framer = framer = self.framer
        m.submodules.uart = uart = self.uart

        connect(m, fe.pins, flipped(self.imu))
        m.d.comb += [fe.int_pin.eq(self.imu_int), self.status.eq(fe.status),
                     self.asa.eq(fe.asa), self.uart_tx.eq(uart.tx)]

        if self.attitude:
            # Sample -> engine -> frame (result + the sample it came from + status) -> UART.
            # The engine takes the next sample only once its result is framed, so one held
            # copy of the sample is enough.
            m.submodules.engine = engine = self.engine
            connect(m, fe.samples, engine.samples)
            connect(m, flipped(self.cfg), engine.cfg)
            connect(m, flipped(self.cfg_read), engine.cfg_read)
            connect(m, engine.cfg_read_data, flipped(self.cfg_read_data))
            held = Signal(Sample, reset_less=True)
            with m.If(fe.samples.valid & fe.samples.ready):
                m.d.sync += held.eq(fe.samples.payload)
            m.d.comb += [
                engine.asa.eq(fe.asa),
                framer.i_stream.valid.eq(engine.results.valid),
                framer.i_stream.payload.attitude.eq(engine.results.payload),
                framer.i_stream.payload.sample.eq(held),
                framer.i_stream.payload.status.eq(fe.status),
                engine.results.ready.eq(framer.i_stream.ready),
            ]
        else:
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
        config = core.config
        uart = platform.request("uart", 0, dir="-")
        m.submodules.uart_tx = uart_tx = io.Buffer("o", uart.tx)
        m.d.comb += uart_tx.o.eq(core.uart_tx)

        if config.wiring == "spi":
            imu = platform.request("imu_spi", 0, dir="-")
            buffers = {"imu_cs": io.Buffer("o", imu.cs), "imu_sclk": io.Buffer("o", imu.clk),
                       "imu_copi": io.Buffer("o", imu.copi),
                       "imu_cipo": io.Buffer("i", imu.cipo), "imu_int": io.Buffer("i", imu.int)}
            # The resource declares CS as PinsN, so the buffer's "o" is chip-select-active.
            m.d.comb += [
                buffers["imu_cs"].o.eq(~core.imu.cs_n),
                buffers["imu_sclk"].o.eq(core.imu.sclk),
                buffers["imu_copi"].o.eq(core.imu.copi),
                core.imu.cipo.eq(buffers["imu_cipo"].i),  # synchronised in the SPI controller
            ]
        else:
            imu = platform.request("imu_i2c", 0, dir="-")
            buffers = {"imu_scl": io.Buffer("io", imu.scl), "imu_sda": io.Buffer("io", imu.sda),
                       "imu_ncs": io.Buffer("o", imu.ncs), "imu_ad0": io.Buffer("o", imu.ad0),
                       "imu_int": io.Buffer("i", imu.int)}
            # Open drain: the output is always 0, enabled to pull the line low.
            m.d.comb += [
                buffers["imu_scl"].o.eq(0), buffers["imu_scl"].oe.eq(core.imu.scl_oe),
                buffers["imu_sda"].o.eq(0), buffers["imu_sda"].oe.eq(core.imu.sda_oe),
                core.imu.scl_i.eq(buffers["imu_scl"].i),  # synchronised in the I2C controller
                core.imu.sda_i.eq(buffers["imu_sda"].i),
                buffers["imu_ncs"].o.eq(1),               # NCS high: the MPU9250 stays on I2C
                buffers["imu_ad0"].o.eq(config.i2c_address & 1),
            ]
        for name, buf in buffers.items():
            m.submodules[name] = buf
        m.d.comb += core.imu_int.eq(buffers["imu_int"].i)   # synchronised in the driver

        status = core.status
        leds = [status.streaming, status.whoami_error, status.no_response, status.int_timeout,
                core.samples_seen[7], *status.retries[:3]]
        for i, value in enumerate(leds):
            led = io.Buffer("o", platform.request("led", i, dir="-"))
            m.submodules[f"led{i}"] = led
            m.d.comb += led.o.eq(value)
        return m
