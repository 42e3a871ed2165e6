"""The stream rules on every stream output of every component, proven by k-induction.

Each component stands alone (``contract_harness``): every input free, every input stream from
any producer that keeps the rules, every output stream's rules asserted against any consumer.
Induction (depth 8) proves them for every reachable state, however long the run.

Not finished (issue #14 stays open): the components marked ``xfail`` below give a
counterexample that is not yet analysed (a real violation, or a free input the component's
documentation says is held still, such as the framer's ``seq``); the third rule (``valid`` not
depending combinationally on ``ready``) has no check yet.

``test_contract_bites``: a copy of the frame arbiter that lets a frame byte's payload change
under ``valid`` (the torn payload of a filter reset during framing, found by hand before) fails.
"""

import pytest

from mpu9250_ahrs.hdl.command_decoder import CommandDecoder, Reply
from mpu9250_ahrs.hdl.frame_arbiter import FrameArbiter
from mpu9250_ahrs.hdl.attitude_program import HOST_WRITABLE
from mpu9250_ahrs.hdl.host_port import HostPort
from mpu9250_ahrs.hdl.i2c_controller import I2CController, I2CTiming
from mpu9250_ahrs.hdl.mpu9250_driver import MPU9250Driver
from mpu9250_ahrs.hdl.register_port import I2CRegisterPort, SPIRegisterPort
from mpu9250_ahrs.hdl.register_port_arbiter import RegisterPortArbiter
from mpu9250_ahrs.hdl.sample_reader import SampleReader
from mpu9250_ahrs.hdl.spi_controller import SPIController, SPITiming
from mpu9250_ahrs.hdl.telemetry import TelemetryFramer
from mpu9250_ahrs.hdl.telemetry_scheduler import TelemetryScheduler
from mpu9250_ahrs.hdl.uart_rx import UARTReceiver

from .stream_contract import contract_harness


DEPTH = 8
COMPONENTS = {
    "spi_controller": lambda: SPIController(SPITiming(slow_half=2, fast_half=1, cs_hold=1,
                                                       cs_gap=2)),
    "i2c_controller": lambda: I2CController(I2CTiming(low=4, high=2, timeout=5)),
    "uart_rx": lambda: UARTReceiver(divisor=4),
    "spi_register_port": SPIRegisterPort,
    "i2c_register_port": I2CRegisterPort,
    "register_port_arbiter": RegisterPortArbiter,
    "sample_reader": lambda: SampleReader(period_cycles=100, first_timeout_cycles=200,
                                          timeout_cycles=400, mag_timeout_periods=3),
    "mpu9250_driver": lambda: MPU9250Driver(clk_freq=1e6),
    "telemetry_framer": TelemetryFramer,
    "reply_framer": lambda: TelemetryFramer(Reply, 0x81),
    "telemetry_scheduler": TelemetryScheduler,
    "frame_arbiter": lambda: FrameArbiter(2),
    "host_port": HostPort,
    "command_decoder": lambda: CommandDecoder(writable=HOST_WRITABLE, version=0x00020000,
                                              timeout=50),
}


PROVEN = {"spi_controller", "uart_rx", "host_port", "command_decoder"}


@pytest.mark.formal
@pytest.mark.parametrize("name", [
    name if name in PROVEN else pytest.param(name, marks=pytest.mark.xfail(
        strict=True, reason="counterexample at depth 8 not yet analysed (issue #14 open)"))
    for name in COMPONENTS])
def test_stream_contract(formal, name):
    formal(contract_harness(COMPONENTS[name]()), name=f"contract_{name}", mode="prove",
           depth=DEPTH)


class TornArbiter(FrameArbiter):
    """The frame arbiter with a fault put in: while a byte waits, the payload shows the
    other input's byte when that one is valid (a multiplexer that follows the wrong select)."""
    def elaborate(self, platform):
        m = super().elaborate(platform)
        with m.If(self.i1.valid & self.o_stream.valid & ~self.o_stream.ready):
            m.d.comb += self.o_stream.payload.eq(self.i1.payload.data ^ 1)
        return m


@pytest.mark.formal
def test_contract_bites(formal):
    formal(contract_harness(TornArbiter(2)), name="contract_torn_arbiter", mode="prove",
           depth=2, expect="fail")
