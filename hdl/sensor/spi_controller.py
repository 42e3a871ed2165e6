"""SPI controller for the MPU9250: mode 3, MSB first, two clock rates chosen per byte."""

import math
from dataclasses import dataclass

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from ..primitives.clocking import cycles


__all__ = ["IOBudget", "IO_BUDGET", "FAST_READ_MAX_HZ", "FAST_READ_MIN_LEVEL_S", "SPITiming",
           "SPIPinsSignature", "SPIByte", "SPIController"]


SYNC_STAGES = 2
# The MPU9250's fast reads (its sensor and interrupt registers): SCLK at most 20 MHz, each level
# at least 25 ns (PS-MPU-9250A-01)
FAST_READ_MAX_HZ = 20e6
FAST_READ_MIN_LEVEL_S = 25e-9


@dataclass(frozen=True)
class IOBudget:
    """The round trip of a CIPO bit, in ns: from the falling SCLK edge leaving the FPGA's
    register to the next bit captured in CIPO's input register. ``sdo_max_ns`` is the MPU9250's
    output delay (PS-MPU-9250A-01: at most 100 ns, no minimum given); the FPGA figures are a
    MAX10 C8's I/O with its I/O registers (``fpga_out_ns``: the SCLK output register to the
    pad; ``fpga_in_ns``: the CIPO pad to its input register, setup included) and are
    allowances, not Quartus figures (only its timing analysis gives those: ``top.sdc``
    carries the same figures as constraints for it to check); ``board_ns`` is one way along
    the board (about 30 cm of trace). ``margin_ns``: what the sample point must leave
    beyond the latest arrival. Nothing has a minimum: the previous bit may change at once."""
    sdo_max_ns: float = 100.0
    fpga_out_ns: float = 7.0
    board_ns: float = 2.0
    fpga_in_ns: float = 3.0
    margin_ns: float = 10.0

    @property
    def arrival_ns(self):
        """The latest time after the falling edge leaves its register that a bit arrives."""
        return self.fpga_out_ns + 2 * self.board_ns + self.sdo_max_ns + self.fpga_in_ns

    @property
    def sdo_window_s(self):
        """(earliest, latest) time after the falling edge leaves its register at which the
        next bit may be sampled: (0, arrival + margin)."""
        return 0.0, (self.arrival_ns + self.margin_ns) * 1e-9


IO_BUDGET = IOBudget()


