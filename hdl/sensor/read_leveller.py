"""Read levelling (issue #58): the CIPO sample point of the SPI controller's trained rate found
on the board it runs on, and watched while it is used."""

from types import SimpleNamespace

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..contract import mpu9250_regs as R
from .register_port import RegisterPortSignature


__all__ = ["ReadLeveller", "LEVEL_BYTES", "LEVEL_REPEATS", "LEVEL_ATTEMPTS"]


# The bytes compared: the accelerometer's six, from ACCEL_XOUT_H (a sensor register: the part
# takes fast reads there only). Their values are whatever the part measures: each trained read
# is compared with the safe fast rate's reads of the same bytes just before and just after it.
# The registers change once a sample period; if the two safe reads differ, the part sampled
# between them and the pair proves nothing: it is void and made again (at most
# ``LEVEL_ATTEMPTS`` pairs per tap: a tap that cannot get ``LEVEL_REPEATS`` fails). The safe
# read after one pair is the one before the next, so a tap of ``LEVEL_REPEATS`` pairs takes
# that many reads at each rate. Bytes all 0x00 or all 0xFF prove nothing (a shifted read of them
# is the same): such a pair fails.
LEVEL_BYTES = 6
LEVEL_REPEATS = 4
LEVEL_ATTEMPTS = 3 * LEVEL_REPEATS


