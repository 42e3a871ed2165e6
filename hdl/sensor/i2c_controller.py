"""I2C controller (single master), 100 kHz or 400 kHz, open drain."""

from contextlib import contextmanager
from dataclasses import dataclass
from types import SimpleNamespace

from amaranth import *
from amaranth.lib import data, enum, stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from ..primitives.clocking import cycles


__all__ = ["I2CTiming", "I2COp", "I2COperation", "I2CResult", "I2CPinsSignature",
           "I2CController"]


@dataclass(frozen=True)
class I2CTiming:
    low: int
    high: int
    timeout: int

    def __post_init__(self):
        if self.low < 4 or self.high < 2:
            raise ValueError("I2CTiming needs low >= 4 and high >= 2 cycles")

    @classmethod
    def for_clock(cls, clk_freq, *, scl_hz=400e3, timeout_s=10e-3):
        if scl_hz > 400e3:
            raise ValueError("the MPU9250 and AK8963 take at most 400 kHz")
        t_low, t_high = (1.3e-6, 0.6e-6) if scl_hz > 100e3 else (4.7e-6, 4.0e-6)
        low = cycles(max(t_low, 0.5 / scl_hz), clk_freq, minimum=4)
        high = max(cycles(t_high, clk_freq, minimum=2), cycles(1 / scl_hz, clk_freq) - low)
        return cls(low=low, high=high, timeout=cycles(timeout_s, clk_freq))

    def scl_hz(self, clk_freq):
        return clk_freq / (self.low + self.high)


class I2COp(enum.Enum, shape=2):
    START = 0
    STOP  = 1
    WRITE = 2
    READ  = 3


I2COperation = data.StructLayout({"op": I2COp, "data": 8, "ack": 1})
I2CResult = data.StructLayout({"data": 8, "ack": 1, "error": 1})


class I2CPinsSignature(wiring.Signature):
    def __init__(self):
        super().__init__({
            "scl_oe": Out(1), "sda_oe": Out(1),
            "scl_i": In(1, init=1), "sda_i": In(1, init=1),
        })