@dataclass(frozen=True)
class SPITiming:
    slow_half: int       # cycles per SCLK level, slow rate
    fast_half: int       # cycles of SCLK's low level (and of the CS setup), fast rate
    cs_hold: int         # cycles from the last rising SCLK edge to CS rising, at least
    cs_gap: int          # cycles CS stays high between transactions
    cipo_delay: int = 1  # cycles from a rising SCLK edge to the edge that samples CIPO's pin
    fast_high: int = None   # cycles of SCLK's high level, fast rate (None: ``fast_half``)
    # a third rate for reads whose sample point was trained (issue #58; None: none): its
    # SCLK levels, and the largest ``sample_delay`` (cycles from a rising edge to the edge
    # that samples CIPO's pin, as ``cipo_delay``) a trained transaction may ask for
    trained_low: int = None
    trained_high: int = None
    max_sample_delay: int = 0

    def __post_init__(self):
        if self.fast_high is None:
            object.__setattr__(self, "fast_high", self.fast_half)
        for name in ("slow_half", "fast_half", "fast_high", "cs_hold", "cs_gap"):
            if getattr(self, name) < 1:
                raise ValueError(f"SPITiming.{name} must be at least 1 cycle")
        if self.cipo_delay < 0:
            raise ValueError("SPITiming.cipo_delay cannot be negative")
        if (self.trained_low is None) != (self.trained_high is None):
            raise ValueError("SPITiming: the trained rate needs both trained_low and "
                             "trained_high")
        if self.trained_low is not None and min(self.trained_low, self.trained_high) < 1:
            raise ValueError("SPITiming: the trained rate's levels must be at least 1 cycle")
        if self.max_sample_delay < 0:
            raise ValueError("SPITiming.max_sample_delay cannot be negative")

    @property
    def has_trained(self):
        return self.trained_low is not None

    def with_trained(self, clk_freq, *, max_hz=FAST_READ_MAX_HZ,
                     min_level_s=FAST_READ_MIN_LEVEL_S, io_budget=None):
        """This timing with a trained rate: the shortest SCLK period the part's fast reads
        allow (at most ``max_hz``, each level at least ``min_level_s`` and 2 cycles), and
        sample delays reaching a cycle more than such a period past the latest safe sample
        point (``io_budget``'s arrival and margin): a scan across more than a period, which
        sees both edges of the eye of any part the safe rate reads."""
        io_budget = io_budget or IO_BUDGET
        level = max(2, cycles(min_level_s, clk_freq))
        period = max(2 * level, cycles(1 / max_hz, clk_freq))
        low = (period + 1) // 2
        first = math.floor(io_budget.sdo_window_s[1] * clk_freq + 1e-9) + 1
        return SPITiming(slow_half=self.slow_half, fast_half=self.fast_half,
                         fast_high=self.fast_high, cs_hold=self.cs_hold, cs_gap=self.cs_gap,
                         cipo_delay=self.cipo_delay, trained_low=low,
                         trained_high=period - low,
                         max_sample_delay=max(0, first - low) + period + 1)

    def trained_period(self):
        return self.trained_low + self.trained_high

    def low(self, fast):
        """Cycles of SCLK's low level (the first of a bit: COPI and the device's SDO change
        at its start)."""
        return self.fast_half if fast else self.slow_half

    def high(self, fast):
        """Cycles of SCLK's high level (the device latches COPI at its start)."""
        return self.fast_high if fast else self.slow_half

    def period(self, fast):
        """Cycles of one SCLK period, a bit."""
        return self.low(fast) + self.high(fast)

    @property
    def capture_delay(self):
        return SYNC_STAGES + self.cipo_delay

    def setup_margin_ns(self, clk_freq, budget=IO_BUDGET, fast=True):
        """How long after ``budget``'s latest arrival CIPO's pin is sampled, ns (the sample
        point's slack, ``for_clock`` makes it at least ``budget.margin_ns``)."""
        first, _ = self.sample_window(fast)
        return first / clk_freq * 1e9 - budget.arrival_ns

    def sample_window(self, fast):
        """(first, last) cycle after a falling SCLK edge leaves its register at which CIPO's
        pin is sampled for that bit: (sample point, the cycle before the next falling edge)."""
        return self.low(fast) + self.cipo_delay, self.period(fast) - 1

    @classmethod
    def for_clock(cls, clk_freq, *, slow_hz=1e6, fast_hz=FAST_READ_MAX_HZ, cs_hold_s=500e-9,
                  min_half=2, io_budget=IO_BUDGET):
        """The fastest timing the datasheet and CIPO's timing allow at ``clk_freq``.

        ``io_budget.sdo_window_s`` = (earliest, latest) time after a falling SCLK edge leaves
        the FPGA's register at which the sensor's next bit may be sampled: its round trip
        (the MPU9250's output delay, at most 100 ns, the FPGA's output and input and the
        board's, ``IOBudget``) plus a setup margin, (0, 124 ns) by default. The previous bit
        can change from ``earliest`` after the next falling edge. The pin is sampled on the
        first clock edge after ``latest`` and it must come before the next falling edge plus
        ``earliest``: so an SCLK period longer than ``latest - earliest`` is needed, whatever
        the clock (at most about 8 MHz with the defaults; 48/7 MHz at 48 MHz). The fast
        period is the shortest whole number of cycles (each level at least ``min_half``,
        SCLK at most ``fast_hz``) with such a sampling edge; it need not be even: the low
        level gets the odd cycle (``fast_half``, ``fast_high``), and ``cipo_delay`` places
        the edge in the high level.
        """
        def half(hz):
            return cycles(1 / (2 * hz), clk_freq, minimum=min_half)
        earliest, latest = io_budget.sdo_window_s
        first = math.floor(latest * clk_freq + 1e-9) + 1    # first edge strictly after latest
        period = max(2 * min_half, cycles(1 / fast_hz, clk_freq))
        while first > period - 1 + math.floor(earliest * clk_freq + 1e-9):
            period += 1
        low = (period + 1) // 2
        slow = max(half(slow_hz), low)
        hold = cycles(cs_hold_s, clk_freq)
        return cls(slow_half=slow, fast_half=low, fast_high=period - low, cs_hold=hold,
                   cs_gap=max(hold, slow), cipo_delay=max(0, first - low))

    def sclk_hz(self, clk_freq, fast):
        return clk_freq / self.period(fast)


class SPIPinsSignature(wiring.Signature):
    def __init__(self):
        super().__init__({
            "sclk": Out(1, init=1),
            "copi": Out(1),
            "cs_n": Out(1, init=1),
            "cipo": In(1),
        })


SPIByte = data.StructLayout({"data": 8, "fast": 1, "last": 1, "trained": 1})


