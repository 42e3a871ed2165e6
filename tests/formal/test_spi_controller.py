"""SPI controller, formally: the bus timing, the framing of transactions, the stream rules.

The producer offers any bytes (any ``fast``, any ``last``) whenever it likes, the consumer takes
results whenever it likes; CIPO is wired to COPI (a loop-back), so each received byte must be
the byte sent. Timing with small numbers of cycles (the logic is the same for any count; the
counters are only narrower).
"""

import pytest
from amaranth import *
from amaranth.hdl import Assert, Assume, Cover

from mpu9250_ahrs.hdl.sensor.spi_controller import SPIController, SPITiming

from .harness import Past, counter, harness_module
from .stream_contract import stream_input, stream_output


pytestmark = pytest.mark.formal

TIMING = SPITiming(slow_half=3, fast_half=2, cs_hold=2, cs_gap=3, cipo_delay=1)
# the smallest timing: SCLK levels of 2 (slow) and 1 (fast) cycles
SMALL = SPITiming(slow_half=2, fast_half=1, cs_hold=1, cs_gap=2, cipo_delay=0)
# an odd fast period, as ``SPITiming.for_clock`` makes at 48 MHz: a low level of 2, a high of 1
ODD = SPITiming(slow_half=2, fast_half=2, fast_high=1, cs_hold=1, cs_gap=2, cipo_delay=0)
# with a trained rate (issue #58): its levels ODD's fast ones, at the sample delay that reads a
# loop-back (0, ``spi_harness`` assumes it), beside SMALL's fast rate
TRAINED = SPITiming(slow_half=2, fast_half=1, cs_hold=1, cs_gap=2, cipo_delay=0,
                    trained_low=2, trained_high=1, max_sample_delay=2)


