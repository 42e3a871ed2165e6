"""The balance controller's safety, proven by k-induction (issue #57): whatever the register
writes, results, faults, periods, commands and the arming pin do, no output is on while it is
disarmed, and the duty is 0 from the cycle after it disarms."""

import pytest
from amaranth import *
from amaranth.asserts import AnySeq
from amaranth.hdl import Assert

from mpu9250_ahrs.hdl.control.balance_controller import BalanceController

from .harness import Past, harness_module


pytestmark = pytest.mark.formal


def safety_harness():
    m = harness_module()
    # a small PWM prescale: the outputs cycle within the proof's depth
    m.submodules.dut = dut = BalanceController(clk_freq=1e6)
    for port in ("done", "angles", "bias", "sample_taken", "gyro", "fault", "period", "kick",
                 "arm_pin"):
        signal = getattr(dut, port)
        m.d.comb += signal.eq(AnySeq(len(Value.cast(signal))))
    bus = dut.bus
    m.d.comb += [bus.addr.eq(AnySeq(8)), bus.w_data.eq(AnySeq(32)), bus.w_en.eq(AnySeq(1))]
    was_armed = Past(m, dut.armed)
    m.d.comb += Assert(dut.armed | (dut.pwm == 0), "no_output_disarmed")
    started = Signal()
    m.d.sync += started.eq(1)
    with m.If(started & ~was_armed):
        m.d.comb += Assert(dut.duty == 0, "no_duty_disarmed")
    return m


def test_no_output_while_disarmed(formal):
    m = safety_harness()
    formal(m, name="balance_safety", mode="prove", depth=6)
