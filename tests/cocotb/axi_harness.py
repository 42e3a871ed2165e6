"""The AXI4-Lite slave as the core wires it (``AHRSCore._axi``: the result's words from the real
attitude engine's registers, its counter and flags from its payload, SEQUENCE from its
``busy``, the host's registers through a ``RegisterExecutor`` on the engine's port; no PWM
block: its space answers DECERR), with samples made here: sample k, every ``period`` cycles, turns at a rate that
changes with k, so every result's words differ from the one's before. Exported to Verilog for
``test_axi_lite.py`` (cocotb, ``cocotbext-axi``); ``result`` and ``done`` show the bench each
result as the engine gives it. The core's own samples need a sensor on its pins; this harness
gives them at a chosen rate instead."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out, connect, flipped

from mpu9250_ahrs.hdl.engine.attitude_engine import AttitudeEngine
from mpu9250_ahrs.hdl.engine.attitude_result import Attitude
from mpu9250_ahrs.hdl.engine.register_map import HOST_WRITABLE
from mpu9250_ahrs.hdl.link.axi_lite_slave import AXILiteSignature, AXILiteSlave
from mpu9250_ahrs.hdl.link.register_executor import RegisterExecutor

VERSION = 0x0002ABCD            # the build word the board's VERSION reads here


class AXIHarness(wiring.Component):
    """``s_axi`` (slave), ``irq``; a sample every ``period`` cycles (``made``: how many);
    ``result`` (the engine's payload) and ``done`` (a result taken). ``sequence`` what
    SEQUENCE counts the rises of: ``"busy"`` (the core's), or the mutations the test must
    catch: ``None`` (it never moves), ``"done"`` (results, not starts: COUNTER and FLAGS
    change before it does)."""

    def __init__(self, period=1100, sequence="busy"):
        self.period = period
        self.sequence = sequence
        super().__init__({"s_axi": In(AXILiteSignature()), "irq": Out(1), "made": Out(32),
                          "result": Out(Attitude), "done": Out(1)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.engine = engine = AttitudeEngine()
        m.submodules.slave = slave = AXILiteSlave()
        m.submodules.executor = executor = RegisterExecutor(writable=HOST_WRITABLE,
                                                            version=VERSION)
        timer = Signal(range(self.period))
        k = self.made
        sample = engine.samples.payload
        m.d.comb += [sample.gyro[0].eq(k[:6] * 40 - 1200), sample.gyro[1].eq(-50),
                     sample.gyro[2].eq(k[2:7] * 30), sample.accel[0].eq(k[:4] * 8),
                     sample.accel[2].eq(2048), sample.counter.eq(k),
                     sample.flags.data_ready.eq(1)]
        m.d.sync += timer.eq(Mux(timer == self.period - 1, 0, timer + 1))
        with m.If(timer == self.period - 1):
            m.d.sync += engine.samples.valid.eq(1)
        with m.If(engine.samples.valid & engine.samples.ready):
            m.d.sync += [engine.samples.valid.eq(0), k.eq(k + 1)]
        done = engine.results.valid & engine.results.ready
        m.d.comb += [engine.results.ready.eq(1), self.result.eq(engine.results.payload),
                     self.done.eq(done), slave.done.eq(done),
                     slave.busy.eq({"busy": engine.busy, "done": done, None: 0}[self.sequence]),
                     slave.counter.eq(engine.results.payload.counter),
                     slave.flags.eq(engine.results.payload.flags),
                     self.irq.eq(slave.irq)]
        connect(m, flipped(self.s_axi), slave.axi)
        connect(m, slave.request, executor.request[0])
        connect(m, executor.response[0], slave.response)
        connect(m, executor.cfg, engine.cfg)
        connect(m, executor.cfg_read, engine.cfg_read)
        connect(m, engine.cfg_read_data, executor.cfg_read_data)
        return m


def verilog(path, **kwargs):
    from amaranth.back import verilog as back
    top = AXIHarness(**kwargs)
    with open(path, "w") as f:
        f.write(back.convert(top, name="axi_harness", emit_src=False))