class ReadLeveller(wiring.Component):
    """Scans the trained rate's sample delays and keeps the middle of the widest run that reads
    right, if it leaves ``margin`` delays on both sides; else the trained rate stays off. Then,
    asked to, checks the two guard delays ``margin`` either side of the middle.

    Parameters
        ``max_sample_delay``: the SPI controller's (``SPITiming.with_trained``).
        ``margin``: whole cycles the chosen delay keeps from the run's ends (the I/O budget's
            margin, 10 ns, rounded up: 1 at 48 MHz): a run of at least 2·``margin`` + 1.
    Members
        ``port`` (out, a register port's client, ``RegisterPortSignature`` flipped): its reads.
        ``sample_delay`` (out): the delay of its own trained reads (the tap scanned or
            checked); the SPI controller must use it for those transactions and ``centre`` for
            everyone else's (``MPU9250Driver`` chooses by the port's owner).
        ``centre`` (out): the delay chosen (0 until a scan trains).
        ``start`` (in): a pulse: scan (while not ``busy``).
        ``check`` (in): a pulse: check the guard delays (while not ``busy``, once ``trained``):
            one pair at ``centre`` - ``margin``, then one at ``centre`` + ``margin``.
        ``busy``, ``done`` (out): scanning or checking; a pulse as either ends.
        ``trained`` (out): the last scan found a run wide enough; ``centre`` is its middle.
        ``check_failed`` (out): the last check saw a guard delay read wrong (valid with
            ``done`` after a check, held until the next).
        ``first``, ``last`` (out): the widest run's delays (``first`` > ``last``: none).
    A scanned tap passes when ``LEVEL_REPEATS`` pairs (a trained read between two safe fast
    reads that agree) read alike; a guard passes on one such pair.
    Latency: a scan takes (``max_sample_delay`` + 1) · ``LEVEL_REPEATS`` reads at each rate
    and one more at the safe rate, plus a pair for each void one (at 48 MHz about 0.5 ms); a
    check four or five reads (about 30 µs). Throughput: one at a time.
    """

    def __init__(self, *, max_sample_delay, margin=1):
        if max_sample_delay < 1 or margin < 0:
            raise ValueError("ReadLeveller: max_sample_delay >= 1 and margin >= 0")
        self.max_sample_delay = max_sample_delay
        self.margin = margin
        span = range(max_sample_delay + 2)
        delays = range(max_sample_delay + 1)
        super().__init__({
            "port": Out(RegisterPortSignature().flip()),
            "sample_delay": Out(delays),
            "centre": Out(delays),
            "start": In(1),
            "check": In(1),
            "busy": Out(1),
            "done": Out(1),
            "trained": Out(1),
            "check_failed": Out(1),
            "first": Out(span),
            "last": Out(span),
        })

    def elaborate(self, platform):
        m = Module()
        port = self.port
        tap = self.sample_delay
        checking = Signal()                 # guard delays, not a scan
        repeat = Signal(range(LEVEL_REPEATS + 1))       # pairs counted at this tap
        attempts = Signal(range(LEVEL_ATTEMPTS + 1))    # pairs made at this tap
        # the last safe read's bytes, turned a byte at a time as each read's bytes come (its
        # first byte always in the low 8 bits when a read begins): a shift register, no index
        reference = Signal(8 * LEVEL_BYTES, reset_less=True)
        zeros, ones = Signal(), Signal()    # the safe read so far is all 0x00 / all 0xFF
        flat = Signal()                     # the last safe read was
        primed = Signal()                   # a trained read is waiting for its second safe one
        changed = Signal()                  # this safe read differs from the last
        pair_differs = Signal()             # the trained read differed from the safe one
        differs = Signal()                  # a counted pair of this tap differed
        run_first = Signal.like(self.first)     # the run of passing taps that ends here
        run_length = Signal(range(self.max_sample_delay + 2))
        best_length = Signal.like(run_length)
        command_taken = Signal()            # the read's command was taken: its bytes come
        top = self.max_sample_delay

        m.d.comb += [port.rx.ready.eq(1), port.rsp.ready.eq(1),
                     port.cmd.payload.reg.eq(R.ACCEL_XOUT_H),
                     port.cmd.payload.length.eq(LEVEL_BYTES),
                     port.cmd.payload.fast.eq(1)]
        m.d.sync += self.done.eq(0)

        read = self._reads(m, SimpleNamespace(
            command_taken=command_taken, reference=reference, zeros=zeros, ones=ones,
            flat=flat, changed=changed, pair_differs=pair_differs))

        def begin(checking_, first_tap):
            m.d.sync += [self.busy.eq(1), checking.eq(checking_), tap.eq(first_tap),
                         repeat.eq(0), attempts.eq(0), differs.eq(0), primed.eq(0),
                         changed.eq(0)]

        with m.FSM():
            with m.State("IDLE"):
                with m.If(self.start):
                    begin(0, 0)
                    m.d.sync += [self.trained.eq(0), run_length.eq(0), best_length.eq(0),
                                 self.first.eq(1), self.last.eq(0), self.centre.eq(0)]
                    m.next = "SAFE"
                with m.Elif(self.check & self.trained):
                    begin(1, self.centre - self.margin)
                    m.d.sync += self.check_failed.eq(0)
                    m.next = "SAFE"
            with m.State("SAFE"):
                with m.If(read(False)):
                    m.d.sync += [changed.eq(0), pair_differs.eq(0), primed.eq(1)]
                    m.next = "TRAINED"
                    with m.If(primed):
                        # the pair before counts if the part did not sample under it
                        m.d.sync += attempts.eq(attempts + 1)
                        with m.If(~changed):
                            m.d.sync += [repeat.eq(repeat + 1),
                                         differs.eq(differs | pair_differs)]
                        m.next = "VERDICT"
            with m.State("TRAINED"):
                with m.If(flat):
                    m.d.sync += pair_differs.eq(1)
                with m.If(read(True)):
                    m.next = "SAFE"
            with m.State("VERDICT"):
                need = Mux(checking, 1, LEVEL_REPEATS)
                with m.If((repeat != need) & (attempts != LEVEL_ATTEMPTS)):
                    m.next = "TRAINED"          # another pair at this tap
                with m.Else():
                    passed = ~differs & (repeat == need)
                    m.d.sync += [repeat.eq(0), attempts.eq(0), differs.eq(0)]
                    with m.If(checking):
                        with m.If(~passed):
                            m.d.sync += self.check_failed.eq(1)
                        with m.If(tap == self.centre + self.margin):
                            m.next = "END"
                        with m.Else():
                            m.d.sync += tap.eq(self.centre + self.margin)
                            m.next = "TRAINED"
                    with m.Else():
                        # a passing tap extends the run, a failing one ends it
                        length = Mux(passed, run_length + 1, 0)
                        start = Mux(passed & (run_length == 0), tap, run_first)
                        m.d.sync += [run_length.eq(length), run_first.eq(start)]
                        with m.If(passed & (run_length >= best_length)):    # length > best
                            m.d.sync += [best_length.eq(length), self.first.eq(start),
                                         self.last.eq(tap)]
                        with m.If(tap == top):
                            m.next = "CHOOSE"
                        with m.Else():
                            m.d.sync += tap.eq(tap + 1)
                            m.next = "TRAINED"
            with m.State("CHOOSE"):
                # the middle of the widest run (its lower middle), if the margin fits
                wide = best_length >= 2 * self.margin + 1
                centre = Mux(wide, (self.first + self.last) >> 1, 0)
                m.d.sync += [self.trained.eq(wide), self.centre.eq(centre)]
                m.next = "END"
            with m.State("END"):
                m.d.sync += [self.busy.eq(0), self.done.eq(1)]
                m.next = "IDLE"
        return m

    def _reads(self, m, n):
        """The reads' common part: ``read(trained)`` offers a read (the safe fast rate, or the
        trained one at ``sample_delay``) until taken, then takes its bytes, comparing each
        with the reference (``n``: the signals it shares with ``elaborate``); it returns the
        response's condition (the read is over)."""
        port = self.port
        (command_taken, reference, zeros, ones, flat, changed, pair_differs) = (
            n.command_taken, n.reference, n.zeros, n.ones, n.flat, n.changed, n.pair_differs)

        def read(trained):
            m.d.comb += port.cmd.payload.trained.eq(trained)
            with m.If(~command_taken):
                m.d.comb += port.cmd.valid.eq(1)
                with m.If(port.cmd.ready):
                    m.d.sync += [command_taken.eq(1), zeros.eq(1), ones.eq(1)]
            # (bytes and a response count only for a command taken: the command once offered
            # stays offered until then, whatever comes in)
            byte, head = port.rx.payload, reference[:8]
            with m.If(command_taken & port.rx.valid):
                with m.If(byte != head):
                    m.d.sync += (pair_differs if trained else changed).eq(1)
                # a safe read's byte replaces the one it was compared with; a trained read's
                # turns the reference round
                m.d.sync += reference.eq(Cat(reference[8:], head if trained else byte))
                if not trained:
                    m.d.sync += [zeros.eq(zeros & (byte == 0)), ones.eq(ones & (byte == 0xFF))]
            over = command_taken & port.rsp.valid
            with m.If(over):
                m.d.sync += command_taken.eq(0)
                if not trained:
                    m.d.sync += flat.eq(zeros | ones)
            return over
        return read
