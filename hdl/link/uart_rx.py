"""UART receiver, 8N1, LSB first: the command channel's input."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out


__all__ = ["UARTReceiver", "MIN_DIVISOR"]


# cycles a bit the receiver needs: three samples of the bit and its edge
MIN_DIVISOR = 4


class UARTReceiver(wiring.Component):
    """Receives bytes at ``divisor`` cycles per bit (the transmitter's divisor: the same baud).

    The line is synchronised (two flip-flops) and sampled every cycle; a bit's value is the
    majority of the three samples around its middle, so a one-cycle spike does not flip it.
    A falling edge starts a byte only if the line is still low (majority) half a bit later
    (start-bit validation: a glitch is ignored). A low stop bit is a framing error: the byte
    is dropped, counted, and the receiver waits for the line to go high again (a break, or a
    host at another baud, costs one count per low stretch, not one per bit).

    Parameters
        ``divisor``: clock cycles per bit, at least 4 (three samples and an edge).
    Members
        ``rx`` (in): the line (asynchronous; idles high).
        ``o_stream`` (out, byte stream): a received byte, valid until taken. A byte that
            completes while the previous one was not taken is dropped and counted.
        ``framing_error``, ``overrun`` (out): a pulse per framing error, per byte dropped (the
            command decoder counts them in its ``EventCounters``: RX_FRAMING_ERRORS,
            RX_OVERRUNS).
    Latency: a byte is valid about the middle of its stop bit (the synchroniser's two cycles
        later); the receiver then looks for the next start bit, so back-to-back bytes and a
        transmitter up to about 4 % off the baud are received.
    """
    def __init__(self, *, divisor):
        if divisor < MIN_DIVISOR:
            raise ValueError(f"UART receiver needs at least {MIN_DIVISOR} cycles per bit, not "
                             f"{divisor}")
        self.divisor = divisor
        super().__init__({
            "rx": In(1, init=1),
            "o_stream": Out(stream.Signature(8)),
            "framing_error": Out(1),
            "overrun": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        d = self.divisor
        line = Signal(init=1)
        m.submodules.sync = FFSynchronizer(self.rx, line, init=1)
        # The sampling registers need no reset (a synchronous reset costs logic per bit with
        # Yosys' MAX10 mapping): ``history`` is refilled within three cycles and is read only at
        # the middle of a start bit, ``timer`` and ``count`` are loaded before they are used,
        # and ``shreg`` is filled with eight bits before it is passed on
        history = Signal(3, init=0b111, reset_less=True)
        m.d.sync += history.eq(Cat(line, history[:2]))
        # the majority of the last three samples: the sample taken at ``timer == 0`` is the
        # middle one of three spaced around the bit's centre
        bit = (history[0] & history[1]) | (history[1] & history[2]) | (history[0] & history[2])
        timer = Signal(range(d), reset_less=True)
        count = Signal(range(9), reset_less=True)
        shreg = Signal(8, reset_less=True)
        data = Signal(8, reset_less=True)           # written with ``valid``: no reset either
        m.d.comb += self.o_stream.payload.eq(data)

        with m.If(self.o_stream.ready):
            m.d.sync += self.o_stream.valid.eq(0)
        with m.If(timer != 0):
            m.d.sync += timer.eq(timer - 1)

        with m.FSM():
            with m.State("IDLE"):
                with m.If(~line):
                    # one cycle after the edge; the middle of the start bit is half a bit on,
                    # and the majority's middle sample one cycle before the newest
                    m.d.sync += timer.eq(d // 2)
                    m.next = "START"
            with m.State("START"):
                with m.If(timer == 0):
                    with m.If(bit):
                        m.next = "IDLE"                 # a glitch, not a start bit
                    with m.Else():
                        m.d.sync += [timer.eq(d - 1), count.eq(0)]
                        m.next = "DATA"
            with m.State("DATA"):
                with m.If(timer == 0):
                    m.d.sync += [shreg.eq(Cat(shreg[1:], bit)), count.eq(count + 1),
                                 timer.eq(d - 1)]
                    with m.If(count == 7):
                        m.next = "STOP"
            with m.State("STOP"):
                with m.If(timer == 0):
                    with m.If(bit):
                        with m.If(self.o_stream.valid & ~self.o_stream.ready):
                            m.d.comb += self.overrun.eq(1)
                        with m.Else():
                            m.d.sync += [data.eq(shreg),
                                         self.o_stream.valid.eq(1)]
                        m.next = "IDLE"
                    with m.Else():
                        m.d.comb += self.framing_error.eq(1)
                        m.next = "BREAK"
            with m.State("BREAK"):
                with m.If(bit):
                    m.next = "IDLE"
        return m
