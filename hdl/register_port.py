"""Register ports: register reads and writes as commands, whatever the bus underneath.

The driver speaks only this interface, so one sequencer serves both wirings.

``RegisterPortSignature`` (seen from the port):
    ``cmd`` (in stream, ``RegisterCommand``): ``device`` (0 = MPU9250, 1 = AK8963 reached
        directly: I2C wiring only), ``reg``, ``write``, ``data`` (the byte to write), ``length``
        (bytes to read, 1..32), ``fast`` (SPI only: the fast clock, for sensor registers).
    ``rx`` (out stream, bytes): the bytes read, in order; the driver is always ready.
    ``rsp`` (out stream, ``RegisterResponse``): one per command, after its last ``rx`` byte;
        ``error`` = the device did not acknowledge (I2C NACK) or the bus failed.

``SPIRegisterPort`` turns commands into SPI transactions for an ``SPIController``:
header byte (bit 7 = read), then the data byte or ``length`` dummy bytes. Latency: the
transaction, plus one cycle.
"""

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from . import mpu9250_regs as R
from .spi_controller import SPIByte


__all__ = ["MAX_READ", "RegisterCommand", "RegisterResponse", "RegisterPortSignature",
           "SPIRegisterPort"]


MAX_READ = 32

RegisterCommand = data.StructLayout({
    "device": 1, "reg": 8, "write": 1, "data": 8, "length": range(MAX_READ + 1), "fast": 1,
})
RegisterResponse = data.StructLayout({"error": 1})


class RegisterPortSignature(wiring.Signature):
    def __init__(self):
        super().__init__({
            "cmd": In(stream.Signature(RegisterCommand)),
            "rx": Out(stream.Signature(8)),
            "rsp": Out(stream.Signature(RegisterResponse)),
        })


class SPIRegisterPort(wiring.Component):
    def __init__(self):
        super().__init__({
            "port": Out(RegisterPortSignature()),
            "spi_o": Out(stream.Signature(SPIByte)),
            "spi_i": In(stream.Signature(8)),
        })

    def elaborate(self, platform):
        m = Module()
        cmd = Signal(RegisterCommand)
        total = Signal(range(MAX_READ + 2))    # bytes in the transaction, header included
        tx_index = Signal.like(total)
        rx_index = Signal.like(total)
        busy = Signal()

        m.d.comb += self.port.cmd.ready.eq(~busy & ~self.port.rsp.valid)
        with m.If(self.port.cmd.valid & self.port.cmd.ready):
            p = self.port.cmd.payload
            m.d.sync += [cmd.eq(p), busy.eq(1), tx_index.eq(0), rx_index.eq(0),
                         total.eq(Mux(p.write, 2, p.length + 1))]

        m.d.comb += [
            self.spi_o.valid.eq(busy & (tx_index < total)),
            self.spi_o.payload.data.eq(Mux(tx_index == 0,
                                           Cat(cmd.reg[:7], ~cmd.write),   # bit 7: read
                                           Mux(cmd.write, cmd.data, 0))),
            self.spi_o.payload.fast.eq(cmd.fast & ~cmd.write),
            self.spi_o.payload.last.eq(tx_index == total - 1),
            self.spi_i.ready.eq(1),
            # Bytes clocked in during the header and during writes mean nothing.
            self.port.rx.valid.eq(self.spi_i.valid & (rx_index != 0) & ~cmd.write),
            self.port.rx.payload.eq(self.spi_i.payload),
        ]
        with m.If(self.spi_o.valid & self.spi_o.ready):
            m.d.sync += tx_index.eq(tx_index + 1)
        with m.If(self.spi_i.valid):
            m.d.sync += rx_index.eq(rx_index + 1)
            with m.If(rx_index == total - 1):
                m.d.sync += [busy.eq(0), self.port.rsp.valid.eq(1),
                             self.port.rsp.payload.error.eq(0)]
        with m.If(self.port.rsp.valid & self.port.rsp.ready):
            m.d.sync += self.port.rsp.valid.eq(0)
        return m