def spi_harness(t=TIMING, dut=None, *, counting=True):
    m = harness_module()
    m.submodules.dut = dut = dut or SPIController(t)
    stream_input(m, dut.i_stream, "cmd")
    stream_output(m, dut.o_stream, "rx")
    pins = dut.pins
    m.d.comb += pins.cipo.eq(pins.copi)

    sclk, cs_n, copi = pins.sclk, pins.cs_n, pins.copi
    sclk_was, cs_was, copi_was = Past(m, sclk), Past(m, cs_n), Past(m, copi)
    fell, rose = sclk_was & ~sclk, ~sclk_was & sclk
    cs_fell, cs_rose = cs_was & ~cs_n, ~cs_was & cs_n

    # The transaction as the harness saw it offered.
    take = dut.i_stream.valid & dut.i_stream.ready
    p = dut.i_stream.payload
    fast = Signal()                     # the rate of the transaction
    trained = Signal()                  # ... the trained one
    nbytes = Signal(4)                  # bytes accepted in it (mod 16)
    rises = Signal(7)                   # rising SCLK edges in it (mod 128)
    offers = Signal(4)                  # results offered in it
    ended = Signal()                    # a byte with ``last`` was accepted
    with m.If(take):
        m.d.sync += [nbytes.eq(nbytes + 1), ended.eq(p.last)]
        with m.If(cs_n):
            m.d.sync += [fast.eq(p.fast), nbytes.eq(1), rises.eq(0), offers.eq(0)]
            if t.has_trained:
                m.d.sync += trained.eq(p.fast & p.trained)
    if t.has_trained:
        m.d.comb += Assume(dut.sample_delay == 0)
    with m.If(rose):
        m.d.sync += rises.eq(rises + 1)
    offer = dut.o_stream.valid & ~Past(m, dut.o_stream.valid)
    with m.If(offer & counting):
        m.d.sync += offers.eq(offers + 1)
    # The bytes accepted whose results are not offered yet, oldest first: the next byte may be
    # accepted while the one before it is still being captured (SCLK without a pause).
    sent = Array([Signal(8, name="sent0"), Signal(8, name="sent1")])
    in_flight = Signal(2)
    pop = offer & counting
    with m.If(pop):
        m.d.sync += sent[0].eq(sent[1])
    with m.If(take):
        m.d.sync += sent[in_flight - pop].eq(p.data)
    m.d.sync += in_flight.eq(in_flight + take - pop)
    # the transaction's SCLK levels as the harness saw its rate chosen; k-induction cannot
    # relate the harness's copy to the controller's, so the proof uses the shorter of the two
    low = Mux(fast, t.fast_half, t.slow_half) if counting else min(t.fast_half, t.slow_half)
    high = Mux(fast, t.fast_high, t.slow_half) if counting else min(t.fast_high, t.slow_half)
    if t.has_trained:
        low = Mux(trained, t.trained_low, low) if counting else min(low, t.trained_low)
        high = Mux(trained, t.trained_high, high) if counting else min(high, t.trained_high)

    # cycles since each event (0 in the cycle after it)
    level = counter(m, 5, clear=sclk != sclk_was, name="level")   # SCLK held
    since_cs = counter(m, 5, clear=cs_fell, name="since_cs")
    since_rise = counter(m, 5, clear=rose, name="since_rise")
    cs_high = counter(m, 5, clear=cs_rose, init=31, name="cs_high")
    first_fall = Signal()               # no falling edge yet in this transaction
    with m.If(cs_fell):
        m.d.sync += first_fall.eq(1)
    with m.If(fell):
        m.d.sync += first_fall.eq(0)

    m.d.comb += [
        # SCLK idles high: with CS inactive it is high (so it cannot toggle)
        Assert(~cs_n | sclk, "sclk_idles_high"),
        Assert(~(cs_fell & (sclk != sclk_was)), "no_edge_with_cs"),
        # COPI changes only with a falling SCLK edge: stable for a whole level either side of
        # each rising edge
        Assert((copi == copi_was) | fell, "copi_stable"),
    ]
    with m.If((sclk != sclk_was) & ~cs_fell):
        # the level that just ended (low before a rising edge, high before a falling one)
        # lasted at least the configured cycles (level counts the cycles before this one: a
        # level of n cycles reads n - 1 here, plus this one)
        m.d.comb += Assert(level + 1 >= Mux(rose, low, high), "sclk_level")
    with m.If(fell & first_fall):
        m.d.comb += Assert(since_cs + 1 >= low, "cs_setup")
    with m.If(cs_rose):
        m.d.comb += Assert(since_rise + 1 >= t.cs_hold, "cs_hold")
    with m.If(cs_rose & counting):
        m.d.comb += [
            # whole transactions: it ends after the byte marked last, and every byte accepted
            # was clocked out (8 rising edges) and its result offered
            Assert(ended, "ends_on_last"),
            Assert(rises == (nbytes * 8)[:7], "eight_clocks_per_byte"),
            Assert(offers == nbytes, "one_result_per_byte"),
        ]
    with m.If(cs_fell):
        m.d.comb += Assert(cs_high + 1 >= t.cs_gap, "cs_gap")
    with m.If(take & ~cs_n & counting):
        # a byte accepted with CS active continues the transaction: there was no last yet
        m.d.comb += Assert(~ended, "no_byte_after_last")
    with m.If(offer & counting):
        m.d.comb += Assert(dut.o_stream.payload == sent[0], "loopback")

    m.d.comb += [
        Cover(cs_rose & (nbytes == 3) & fast, "three_byte_burst_fast"),
        Cover(cs_rose & (nbytes == 1) & ~fast, "one_byte_slow"),
    ]
    return m


# Bus timing and transactions: k-induction does not close (the harness's per-transaction state,
# rate included, cannot be related to the controller's), so they are checked from reset to depth 64 with the smallest
# timing (SCLK levels of 2 and 1 cycles). 64 cycles hold a three-byte fast transaction (1 + 1 +
# 3 × (16 + 3) + 1 + 2 = 62): its first byte (CS setup), a middle byte (a byte after a byte)
# and its last (CS hold, gap), or a one-byte slow one; every longer transaction repeats the
# middle byte's states, with the consumer stalling any number of cycles in between.
@pytest.mark.slow
def test_spi_transactions(formal):
    formal(spi_harness(SMALL), name="spi_transactions", mode="bmc", depth=64)


@pytest.mark.slow
def test_spi_cover(formal):
    formal(spi_harness(SMALL), name="spi_cover", mode="cover", depth=64)


# The odd period (a high level shorter than the low one) from reset to depth 64: a two-byte fast
# transaction (1 + 2 + 2 × (24 + 3) + 1 + 2 = 60) or a one-byte slow one.
@pytest.mark.slow
def test_spi_transactions_odd_period(formal):
    formal(spi_harness(ODD), name="spi_transactions_odd", mode="bmc", depth=64)


# Issue #58: with a trained rate, either rate in any transaction (``fast`` and ``trained`` as
# the producer likes), from reset to depth 64.
@pytest.mark.slow
def test_spi_transactions_trained(formal):
    formal(spi_harness(TRAINED), name="spi_transactions_trained", mode="bmc", depth=64)
