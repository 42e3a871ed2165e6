"""UART transmitter, 8N1, LSB first."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from .uart_rx import MIN_DIVISOR


__all__ = ["UARTTransmitter"]


class UARTTransmitter(wiring.Component):
    """UART transmitter, 8N1, LSB first.

    Interface
        ``i_stream`` (in, byte stream): bytes to send; ``ready`` is high while idle.
        ``tx`` (out): line, idles high.

    Timing: one bit every ``divisor`` cycles (``divisor = round(clk_freq / baud)``); a byte takes
    ``10 * divisor`` cycles and the next byte is accepted in the cycle after its stop bit ends.
    Latency: the start bit goes out the cycle after a byte is taken.
    """
    def __init__(self, *, divisor):
        if divisor < 2:
            raise ValueError(f"UART divisor must be at least 2 cycles per bit, not {divisor}")
        self.divisor = divisor
        super().__init__({
            "i_stream": In(stream.Signature(8)),
            "tx": Out(1, init=1),
        })

    @staticmethod
    def divisor_for(clk_freq, baud):
        """Cycles per bit for ``baud``; an error above 2 % would garble bytes, so it raises, as
        for fewer cycles a bit than the receiver needs (``uart_rx.MIN_DIVISOR``)."""
        divisor = round(clk_freq / baud)
        if divisor < MIN_DIVISOR:
            raise ValueError(f"{baud:g} baud from {clk_freq / 1e6:g} MHz is "
                             f"{clk_freq / baud:.3g} cycles a bit; the UART needs at least "
                             f"{MIN_DIVISOR}: at most {clk_freq / MIN_DIVISOR:g} baud")
        error = abs(clk_freq / divisor - baud) / baud
        if error > 0.02:
            raise ValueError(f"{baud} baud from {clk_freq / 1e6:g} MHz is off by {error:.1%}")
        return divisor

    @classmethod
    def for_baud(cls, clk_freq, baud):
        return cls(divisor=cls.divisor_for(clk_freq, baud))

    def elaborate(self, platform):
        m = Module()
        shreg = Signal(10, init=0x3FF)     # stop bit, data LSB first, start bit
        bits_left = Signal(range(11))
        timer = Signal(range(self.divisor))

        m.d.comb += [self.tx.eq(shreg[0]), self.i_stream.ready.eq(bits_left == 0)]
        with m.If(self.i_stream.valid & self.i_stream.ready):
            m.d.sync += [shreg.eq(Cat(0, self.i_stream.payload, 1)), bits_left.eq(10),
                         timer.eq(self.divisor - 1)]
        with m.Elif(bits_left != 0):
            m.d.sync += timer.eq(timer - 1)
            with m.If(timer == 0):
                m.d.sync += [shreg.eq(Cat(shreg[1:], 1)), bits_left.eq(bits_left - 1),
                             timer.eq(self.divisor - 1)]
        return m
