"""Read levelling (issue #58): the CIPO sample point of the SPI controller's trained rate found
on the board it runs on.

A building block, tested on its own against the MPU9250 model (``tests/hdl/test_read_leveller.py``)
and formally for its stream contract; not wired into the driver yet (bring-up does not run it,
the sample bursts stay at the safe rate): issue #58 is open."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from ..contract import mpu9250_regs as R
from .register_port import RegisterPortSignature


__all__ = ["ReadLeveller", "LEVEL_BYTES", "LEVEL_REPEATS"]


# The bytes compared: the accelerometer's six, from ACCEL_XOUT_H (a sensor register: the part
# takes fast reads there only). Their values are whatever the part measures; each trained read
# is checked against a read of the same bytes at the safe fast rate just before it (the
# registers change once a sample period, a few hundred times the pair's microseconds: a pair
# a sample falls between fails, and the repeats make a tap pass only on all of them). Bytes
# all 0x00 or all 0xFF prove nothing (a shifted read of them is the same): such a pair fails.
# (Bytes of a known, varied pattern in the fast-read range, the AK8963's WIA read into
# EXT_SENS_DATA by a slave of the I2C master, are the way to make the scan independent of
# what the part measures: not built yet.)
LEVEL_BYTES = 6
LEVEL_REPEATS = 4


class ReadLeveller(wiring.Component):
    """Scans the trained rate's sample delays and keeps the middle of the widest run that reads
    right, if it leaves ``margin`` delays on both sides; else the trained rate stays off.

    Parameters
        ``max_sample_delay``: the SPI controller's (``SPITiming.with_trained``).
        ``margin``: whole cycles the chosen delay keeps from the run's ends (the I/O budget's
            margin, 10 ns, rounded up: 1 at 48 MHz): a run of at least 2·``margin`` + 1.
    Members
        ``port`` (out, a register port's client, ``RegisterPortSignature`` flipped): its reads.
        ``sample_delay`` (out): to the SPI controller: the delay scanned, then the one chosen.
        ``start`` (in): a pulse: scan (while not ``busy``).
        ``busy``, ``done`` (out): scanning; a pulse as it ends.
        ``trained`` (out): the scan found a run wide enough; ``sample_delay`` is its middle.
        ``first``, ``last`` (out): the widest run's delays (``first`` > ``last``: none).
    A tap passes when each of ``LEVEL_REPEATS`` pairs reads the same ``LEVEL_BYTES`` at the safe
    fast rate and then at the trained rate at that tap.
    Latency: (``max_sample_delay`` + 1) · ``LEVEL_REPEATS`` pairs of reads (at 48 MHz about 1
    µs a read: 0.1 ms). Throughput: one scan at a time.
    """

    def __init__(self, *, max_sample_delay, margin=1):
        if max_sample_delay < 1 or margin < 0:
            raise ValueError("ReadLeveller: max_sample_delay >= 1 and margin >= 0")
        self.max_sample_delay = max_sample_delay
        self.margin = margin
        span = range(max_sample_delay + 2)
        super().__init__({
            "port": Out(RegisterPortSignature().flip()),
            "sample_delay": Out(range(max_sample_delay + 1)),
            "start": In(1),
            "busy": Out(1),
            "done": Out(1),
            "trained": Out(1),
            "first": Out(span),
            "last": Out(span),
        })

    def elaborate(self, platform):
        m = Module()
        port = self.port
        tap = Signal(range(self.max_sample_delay + 1))
        repeat = Signal(range(LEVEL_REPEATS))
        reference = Signal(8 * LEVEL_BYTES, reset_less=True)     # the safe read's bytes
        index = Signal(range(LEVEL_BYTES + 1))                   # bytes of this read so far
        differs = Signal()                  # a byte of the trained reads of this tap differed,
                                            # or a safe read's bytes were all 0x00 or 0xFF
        run_first = Signal.like(self.first)     # the run of passing taps that ends here
        run_length = Signal(range(self.max_sample_delay + 2))
        best_length = Signal.like(run_length)
        command_taken = Signal()            # the read's command was taken: its bytes come

        m.d.comb += [port.rx.ready.eq(1), port.rsp.ready.eq(1),
                     port.cmd.payload.reg.eq(R.ACCEL_XOUT_H),
                     port.cmd.payload.length.eq(LEVEL_BYTES),
                     port.cmd.payload.fast.eq(1)]
        m.d.sync += self.done.eq(0)

        def read(trained, next_state):
            """Offer the read until taken, then take its bytes and response."""
            m.d.comb += port.cmd.payload.trained.eq(trained)
            with m.If(~command_taken):
                m.d.comb += port.cmd.valid.eq(1)
                with m.If(port.cmd.ready):
                    m.d.sync += [command_taken.eq(1), index.eq(0)]
            # (bytes and a response count only for a command taken: the command once offered
            # stays offered until then, whatever comes in)
            with m.If(command_taken & port.rx.valid):
                byte = reference.word_select(index, 8)
                if trained:
                    with m.If(port.rx.payload != byte):
                        m.d.sync += differs.eq(1)
                else:
                    m.d.sync += byte.eq(port.rx.payload)
                m.d.sync += index.eq(index + 1)
            with m.If(command_taken & port.rsp.valid):
                m.d.sync += command_taken.eq(0)
                m.next = next_state

        with m.FSM():
            with m.State("IDLE"):
                with m.If(self.start):
                    m.d.sync += [self.busy.eq(1), self.trained.eq(0), tap.eq(0), repeat.eq(0),
                                 differs.eq(0), run_length.eq(0), best_length.eq(0),
                                 self.first.eq(1), self.last.eq(0),
                                 self.sample_delay.eq(0)]
                    m.next = "SAFE"
            with m.State("SAFE"):
                read(False, "TRAINED")
            with m.State("TRAINED"):
                flat = (reference == 0) | reference.all()
                with m.If(flat):
                    m.d.sync += differs.eq(1)
                read(True, "NEXT")
            with m.State("NEXT"):
                with m.If(repeat != LEVEL_REPEATS - 1):
                    m.d.sync += repeat.eq(repeat + 1)
                    m.next = "SAFE"
                with m.Else():
                    # the tap's verdict: a passing tap extends the run, a failing one ends it
                    passed = ~differs
                    length = Mux(passed, run_length + 1, 0)
                    start = Mux(passed & (run_length == 0), tap, run_first)
                    m.d.sync += [run_length.eq(length), run_first.eq(start),
                                 repeat.eq(0), differs.eq(0)]
                    with m.If(passed & (length > best_length)):
                        m.d.sync += [best_length.eq(length), self.first.eq(start),
                                     self.last.eq(tap)]
                    with m.If(tap == self.max_sample_delay):
                        m.next = "CHOOSE"
                    with m.Else():
                        m.d.sync += [tap.eq(tap + 1), self.sample_delay.eq(tap + 1)]
                        m.next = "SAFE"
            with m.State("CHOOSE"):
                # the middle of the widest run (its lower middle), if the margin fits
                wide = best_length >= 2 * self.margin + 1
                m.d.sync += [self.busy.eq(0), self.done.eq(1), self.trained.eq(wide),
                             self.sample_delay.eq(Mux(wide, (self.first + self.last) >> 1, 0))]
                m.next = "IDLE"
        return m
