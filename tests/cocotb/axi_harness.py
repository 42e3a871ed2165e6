"""The AXI4-Lite slave as the core builds it (``AXILiteSlave`` behind a ``StreamTap``), on the
real attitude engine's register port, with results made here: result k has every word k (its
quaternion, angles, bias and counter), so a block read from two results shows two values.
Exported to Verilog for ``test_axi_lite.py`` (cocotb, ``cocotbext-axi``). The core's own
results need a sensor on its pins; this harness gives results at a chosen rate instead."""

from amaranth import *
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out, connect, flipped

from mpu9250_ahrs.hdl.engine.attitude_engine import AttitudeEngine
from mpu9250_ahrs.hdl.engine.attitude_result import Attitude
from mpu9250_ahrs.hdl.engine.register_map import HOST_WRITABLE
from mpu9250_ahrs.hdl.link.axi_lite_slave import AXILiteSignature, AXILiteSlave
from mpu9250_ahrs.hdl.link.stream_tap import StreamTap


class AXIHarness(wiring.Component):
    """``s_axi`` (slave), ``irq``; a result every ``period`` cycles (``made``: how many);
    ``snapshot_per_word``: the mutation the test must catch (the block not held)."""

    def __init__(self, period=97, snapshot_per_word=False):
        self.period = period
        self.snapshot_per_word = snapshot_per_word
        super().__init__({"s_axi": In(AXILiteSignature()), "irq": Out(1), "made": Out(32)})

    def elaborate(self, platform):
        m = Module()
        m.submodules.engine = engine = AttitudeEngine()
        m.submodules.tap = tap = StreamTap(Attitude)
        m.submodules.slave = slave = AXILiteSlave(HOST_WRITABLE)
        timer = Signal(range(self.period))
        result = Signal(Attitude)
        k = self.made
        m.d.comb += [result.quat[i].eq(k) for i in range(4)]
        m.d.comb += [result.angles[i].eq(k) for i in range(3)]
        m.d.comb += [result.bias[i].eq(k) for i in range(3)]
        m.d.comb += result.counter.eq(k)
        m.d.sync += timer.eq(Mux(timer == self.period - 1, 0, timer + 1))
        with m.If(timer == self.period - 1):
            m.d.sync += k.eq(k + 1)
        m.d.comb += [tap.taken.eq(timer == self.period - 1), tap.payload.eq(result),
                     tap.hold.eq(0 if self.snapshot_per_word else slave.hold),
                     slave.dropped.eq(tap.dropped), slave.refused.eq(engine.cfg_refused),
                     self.irq.eq(slave.irq)]
        connect(m, tap.o, slave.result)
        connect(m, flipped(self.s_axi), slave.axi)
        connect(m, slave.cfg, engine.cfg)
        connect(m, slave.cfg_read, engine.cfg_read)
        connect(m, engine.cfg_read_data, slave.cfg_read_data)
        return m


def verilog(path, **kwargs):
    from amaranth.back import verilog as back
    top = AXIHarness(**kwargs)
    with open(path, "w") as f:
        f.write(back.convert(top, name="axi_harness", emit_src=False))
