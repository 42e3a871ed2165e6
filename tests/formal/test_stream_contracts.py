"""The stream rules on every stream output of every component, proven by k-induction, and
rule 3 checked on the netlist.

Rules 1 and 2 (``valid`` held until a transfer, payload still while ``valid & ~ready``): each
component stands alone (``contract_harness``): every input free, every input stream from any
producer that keeps the rules, every output stream's rules asserted against any consumer.
Induction (depth 8) proves them for every reachable state, however long the run. The
composites (``MPU9250Driver``, ``SensorFrontEnd``) are checked as a whole too, so their inner
connections are covered as built.

Rule 3 (``valid`` does not depend combinationally on ``ready``; every block here promises it):
``comb_paths.valid_ready_paths`` walks each component's flattened netlist back from every
output stream's ``valid`` and fails on any ``ready`` input it reaches.

``test_contract_bites`` / ``test_comb_path_bites``: a frame arbiter that lets a frame byte's
payload change under ``valid`` (the torn payload of a filter reset during framing, found by
hand before) fails the proof; a block whose ``valid`` waits for ``ready`` fails rule 3.
"""

import pytest
from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import Out

from mpu9250_ahrs.hdl.engine.attitude_engine import AttitudeEngine
from mpu9250_ahrs.hdl.engine.register_map import HOST_WRITABLE
from mpu9250_ahrs.hdl.sensor.bring_up_sequencer import (BringUpSequencer, SelfTestWaits,
                                                        bring_up_program)
from mpu9250_ahrs.hdl.link.command_decoder import CommandDecoder
from mpu9250_ahrs.hdl.engine.config_port_arbiter import ConfigPortArbiter
from mpu9250_ahrs.hdl.link.frame_arbiter import FrameArbiter
from mpu9250_ahrs.hdl.engine.host_port import HostPort
from mpu9250_ahrs.hdl.sensor.i2c_controller import I2CController, I2CTiming
from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config, MPU9250Driver
from mpu9250_ahrs.hdl.sensor.read_leveller import ReadLeveller
from mpu9250_ahrs.hdl.sensor.register_port import I2CRegisterPort, SPIRegisterPort
from mpu9250_ahrs.hdl.sensor.register_port_arbiter import RegisterPortArbiter
from mpu9250_ahrs.hdl.link.rewindable_fifo import RewindableFIFO
from mpu9250_ahrs.hdl.link.stream_tap import StreamTap
from mpu9250_ahrs.hdl.link.axi_lite_slave import AXILiteSlave
from mpu9250_ahrs.hdl.link.register_executor import RegisterExecutor
from mpu9250_ahrs.hdl.sensor.sample_offer import SampleOffer
from mpu9250_ahrs.hdl.sensor.sample_reader import SampleReader
from mpu9250_ahrs.hdl.sensor.sensor_frontend import SensorFrontEnd
from mpu9250_ahrs.hdl.sensor.spi_controller import SPIController, SPITiming
from mpu9250_ahrs.hdl.link.frame_types import AttitudeFrame, Reply, SensorFrame
from mpu9250_ahrs.hdl.link.telemetry import TelemetryFramer
from mpu9250_ahrs.hdl.board.top import result_fetch, sample_borrow
from mpu9250_ahrs.hdl.link.telemetry_scheduler import TelemetryScheduler
from mpu9250_ahrs.hdl.link.uart_rx import UARTReceiver

from .comb_paths import valid_ready_paths
from .stream_contract import contract_harness


