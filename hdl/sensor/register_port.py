"""Register ports: register reads and writes as commands, whatever the bus underneath.

The driver speaks only this interface, so one sequencer serves both wirings.

``RegisterPortSignature`` (seen from the port):
    ``cmd`` (in stream, ``RegisterCommand``): ``device`` (0 = MPU9250, 1 = AK8963 reached
        directly: I2C wiring only), ``reg``, ``write``, ``data`` (the byte to write), ``length``
        (bytes to read, 1..32), ``fast`` (SPI only: the fast clock, for sensor registers),
        ``trained`` (SPI only, with ``fast``: the trained rate at the controller's sample
        delay, ``SPITiming.with_trained``; issue #58).
    ``rx`` (out stream, bytes): the bytes read, in order. The driver is always ready; a
        consumer that is not holds the bus controller back (its result waits), so no byte is
        lost.
    ``rsp`` (out stream, ``RegisterResponse``): one per command, after its last ``rx`` byte;
        ``error`` = the device did not acknowledge (I2C NACK) or the bus failed.

``SPIRegisterPort`` turns commands into SPI transactions for an ``SPIController``:
header byte (bit 7 = read), then the data byte or ``length`` dummy bytes. A result byte
counts only for a byte already sent. Latency: the transaction, plus one cycle.

``I2CRegisterPort`` turns them into I2C operations for an ``I2CController``:
write: START, address+W, register, data, STOP; read: START, address+W, register, repeated
START, address+R, ``length`` bytes (ACK on all but the last), STOP. A NACK or a controller error
ends the command with a STOP and ``error`` = 1. ``device`` 0 is the MPU9250 at ``mpu_address``
(0x68 or 0x69), 1 the AK8963 at 0x0C (reachable once the MPU9250's bypass is on).
"""

from contextlib import contextmanager

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from ..contract import ak8963_regs as A
from .i2c_controller import I2COp, I2COperation, I2CResult
from .spi_controller import SPIByte


__all__ = ["MAX_READ", "RegisterCommand", "RegisterResponse", "RegisterPortSignature",
           "SPIRegisterPort", "I2CRegisterPort"]


MAX_READ = 32