class I2CController(wiring.Component):
    """I2C controller (single master), 100 kHz or 400 kHz, open drain.

    Interface
        ``i_stream`` (in, ``I2COperation``): ``op`` START (a repeated start if the controller holds
            the bus), STOP, WRITE (``data``), READ (answer with ``ack``: 1 = ACK, 0 = NACK).
        ``o_stream`` (out, ``I2CResult``): one per operation, in order: ``data`` (READ), ``ack``
            (WRITE: the device acknowledged), ``error`` (the operation failed: see below; a WRITE
            or READ without a START holding the bus is refused with ``error`` and no clock).
        ``pins``: ``scl_oe``/``sda_oe`` (1 = pull the line low; never driven high),
            ``scl_i``/``sda_i`` (line levels, raw: synchronised here).
        ``status``: ``timeout``, ``bus_stuck``, ``arbitration``: the last failure, set by the
            operation that failed and cleared by the next START that gets the bus; ``recoveries``
            (stuck-bus recoveries done since reset, saturating at 15).

    Errors (the controller then releases both lines and forgets the bus; before its next START it
    waits for SCL to be released, at most ``timeout``, and sends a START and a STOP, which puts a
    device cut off mid-transfer back to idle)
        - time-out: SCL held low by a device (clock stretching) longer than ``timeout``;
        - stuck bus: SDA low before a START and still low after nine recovery clocks;
        - arbitration: SDA read low while the controller sent a 1 (another driver on the bus).

    Before each START on an idle bus, SDA low means a device was interrupted mid-byte (for example
    by an FPGA reset): the controller clocks SCL until SDA is released, at most nine times, then
    sends a STOP and goes on.

    Timing (``I2CTiming``, cycles): SCL low ``low``, high ``high`` (after the line is seen high, so
    clock stretching only lengthens it); SDA changes ``low // 2`` after SCL falls; START hold and
    STOP setup ``high``; repeated-START setup and bus-free time ``low``. ``for_clock`` meets the
    I2C-bus specification's fast-mode (≤ 400 kHz) or standard-mode minimums.
    Throughput: about (low + high + 3) cycles per bit, 9 bits per byte.
    Latency: a WRITE's or READ's result is offered at the end of its ninth bit, about
    9 × (low + high + 3) cycles after it is taken, longer by any clock stretching; a START or
    STOP's result once its last SCL or SDA edge has had its hold time.
    """
    def __init__(self, timing):
        self.timing = timing
        super().__init__({
            "i_stream": In(stream.Signature(I2COperation)),
            "o_stream": Out(stream.Signature(I2CResult)),
            "pins": Out(I2CPinsSignature()),
            "status": Out(data.StructLayout({"timeout": 1, "bus_stuck": 1, "arbitration": 1,
                                             "recoveries": 4})),
        })

    def elaborate(self, platform):
        m = Module()
        t = self.timing
        scl = Signal(init=1)
        sda = Signal(init=1)
        m.submodules.scl_sync = FFSynchronizer(self.pins.scl_i, scl, init=1)
        m.submodules.sda_sync = FFSynchronizer(self.pins.sda_i, sda, init=1)

        timer = Signal(range(max(t.low, t.high, t.timeout) + 1))
        op = Signal(I2COperation)
        held = Signal()             # a START was sent and no STOP yet: SCL is ours, low
        shreg = Signal(9)           # bits to send, MSB first; a 1 releases SDA
        rx = Signal(8)
        bit = Signal(range(10))
        recover = Signal(range(10))
        sent = Signal()             # the bit being clocked, as driven
        then_start = Signal()       # a recovery STOP, to be followed by the requested START

        res = self.o_stream
        # A result is offered only in IDLE, which is left only once it was taken. (It is never
        # pending elsewhere; gating it costs a gate and lets the stream contract be proven by
        # induction.)
        pending = Signal()
        with m.If(res.valid & res.ready):
            m.d.sync += pending.eq(0)

        def respond(*, error=0, ack=0):
            m.d.sync += [pending.eq(1), res.payload.error.eq(error), res.payload.ack.eq(ack),
                         res.payload.data.eq(rx)]
            m.next = "IDLE"

        aborted = Signal()          # the last transfer was cut off: devices may be mid-byte
        reset_first = Signal()      # a START-STOP goes before the next START

        def abort(flag):
            m.d.sync += [self.pins.scl_oe.eq(0), self.pins.sda_oe.eq(0), held.eq(0),
                         flag.eq(1), aborted.eq(1)]
            respond(error=1)

        def wait(cycles):
            m.d.sync += timer.eq(cycles - 1)

        @contextmanager
        def timed(name):
            """A state that counts ``timer`` down and runs the body when it reaches zero."""
            with m.State(name):
                m.d.sync += timer.eq(timer - 1)
                with m.If(timer == 0):
                    yield

        def clock_up(prefix, after, high):
            """``{prefix}_LOW``: SCL stays low until the timer ends; ``{prefix}_RISE``: SCL is
            released and, once the line is seen high (no device stretching it past the
            time-out), ``after`` runs for ``high`` cycles."""
            with timed(f"{prefix}_LOW"):
                m.d.sync += [self.pins.scl_oe.eq(0), timer.eq(t.timeout - 1)]
                m.next = f"{prefix}_RISE"
            with m.State(f"{prefix}_RISE"):
                m.d.sync += timer.eq(timer - 1)
                with m.If(scl):
                    wait(high)
                    m.next = after
                with m.Elif(timer == 0):
                    abort(self.status.timeout)

        with m.FSM() as fsm:
            m.d.comb += res.valid.eq(pending & fsm.ongoing("IDLE"))
            with m.State("IDLE"):
                m.d.comb += self.i_stream.ready.eq(~res.valid)
                with m.If(self.i_stream.valid & ~res.valid):
                    m.d.sync += op.eq(self.i_stream.payload)
                    p = self.i_stream.payload
                    with m.Switch(p.op):
                        with m.Case(I2COp.START):
                            with m.If(held):
                                # Repeated START: SDA up while SCL is low, then SCL up.
                                m.d.sync += self.pins.sda_oe.eq(0)
                                wait(t.low)
                                m.next = "RS_LOW"
                            with m.Else():
                                m.d.sync += timer.eq(t.timeout - 1)
                                m.next = "START_IDLE"
                        with m.Case(I2COp.STOP):
                            with m.If(held):
                                wait(t.low // 2)
                                m.next = "STOP_HOLD"
                            with m.Else():
                                respond()
                        with m.Case(I2COp.WRITE, I2COp.READ):
                            with m.If(~held):
                                # No START before it (or the bus was lost): clocking a byte on
                                # an idle bus would change SDA while SCL is high, a START or
                                # STOP nobody asked for. Refused (found by the formal check).
                                respond(error=1)
                            with m.Elif(p.op == I2COp.WRITE):
                                # Data MSB first, then a released bit for the device's ACK.
                                m.d.sync += [shreg.eq(Cat(Const(1, 1), p.data)), bit.eq(0)]
                                wait(t.low // 2)
                                m.next = "BIT_HOLD"
                            with m.Else():
                                # Eight released bits for the device's data, then our ACK/NACK.
                                m.d.sync += [shreg.eq(Cat(~p.ack, Const(0xFF, 8))), bit.eq(0)]
                                wait(t.low // 2)
                                m.next = "BIT_HOLD"


            self._bus_states(m, SimpleNamespace(clock_up=clock_up, wait=wait, timed=timed, t=t,
                timer=timer, scl=scl, abort=abort, reset_first=reset_first, respond=respond,
                then_start=then_start, bit=bit, recover=recover, sda=sda, aborted=aborted,
                held=held, sent=sent, shreg=shreg, rx=rx, op=op))

        return m

    def _bus_states(self, m, c):
        """The bus states of the FSM after IDLE: START (on an idle bus, or repeated),
        STOP, the bits of a byte and the stuck-bus recovery. ``c``: the controller's
        signals and helpers (``elaborate``)."""
        (clock_up, wait, timed, t, timer, scl, abort, reset_first, respond, then_start, bit,
         recover, sda, aborted, held, sent, shreg, rx, op) = (
            c.clock_up, c.wait, c.timed, c.t, c.timer, c.scl, c.abort, c.reset_first, c.respond,
            c.then_start, c.bit, c.recover, c.sda, c.aborted, c.held, c.sent, c.shreg, c.rx, c.op)
        # -- START on an idle bus: SDA falls while SCL is high ------------------------------
        with m.State("START_IDLE"):
            # A device may still hold SCL low (stretching past a time-out that aborted the
            # last transfer): wait for it, as long as a time-out. After an abort a device
            # may be mid-transfer: a START and a STOP first put every device back to idle.
            m.d.sync += timer.eq(timer - 1)
            with m.If(scl & ~sda):
                m.d.sync += recover.eq(0)
                m.next = "REC"
            with m.Elif(scl):
                with m.If(aborted):
                    m.d.sync += [aborted.eq(0), reset_first.eq(1)]
                m.next = "START_A"
            with m.Elif(timer == 0):
                abort(self.status.timeout)
        with m.State("START_A"):
            m.d.sync += self.pins.sda_oe.eq(1)
            wait(t.high)
            m.next = "START_B"
        with timed("START_B"):
            m.d.sync += [self.pins.scl_oe.eq(1), held.eq(1)]
            with m.If(reset_first):
                # the START of a START-STOP that resets the devices; then the real START
                m.d.sync += [reset_first.eq(0), then_start.eq(1)]
                wait(t.low // 2)
                m.next = "STOP_HOLD"
            with m.Else():
                m.d.sync += [self.status.timeout.eq(0), self.status.bus_stuck.eq(0),
                             self.status.arbitration.eq(0)]
                respond()

        # -- repeated START: SCL up with SDA released, set-up time, then a START ------------
        clock_up("RS", "RS_SETUP", t.low)
        with timed("RS_SETUP"):
            m.next = "START_A"

        # -- STOP: SDA low in the middle of SCL low, SCL up, then SDA up --------------------
        with timed("STOP_HOLD"):
            m.d.sync += self.pins.sda_oe.eq(1)
            wait(t.low - t.low // 2)
            m.next = "STOP_LOW"
        clock_up("STOP", "STOP_SETUP", t.high)
        with timed("STOP_SETUP"):
            m.d.sync += [self.pins.sda_oe.eq(0), held.eq(0)]
            wait(t.low)                  # bus-free time before the next START
            m.next = "STOP_FREE"
        with timed("STOP_FREE"):
            with m.If(then_start):
                m.d.sync += then_start.eq(0)
                m.next = "START_A"
            with m.Else():
                respond()

        # -- one bit: SDA set in the middle of SCL low, sampled at the end of SCL high ------
        with timed("BIT_HOLD"):
            m.d.sync += [self.pins.sda_oe.eq(~shreg[8]), sent.eq(shreg[8])]
            wait(t.low - t.low // 2)
            m.next = "BIT_LOW"
        clock_up("BIT", "BIT_HIGH", t.high)
        with timed("BIT_HIGH"):
            m.d.sync += [self.pins.scl_oe.eq(1), shreg.eq(shreg << 1), bit.eq(bit + 1)]
            with m.If(bit < 8):
                m.d.sync += rx.eq(Cat(sda, rx[:-1]))
            # A 1 we sent must read back as 1, except where the other side answers
            # (ACK of a WRITE, the data bits of a READ).
            is_ours = Mux(op.op == I2COp.WRITE, bit < 8, bit == 8)
            with m.If(sent & ~sda & is_ours):
                abort(self.status.arbitration)
            with m.Elif(bit == 8):
                respond(ack=~sda)
            with m.Else():
                wait(t.low // 2)
                m.next = "BIT_HOLD"

        # -- stuck-bus recovery: clock until SDA is released, then STOP ---------------------
        with m.State("REC"):
            m.d.sync += self.pins.scl_oe.eq(1)
            wait(t.low)
            m.next = "REC_LOW"
        clock_up("REC", "REC_HIGH", t.high)
        with timed("REC_HIGH"):
            m.d.sync += recover.eq(recover + 1)
            with m.If(sda):
                # Released: a STOP (SDA low during SCL low, then up), then the START.
                with m.If(self.status.recoveries != 15):
                    m.d.sync += self.status.recoveries.eq(self.status.recoveries + 1)
                m.d.sync += [self.pins.scl_oe.eq(1), held.eq(1), then_start.eq(1)]
                wait(t.low // 2)
                m.next = "STOP_HOLD"
            with m.Elif(recover == 8):
                abort(self.status.bus_stuck)
            with m.Else():
                m.next = "REC"