DEPTH = 8
COMPONENTS = {
    "spi_controller": lambda: SPIController(SPITiming(slow_half=2, fast_half=1, cs_hold=1,
                                                       cs_gap=2)),
    "i2c_controller": lambda: I2CController(I2CTiming(low=4, high=2, timeout=5)),
    "uart_rx": lambda: UARTReceiver(divisor=4),
    # with a trained rate (issue #58): its sample delay any, changing any time
    "spi_controller_trained": lambda: SPIController(SPITiming(
        slow_half=2, fast_half=1, cs_hold=1, cs_gap=2, trained_low=2, trained_high=1,
        max_sample_delay=3)),
    "read_leveller": lambda: ReadLeveller(max_sample_delay=3),
    "spi_register_port": SPIRegisterPort,
    "i2c_register_port": I2CRegisterPort,
    "register_port_arbiter": RegisterPortArbiter,
    "bring_up_sequencer": lambda: BringUpSequencer(
        bring_up_program(MPU9250Config(), 20, 10, 5, SelfTestWaits(6, 4, 5)),
        accepted_who_am_i=(0x71,),
        poll_cycles=30),
    "sample_reader": lambda: SampleReader(period_cycles=100, first_timeout_cycles=200,
                                          timeout_cycles=400, mag_timeout_periods=3),
    "sample_offer": SampleOffer,
    "mpu9250_driver": lambda: MPU9250Driver(clk_freq=1e6),
    "telemetry_framer": TelemetryFramer,
    "attitude_framer": lambda: TelemetryFramer(AttitudeFrame, 0x02, buffered=True,
                                               short=(0x01, SensorFrame)),
    # as the core builds it: the result's words fetched from the engine during the copy, the
    # sample borrowed from it
    "attitude_framer_fetch": lambda: TelemetryFramer(AttitudeFrame, 0x02, buffered=True,
                                                     short=(0x01, SensorFrame),
                                                     fetch=result_fetch(),
                                                     borrow=sample_borrow()),
    "sensor_frontend_spi": lambda: SensorFrontEnd(clk_freq=1e6),
    "sensor_frontend_i2c": lambda: SensorFrontEnd(clk_freq=1e6,
                                                  config=MPU9250Config(wiring="i2c")),
    "attitude_engine": AttitudeEngine,
    # as the core builds it: the sample's sensor fields read from the sample store
    "attitude_engine_store": lambda: AttitudeEngine(sample_store=True),
    "reply_framer": lambda: TelemetryFramer(Reply, 0x81),
    "telemetry_scheduler": TelemetryScheduler,
    "frame_arbiter": lambda: FrameArbiter(2),
    "host_port": HostPort,
    "rewindable_fifo": lambda: RewindableFIFO(depth=8),
    "stream_tap": lambda: StreamTap(8),
    "axi_lite_slave": AXILiteSlave,
    # two front ends, as the core with the AXI slave builds it
    "register_executor": lambda: RegisterExecutor(writable=HOST_WRITABLE, version=0x00020000,
                                                  ports=2),
    "config_port_arbiter": ConfigPortArbiter,
    "command_decoder": lambda: CommandDecoder(writable=HOST_WRITABLE, version=0x00020000,
                                              timeout=50),
}


# Inputs the documentation says hold still while a stream's transfer waits: the engine holds
# the sample and status its result came from until the result is taken.
HELD = {"telemetry_scheduler": {"sample": "results", "status": "results"}}
# What a component's documentation asks of its user in every cycle: the rewindable FIFO is
# rewound only with the byte it offers taken, or none offered; the engine's port (behind the
# config-port arbiter) takes no read address while a word waits; a register executor's front
# end keeps its request until it is taken (``documented_use``).
ASSUME = {"register_executor": lambda c: c.documented_use(),
          "rewindable_fifo":
          lambda c: ~(c.rewind & c.r_stream.valid & ~c.r_stream.ready),
          "config_port_arbiter":
          lambda c: ~(c.cfg_read.ready & c.cfg_read_data.valid)}


@pytest.mark.formal
@pytest.mark.parametrize("name", COMPONENTS)
def test_stream_contract(formal, name):
    formal(contract_harness(COMPONENTS[name](), HELD.get(name), ASSUME.get(name)),
           name=f"contract_{name}",
           mode="prove", depth=DEPTH)


@pytest.mark.formal
@pytest.mark.parametrize("name", COMPONENTS)
def test_valid_independent_of_ready(tmp_path, name):
    assert valid_ready_paths(COMPONENTS[name](), str(tmp_path)) == {}


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


class WaitingProducer(wiring.Component):
    """A producer that breaks rule 3: it offers a byte only when the consumer is ready."""
    o_stream: Out(stream.Signature(8))

    def elaborate(self, platform):
        m = Module()
        count = Signal(8)
        m.d.comb += [self.o_stream.valid.eq(self.o_stream.ready & count[0]),
                     self.o_stream.payload.eq(count)]
        m.d.sync += count.eq(count + 1)
        return m


@pytest.mark.formal
def test_comb_path_bites(tmp_path):
    assert valid_ready_paths(WaitingProducer(), str(tmp_path)) == {"o_stream": ["o_stream__ready"]}