class SPIController(wiring.Component):
    """SPI controller for the MPU9250: mode 3, MSB first, two clock rates chosen per byte.

    Interface
        ``i_stream`` (in):  bytes to send. Payload ``data`` (8), ``fast`` (1: use the fast clock),
                            ``last`` (1: raise chip select after this byte). ``fast`` is taken from
                            the first byte of a transaction and holds for the whole transaction.
        ``o_stream`` (out): one received byte for every byte sent (full duplex), in order.
        ``pins``:           ``sclk``, ``copi``, ``cs_n`` outputs (registered), ``cipo`` input
                            (raw: it goes through an ``FFSynchronizer`` here).

    Timing (``SPITiming``, all in system clock cycles)
        Each SCLK level lasts ``slow_half`` cycles at the slow rate; at the fast rate the low
        level lasts ``fast_half`` and the high level ``fast_high`` (a period need not be even:
        ``for_clock``). Chip select falls a low level's cycles before the first falling SCLK
        edge (setup) and rises at least ``cs_hold`` cycles after the last rising edge; it then
        stays high for ``cs_gap`` cycles.
        Mode 3: SCLK idles high, COPI changes on the falling edge. CIPO's pin is sampled (the
        synchroniser's first flip-flop) ``cipo_delay`` cycles after the rising edge leaves its
        register, so ``low + cipo_delay`` cycles after the falling edge the device answers: late
        enough for the round trip (``IOBudget``: the output delay, the I/O, the board, a
        margin), early enough that the bit has not yet changed; the bit is shifted in
        ``capture_delay`` = 2 + ``cipo_delay`` cycles after the rising edge.

    Throughput: 8 bits take 8 periods (``period``). Within a transaction the next byte's first
    falling edge follows the last rising edge by a high level (SCLK runs without a pause) when that
    byte is offered in time and every earlier result has been taken; the byte in flight is
    still captured (its result held in the receive shift register until the one before it is
    taken, so none is lost). Otherwise the controller waits for its byte's result to be
    handed over, then for the next byte: ``capture_delay`` + 2 or more cycles between bytes.
    Latency: a byte's result is offered 8·``period`` + ``capture_delay`` - ``high`` + 1 cycles
    after its first falling edge; the first byte of a transaction adds the chip-select setup
    (a low level).
    """
    def __init__(self, timing):
        self.timing = timing
        super().__init__({
            "i_stream": In(stream.Signature(SPIByte)),
            "o_stream": Out(stream.Signature(8)),
            "pins": Out(SPIPinsSignature()),
            **({"sample_delay": In(range(timing.max_sample_delay + 1))}
               if timing.has_trained else {}),
        })

    def elaborate(self, platform):
        m = Module()
        t = self.timing

        cipo = Signal()
        m.submodules.cipo_sync = FFSynchronizer(self.pins.cipo, cipo, stages=SYNC_STAGES)

        timer = Signal(range(max(t.slow_half, t.fast_half, t.fast_high, t.cs_hold, t.cs_gap,
                                 t.trained_low or 0, t.trained_high or 0) + 1))
        fast = Signal()         # rate of the current transaction
        trained = Signal()      # ... the trained rate, at ``delay`` (``SPITiming.trained_low``)
        delay = Signal(range(t.max_sample_delay + 1))
        last = Signal()         # current byte ends the transaction
        tx = Signal(8, reset_less=True)     # loaded with each byte
        bit = Signal(range(8))
        half = Signal.like(timer)       # the low level (and the CS setup)
        high = Signal.like(timer)
        m.d.comb += [half.eq(Mux(fast, t.fast_half, t.slow_half)),
                     high.eq(Mux(fast, t.fast_high, t.slow_half))]
        if t.has_trained:
            with m.If(trained):
                m.d.comb += [half.eq(t.trained_low), high.eq(t.trained_high)]

        rise = Signal()         # a rising edge goes out this cycle
        strobe, rx_count, waiting, handover = self._capture(m, cipo, rise, trained, delay)

        # Bytes whose last rising edge has gone out and whose result has not been taken yet.
        # A byte may follow the one in flight without a pause only if this is at most 1 (the
        # one in flight: results are taken in order, so every earlier one was): its result
        # then finds the output free or holding only the one before it, so it waits in ``rx``
        # at worst and the next byte's first capture cannot overwrite it.
        owed = Signal(2)
        clocked = Signal()      # the last bit's rising edge goes out this cycle
        m.d.sync += owed.eq(owed + clocked - (self.o_stream.valid & self.o_stream.ready))

        def start_bit(value):
            m.d.sync += [self.pins.sclk.eq(0), self.pins.copi.eq(value[7]), timer.eq(half - 1)]


        with m.FSM():
            with m.State("IDLE"):
                m.d.comb += self.i_stream.ready.eq(1)
                with m.If(self.i_stream.valid):
                    p = self.i_stream.payload
                    m.d.sync += [
                        tx.eq(p.data), fast.eq(p.fast), last.eq(p.last), bit.eq(0),
                        self.pins.cs_n.eq(0),
                        timer.eq(Mux(p.fast, t.fast_half, t.slow_half) - 1),
                    ]
                    if t.has_trained:
                        # the rate and the sample point held for the transaction; the line
                        # emptied of the last one's strobes past its tap (none before it: it
                        # drained them)
                        m.d.sync += [trained.eq(p.fast & p.trained),
                                     delay.eq(self.sample_delay), strobe.eq(0)]
                        with m.If(p.fast & p.trained):
                            m.d.sync += timer.eq(t.trained_low - 1)
                    m.next = "SETUP"
            with m.State("SETUP"):
                m.d.sync += timer.eq(timer - 1)
                with m.If(timer == 0):
                    start_bit(tx)
                    m.next = "LOW"
            with m.State("LOW"):
                m.d.sync += timer.eq(timer - 1)
                with m.If(timer == 0):
                    m.d.sync += [self.pins.sclk.eq(1), timer.eq(high - 1)]
                    m.d.comb += [rise.eq(1), clocked.eq(bit == 7)]
                    m.next = "HIGH"
            with m.State("HIGH"):
                m.d.sync += timer.eq(timer - 1)
                with m.If(timer == 0):
                    with m.If(bit == 7):
                        with m.If(~last & self.i_stream.valid & ~owed[1]):
                            # the next byte at once: SCLK keeps its rhythm
                            m.d.comb += self.i_stream.ready.eq(1)
                            m.d.sync += [tx.eq(self.i_stream.payload.data), bit.eq(0),
                                         last.eq(self.i_stream.payload.last)]
                            start_bit(self.i_stream.payload.data)
                            m.next = "LOW"
                        with m.Else():
                            m.next = "DRAIN"
                    with m.Else():
                        m.d.sync += [bit.eq(bit + 1), tx.eq(tx << 1)]
                        start_bit(tx << 1)
                        m.next = "LOW"
            with m.State("DRAIN"):
                # Wait for the last bit through the capture delay line and for the previous
                # byte to be taken: this byte is handed over (above) as this state ends, or
                # already was (a capture delay shorter than the high level).
                with m.If(handover | ((rx_count == 0) & ~waiting)):
                    with m.If(last):
                        m.d.sync += timer.eq(t.cs_hold - 1)
                        m.next = "HOLD"
                    with m.Else():
                        m.next = "NEXT"
            with m.State("NEXT"):
                m.d.comb += self.i_stream.ready.eq(1)
                with m.If(self.i_stream.valid):
                    m.d.sync += [tx.eq(self.i_stream.payload.data), bit.eq(0),
                                 last.eq(self.i_stream.payload.last)]
                    start_bit(self.i_stream.payload.data)
                    m.next = "LOW"
            with m.State("HOLD"):
                m.d.sync += timer.eq(timer - 1)
                with m.If(timer == 0):
                    m.d.sync += [self.pins.cs_n.eq(1), timer.eq(t.cs_gap - 1)]
                    m.next = "GAP"
            with m.State("GAP"):
                m.d.sync += timer.eq(timer - 1)
                with m.If(timer == 0):
                    m.next = "IDLE"

        return m

    def _capture(self, m, cipo, rise, trained, delay):
        """CIPO's bits into bytes and the bytes onto ``o_stream``: returns the capture line
        (``strobe``), the bits captured (``rx_count``), whether a strobe is still to be
        captured (``waiting``) and the handover pulse."""
        t = self.timing
        # The capture strobe follows each rising edge through a delay line as long as the
        # round trip, so the received bit is the one the device drove for that edge. With a
        # trained rate the line reaches the longest sample delay, and a trained transaction
        # takes its strobe from its own tap.
        length = t.capture_delay
        if t.has_trained:
            length = max(length, SYNC_STAGES + t.max_sample_delay)
        strobe = Signal(length)
        m.d.sync += strobe.eq(Cat(rise, strobe[:-1]))
        rx = Signal(8, reset_less=True)     # read after 8 captures
        rx_count = Signal(range(9))
        if t.has_trained:
            tap = Signal(range(length))
            m.d.comb += tap.eq(Mux(trained, SYNC_STAGES - 1 + delay, t.capture_delay - 1))
            capture = strobe.bit_select(tap, 1)
            # strobes at or before the tap: still to be captured (those past it mean nothing)
            waiting = (strobe & ((C(1, length + 1) << (tap + 1)) - 1)[:length]) != 0
        else:
            capture = strobe[-1]
            waiting = strobe != 0
        with m.If(capture):
            m.d.sync += [rx.eq(Cat(cipo, rx[:-1])), rx_count.eq(rx_count + 1)]

        # A received byte is handed over as soon as the output is free, whatever the state.
        handover = (rx_count == 8) & ~self.o_stream.valid
        with m.If(handover):
            m.d.sync += [self.o_stream.payload.eq(rx), self.o_stream.valid.eq(1),
                         rx_count.eq(0)]
        with m.If(self.o_stream.valid & self.o_stream.ready):
            m.d.sync += self.o_stream.valid.eq(0)

        return strobe, rx_count, waiting, handover