RegisterCommand = data.StructLayout({
    "device": 1, "reg": 8, "write": 1, "data": 8, "length": range(MAX_READ + 1), "fast": 1,
    "trained": 1,
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
    """Register commands as SPI transactions for an ``SPIController``.

    Members
        ``port`` (a ``RegisterPortSignature``): the commands, bytes read and responses.
        ``spi_o`` (out, stream of ``SPIByte``) / ``spi_i`` (in, byte stream): to and from the
            controller.
    A command is a transaction: the header byte (bit 7 = read, the register in bits 6:0),
    then the data byte (write) or ``length`` dummy bytes whose answers are the ``rx`` bytes.
    A result byte counts only for a byte already sent. ``rsp.error`` is always 0 (SPI has no
    acknowledge).
    Latency: the command's first byte is offered the cycle after it is taken; its response
    one cycle after the transaction's last byte. Throughput: one command at a time.
    """
    def __init__(self):
        super().__init__({
            "port": Out(RegisterPortSignature()),
            "spi_o": Out(stream.Signature(SPIByte)),
            "spi_i": In(stream.Signature(8)),
        })

    def elaborate(self, platform):
        m = Module()
        cmd = Signal(RegisterCommand, reset_less=True)    # captured with each command
        total = Signal(range(MAX_READ + 2))    # bytes in the transaction, header included
        tx_index = Signal.like(total)
        rx_index = Signal.like(total)
        busy = Signal()
        expected = Signal()         # the byte coming in answers one sent
        data_byte = Signal()        # ... and is one the command asked for

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
            self.spi_o.payload.trained.eq(cmd.trained & cmd.fast & ~cmd.write),
            self.spi_o.payload.last.eq(tx_index == total - 1),
            # A result counts only for a byte already sent (the controller never sends one
            # otherwise; a stray one cannot end the command early). Bytes clocked in during
            # the header and during writes mean nothing: they are taken and dropped. A data
            # byte waits for ``rx.ready`` (back-pressure reaches the SPI controller), so it is
            # never lost, whatever the consumer does.
            expected.eq(busy & (rx_index < tx_index)),
            data_byte.eq(expected & (rx_index != 0) & ~cmd.write),
            self.port.rx.valid.eq(self.spi_i.valid & data_byte),
            self.port.rx.payload.eq(self.spi_i.payload),
            self.spi_i.ready.eq(~data_byte | self.port.rx.ready),
            self.port.rsp.payload.error.eq(0),      # SPI has no acknowledge to miss
        ]
        with m.If(self.spi_o.valid & self.spi_o.ready):
            m.d.sync += tx_index.eq(tx_index + 1)
        with m.If(expected & self.spi_i.valid & self.spi_i.ready):
            m.d.sync += rx_index.eq(rx_index + 1)
            with m.If(rx_index == total - 1):
                m.d.sync += [busy.eq(0), self.port.rsp.valid.eq(1)]
        with m.If(self.port.rsp.valid & self.port.rsp.ready):
            m.d.sync += self.port.rsp.valid.eq(0)
        return m


class I2CRegisterPort(wiring.Component):
    """Register commands as I2C operations for an ``I2CController``.

    Parameters
        ``mpu_address``: the MPU9250's 7-bit address (0x68, or 0x69 with AD0 high).
    Members
        ``port`` (a ``RegisterPortSignature``): the commands, bytes read and responses.
        ``i2c_o`` (out, stream of ``I2COperation``) / ``i2c_i`` (in, stream of ``I2CResult``):
            to and from the controller.
    Write: START, address+W, register, data, STOP. Read: START, address+W, register, repeated
    START, address+R, ``length`` bytes (ACK on all but the last), STOP. A NACK or a controller
    error ends the command with a STOP and ``rsp.error`` = 1. ``device`` 1 is the AK8963 at
    0x0C (reachable once the MPU9250's bypass is on).
    Latency: one operation at a time, each offered the cycle after the last one's result; the
    response the cycle after the STOP's result. Throughput: one command at a time.
    """
    def __init__(self, *, mpu_address=0x68):
        self.mpu_address = mpu_address
        super().__init__({
            "port": Out(RegisterPortSignature()),
            "i2c_o": Out(stream.Signature(I2COperation)),
            "i2c_i": In(stream.Signature(I2CResult)),
        })

    def elaborate(self, platform):
        m = Module()
        cmd = Signal(RegisterCommand, reset_less=True)    # captured with each command
        address = Signal(7)
        remaining = Signal(range(MAX_READ + 1))
        error = Signal()
        issued = Signal()           # the current operation went out; waiting for its result
        op, res = self.i2c_o, self.i2c_i

        m.d.comb += [self.port.cmd.ready.eq(0), res.ready.eq(0),
                     self.port.rx.payload.eq(res.payload.data)]
        with m.If(self.port.rsp.valid & self.port.rsp.ready):
            m.d.sync += self.port.rsp.valid.eq(0)

        @contextmanager
        def operation(kind, data=0, ack=0):
            """Offer one operation until it is taken, then run the body (which sets
            ``res.ready``) each cycle until its result is taken."""
            with m.If(~issued):
                m.d.comb += [op.valid.eq(1), op.payload.op.eq(kind), op.payload.data.eq(data),
                             op.payload.ack.eq(ack)]
                with m.If(op.ready):
                    m.d.sync += issued.eq(1)
            with m.Else():
                yield
                with m.If(res.valid & res.ready):
                    m.d.sync += issued.eq(0)

        def step(kind, next_state, data=0, ack=0, *, acked=False):
            """Send one operation, wait for its result; on failure, STOP and report."""
            with operation(kind, data, ack):
                m.d.comb += res.ready.eq(1)
                with m.If(res.valid):
                    bad = res.payload.error | (~res.payload.ack if acked else 0)
                    with m.If(bad):
                        m.d.sync += error.eq(1)
                        m.next = "STOP"
                    with m.Else():
                        m.next = next_state

        with m.FSM():
            with m.State("IDLE"):
                m.d.comb += self.port.cmd.ready.eq(~self.port.rsp.valid)
                with m.If(self.port.cmd.valid & ~self.port.rsp.valid):
                    p = self.port.cmd.payload
                    m.d.sync += [cmd.eq(p), error.eq(0), remaining.eq(p.length),
                                 address.eq(Mux(p.device, A.I2C_ADDRESS, self.mpu_address))]
                    m.next = "START"
            with m.State("START"):
                step(I2COp.START, "ADDR_W")
            with m.State("ADDR_W"):
                step(I2COp.WRITE, "REG", Cat(Const(0, 1), address), acked=True)
            with m.State("REG"):
                step(I2COp.WRITE, "AFTER_REG", cmd.reg, acked=True)
            with m.State("AFTER_REG"):
                with m.If(cmd.write):
                    m.next = "DATA"
                with m.Else():
                    m.next = "RESTART"
            with m.State("DATA"):
                step(I2COp.WRITE, "STOP", cmd.data, acked=True)
            with m.State("RESTART"):
                step(I2COp.START, "ADDR_R")
            with m.State("ADDR_R"):
                step(I2COp.WRITE, "READ", Cat(Const(1, 1), address), acked=True)
            with m.State("READ"):
                with operation(I2COp.READ, ack=remaining != 1):
                    # a byte read waits for ``rx.ready`` (back-pressure reaches the controller)
                    good = ~res.payload.error
                    m.d.comb += [self.port.rx.valid.eq(res.valid & good),
                                 res.ready.eq(~good | self.port.rx.ready)]
                    with m.If(res.valid & res.ready):
                        m.d.sync += remaining.eq(remaining - 1)
                        with m.If(~good):
                            m.d.sync += error.eq(1)
                            m.next = "STOP"
                        with m.Elif(remaining == 1):
                            m.next = "STOP"
            with m.State("STOP"):
                with operation(I2COp.STOP):
                    # (``rsp`` is never valid here: IDLE waits for it to be taken. Waiting
                    # anyway costs a gate and lets the stream contract be proven by induction.)
                    m.d.comb += res.ready.eq(~self.port.rsp.valid)
                    with m.If(res.valid & res.ready):
                        m.d.sync += [self.port.rsp.valid.eq(1),
                                     self.port.rsp.payload.error.eq(error |
                                                                    res.payload.error)]
                        m.next = "IDLE"
        return m
