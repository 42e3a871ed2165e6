"""I2C controller, formally: open drain, START/STOP only where meant, SCL timing, clock
stretching and its time-out, stuck-bus recovery, the stream rules.

The bus is modelled as open drain: each line is low if the controller (``*_oe``) or the device
pulls it. The device pulls SDA whenever it likes (an ACK, data, a stuck bus, another master) and
pulls SCL only while it is already low (clock stretching: a device cannot start a clock pulse).
"Never drives a line high" is structural: the controller's pins are output-enables only
(``I2CPinsSignature``), so the harness has nothing to drive high with.

Timing: the smallest the controller accepts (SCL low 4 cycles, high 2), time-out 5 cycles.
"""

import pytest
from amaranth import *
from amaranth.asserts import AnySeq
from amaranth.hdl import Assert, Assume, Cover

from mpu9250_ahrs.hdl.sensor.i2c_controller import I2CController, I2COp, I2CTiming

from .harness import Past, counter, harness_module
from .stream_contract import stream_input, stream_output


pytestmark = pytest.mark.formal

TIMING = I2CTiming(low=4, high=2, timeout=5)


def i2c_harness(t=TIMING, dut=None):
    m = harness_module()
    m.submodules.dut = dut = dut or I2CController(t)
    stream_input(m, dut.i_stream, "op")
    stream_output(m, dut.o_stream, "result")
    pins = dut.pins

    scl, sda = Signal(init=1), Signal(init=1)
    dev_scl, dev_sda = AnySeq(1), AnySeq(1)
    scl_was = Past(m, scl)
    # the device may keep SCL low, never pull it low while it is high
    m.d.comb += Assume(~dev_scl | ~scl_was | pins.scl_oe)
    m.d.comb += [scl.eq(~(pins.scl_oe | dev_scl)), sda.eq(~(pins.sda_oe | dev_sda)),
                 pins.scl_i.eq(scl), pins.sda_i.eq(sda)]

    # the operation being carried out: from its acceptance to its result
    take = dut.i_stream.valid & dut.i_stream.ready
    op = Signal(I2COp)
    busy = Signal()
    with m.If(take):
        m.d.sync += [op.eq(dut.i_stream.payload.op), busy.eq(1)]
    offered = dut.o_stream.valid & ~Past(m, dut.o_stream.valid)
    with m.If(offered):
        m.d.sync += busy.eq(0)

    scl_oe_was, sda_oe_was = Past(m, pins.scl_oe), Past(m, pins.sda_oe)
    pull, release = pins.scl_oe & ~scl_oe_was, ~pins.scl_oe & scl_oe_was
    low_for = counter(m, 4, count=pins.scl_oe, name="low_for")
    high_for = counter(m, 4, count=scl, name="high_for")
    stretched = counter(m, 4, count=busy & ~pins.scl_oe & ~scl, name="stretched")
    was_stretched = Signal()             # a device stretched SCL in this operation
    with m.If(take):
        m.d.sync += was_stretched.eq(0)
    with m.Elif(stretched >= 2):
        m.d.sync += was_stretched.eq(1)
    rises = Signal(5)                    # SCL released by the controller in this operation
    with m.If(take):
        m.d.sync += rises.eq(0)
    with m.Elif(release & (rises != 31)):
        m.d.sync += rises.eq(rises + 1)

    # SDA moves while SCL is high (a START or a STOP on the bus) only in a START or STOP
    # operation (a START's recovery STOP and reset START-STOP included), or as the release of
    # an aborted operation (a time-out can end as the device lets SCL go: SDA then rises, a
    # STOP, which also puts the devices back to idle)
    sda_moved_in_high = (pins.sda_oe != sda_oe_was) & scl & scl_was
    aborted = offered & dut.o_stream.payload.error & ~pins.sda_oe
    with m.If(sda_moved_in_high):
        m.d.comb += Assert((busy & ((op == I2COp.START) | (op == I2COp.STOP))) | aborted,
                           "start_stop_only")
    with m.If(release):
        m.d.comb += Assert(low_for >= t.low, "scl_low_time")
    with m.If(pull):
        m.d.comb += Assert(high_for >= t.high, "scl_high_time")
    # a stretched clock is waited for at most the time-out (plus the synchroniser), then the
    # operation ends with an error and the time-out flag
    m.d.comb += Assert(stretched <= t.timeout + 3, "stretch_bounded")
    with m.If(offered & (Past(m, stretched) >= t.timeout + 2)):
        m.d.comb += Assert(dut.o_stream.payload.error & dut.status.timeout, "timeout_reported")
    # recovery: at most nine clocks, then a STOP's clock, in one START operation
    with m.If(busy & (op == I2COp.START)):
        m.d.comb += Assert(rises <= 10, "recovery_clocks")

    m.d.comb += [
        Cover(offered & ~dut.o_stream.payload.error & (op == I2COp.WRITE) &
              dut.o_stream.payload.ack & was_stretched, "stretched_write_acked"),
        Cover(offered & dut.status.timeout, "timeout"),
        Cover(offered & (op == I2COp.START) & (dut.status.recoveries == 1) &
              ~dut.o_stream.payload.error, "recovered"),
    ]
    return m


# Depth: the longest operation is a START on a stuck bus: up to nine recovery clocks of
# low + high + 2 (synchroniser) = 8 cycles, a STOP and the START: about 100 cycles. A WRITE
# is 9 such clocks (about 75). 110 covers either from reset, with the harness's per-operation
# counts back to zero at each new operation.
@pytest.mark.slow
def test_i2c_properties(formal):
    formal(i2c_harness(), name="i2c_controller", mode="bmc", depth=110)


@pytest.mark.slow
def test_i2c_cover(formal):
    formal(i2c_harness(), name="i2c_cover", mode="cover", depth=110)


def test_i2c_fast_mode_minimums():
    """``for_clock`` meets the fast-mode minimums (1.3 µs low, 0.6 µs high) at the clocks used."""
    for clk in (4e6, 12e6, 48e6, 50e6):
        t = I2CTiming.for_clock(clk)
        assert t.low / clk >= 1.3e-6 and t.high / clk >= 0.6e-6
        assert clk / (t.low + t.high) <= 400e3
