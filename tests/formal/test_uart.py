"""UART transmitter and receiver, formally: the line's frame and timing, and a loop-back.

The transmitter's line drives the receiver's (same divisor, the receiver always ready), the
producer offers any bytes at any time. 4 cycles per bit: the receiver's minimum, and a power of
two, so a bit's index is the cycle count's top bits.
"""

import pytest
from amaranth import *
from amaranth.asserts import AnySeq
from amaranth.hdl import Assert, Cover

from mpu9250_ahrs.hdl.link.uart_rx import UARTReceiver
from mpu9250_ahrs.hdl.link.uart_tx import UARTTransmitter

from .harness import harness_module
from .stream_contract import stream_input, stream_output


pytestmark = pytest.mark.formal

DIVISOR = 4
FRAME = 10 * DIVISOR


def loopback_harness(tx=None, rx=None):
    m = harness_module()
    m.submodules.tx = tx = tx or UARTTransmitter(divisor=DIVISOR)
    m.submodules.rx = rx = rx or UARTReceiver(divisor=DIVISOR)
    stream_input(m, tx.i_stream, "tx_in")
    stream_output(m, rx.o_stream, "rx_out", ready=1, cover=False)
    m.d.comb += rx.rx.eq(tx.tx)

    take = tx.i_stream.valid & tx.i_stream.ready
    t = Signal(range(FRAME + 6), init=FRAME + 5)     # cycles since the last byte was taken
    data = Signal(8)
    previous = Signal(8)            # the byte before: the receiver finishes a byte after the
                                    # transmitter took the next one
    sent = Signal(4)
    received = Signal(4)
    with m.If(take):
        m.d.sync += [t.eq(0), data.eq(tx.i_stream.payload), previous.eq(data),
                     sent.eq(sent + 1)]
    with m.Elif(t != FRAME + 5):
        m.d.sync += t.eq(t + 1)
    with m.If(rx.o_stream.valid):
        m.d.sync += received.eq(received + 1)

    frame = Cat(C(0, 1), data, C(1, 1))         # start bit, LSB first, stop bit
    with m.If(t < FRAME):
        # each bit for exactly DIVISOR cycles, from the cycle after the byte was taken
        m.d.comb += Assert(tx.tx == frame.bit_select(t[2:], 1), "tx_frame")
    with m.Else():
        m.d.comb += Assert(tx.tx, "tx_idles_high")
    # the next byte is taken in the cycle after the stop bit, not before
    m.d.comb += Assert(tx.i_stream.ready == (t >= FRAME), "tx_ready_after_stop")
    with m.If(rx.o_stream.valid):
        last = (received + 1 == sent) & (rx.o_stream.payload == data)
        before = (received + 2 == sent) & (rx.o_stream.payload == previous)
        m.d.comb += Assert(last | before, "loopback_byte_in_order")
    with m.If(t == FRAME + 4):
        # a byte is received at most 4 cycles after its stop bit's end (the middle of the
        # stop bit, one bit's majority, the synchroniser)
        m.d.comb += Assert(received == sent, "loopback_complete")
    m.d.comb += [Assert(~rx.framing_error, "no_framing_error"),
                 Assert(~rx.overrun, "no_overrun"),
                 Cover((received == 2) & (sent == 2) & (t == FRAME + 5), "two_bytes")]
    return m


def receiver_harness(rx=None):
    """The receiver alone, any line, any consumer: its output keeps the stream rules."""
    m = harness_module()
    m.submodules.rx = rx = rx or UARTReceiver(divisor=DIVISOR)
    m.d.comb += rx.rx.eq(AnySeq(1))
    stream_output(m, rx.o_stream, "rx_out")
    return m


# Depth: two back-to-back bytes are 2 × 40 cycles, plus the receiver's synchroniser and
# half a bit: 96 covers a byte taken, sent, received, and the next one taken after it.
@pytest.mark.slow
def test_uart_loopback(formal):
    formal(loopback_harness(), name="uart_loopback", mode="bmc", depth=96)


def test_uart_loopback_cover(formal):
    formal(loopback_harness(), name="uart_loopback_cover", mode="cover", depth=96)


def test_uart_receiver_stream(formal):
    formal(receiver_harness(), name="uart_rx_stream", mode="prove", depth=4)
