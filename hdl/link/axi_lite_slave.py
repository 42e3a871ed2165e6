"""An AXI4-Lite slave for a soft CPU or an SoC bus: the last result, the driver's status and
counters, an interrupt, and the engine's registers read and written (``hdl/contract/axi_regs.py``
is the map)."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..contract.axi_regs import (AXI_ADDR_BITS, AXI_ENGINE_BASE, AXI_REGS, AXI_RESULT_WORDS)
from ..contract.commands import REGMAP_VERSION
from ..engine.attitude_isa import REG_BITS
from ..engine.attitude_result import Attitude
from ..engine.config_write import ConfigWrite
from ..engine.host_port import address_in, write_allowed
from ..sensor.driver_status import DriverStatus
from .frame_types import TelemetryCounters


__all__ = ["AXILiteSignature", "AXILiteSlave", "RESP_OKAY", "RESP_SLVERR", "RESP_DECERR"]

RESP_OKAY, RESP_SLVERR, RESP_DECERR = 0b00, 0b10, 0b11


class AXILiteSignature(wiring.Signature):
    """AXI4-Lite, 32-bit data, ``addr_bits`` of address, from the master's side (a slave's
    port is its flip): the five channels with their AMBA names."""

    def __init__(self, addr_bits=AXI_ADDR_BITS):
        super().__init__({
            "awvalid": Out(1), "awready": In(1), "awaddr": Out(addr_bits), "awprot": Out(3),
            "wvalid": Out(1), "wready": In(1), "wdata": Out(32), "wstrb": Out(4),
            "bvalid": In(1), "bready": Out(1), "bresp": In(2),
            "arvalid": Out(1), "arready": In(1), "araddr": Out(addr_bits), "arprot": Out(3),
            "rvalid": In(1), "rready": Out(1), "rdata": In(32), "rresp": In(2),
        })


def _word_address(name):
    return AXI_REGS[name][0] >> 2


class AXILiteSlave(wiring.Component):
    """The register map of ``hdl/contract/axi_regs.py`` on an AXI4-Lite port.

    Parameters
        ``writable``: the engine addresses a write may change (``HOST_WRITABLE``).
    Members
        ``axi`` (slave, ``AXILiteSignature``): the bus. One transaction of each kind at a time;
            the address and data of a write are taken independently (either first), each
            ready while its holding register is empty; nothing reaches a valid from a ready
            in the same cycle (the channels' valids and readies are registers).
        ``irq`` (out): IRQ bit 0 and IRQ_ENABLE bit 0.
        ``result`` (in, stream of ``Attitude``): the results (a ``StreamTap``'s), always
            taken: its payload is the result block. ``hold`` (out): the block held, from a
            read of QUAT0 to a read of FLAGS or of any word outside the block (the tap keeps
            its copy and counts what it cannot show: ``dropped``).
        ``status`` (in, ``DriverStatus``), ``counters`` (in, ``TelemetryCounters``),
        ``dropped``, ``refused`` (in, 16): shown as read-only words.
        ``cfg`` (out, stream of ``ConfigWrite``), ``cfg_read`` (out, stream of addresses),
        ``cfg_read_data`` (in, stream of words): the engine's register port. Every engine
            write goes to the engine (which refuses and counts what it must); the answer is
            SLVERR for one it refuses (``write_allowed``: its own rule).
    Latency: a local word's read answers two cycles after its address is taken; an engine
    register's when the engine's port answers (a few cycles; the engine takes its port only
    between updates, so up to an update, ``report``'s ``cycles_per_update``).
    """

    def __init__(self, writable):
        self.writable = frozenset(writable)
        # the channels' states, named here so that ``invariant`` can state how they relate
        self._w_engine = Signal()       # an engine write offered on ``cfg``
        self._aw_full = Signal()        # a write's address taken
        self._w_full = Signal()         # a write's data taken
        self._r_decode = Signal()       # a read address taken, decoded next
        self._r_engine = Signal()       # an engine read waiting for its word
        super().__init__({
            "axi": In(AXILiteSignature()),
            "irq": Out(1),
            "result": In(stream.Signature(Attitude)),
            "hold": Out(1),
            "status": In(DriverStatus),
            "counters": In(TelemetryCounters),
            "dropped": In(16),
            "refused": In(16),
            "cfg": Out(stream.Signature(ConfigWrite)),
            "cfg_read": Out(stream.Signature(REG_BITS)),
            "cfg_read_data": In(stream.Signature(signed(32))),
        })

    def invariant(self):
        """What holds in every state a reset reaches: a response waits only with its
        channel idle (no engine write offered, no read being decoded or answered), and an
        engine write is offered only with its address and data held."""
        axi = self.axi
        return ~(axi.bvalid & self._w_engine) & \
            (~self._w_engine | (self._aw_full & self._w_full)) & \
            ~(axi.rvalid & (self._r_decode | self._r_engine)) & ~(self._r_decode & self._r_engine)

    def elaborate(self, platform):
        m = Module()
        pending = Signal()          # IRQ bit 0
        enable = Signal()           # IRQ_ENABLE bit 0
        m.d.comb += [self.irq.eq(pending & enable), self.result.ready.eq(1)]
        self._writes(m, pending, enable)
        self._reads(m, pending, enable)
        with m.If(self.result.valid):       # after a clear: a result in its cycle raises it
            m.d.sync += pending.eq(1)
        return m

    def _writes(self, m, pending, enable):
        axi = self.axi
        aw_full, w_full = self._aw_full, self._w_full
        addr = Signal(AXI_ADDR_BITS - 2)
        wdata = Signal(32)
        m.d.comb += [axi.awready.eq(~aw_full), axi.wready.eq(~w_full)]
        with m.If(axi.awvalid & ~aw_full):
            m.d.sync += [aw_full.eq(1), addr.eq(axi.awaddr[2:])]
        with m.If(axi.wvalid & ~w_full):
            m.d.sync += [w_full.eq(1), wdata.eq(axi.wdata)]
        engine = addr >= (AXI_ENGINE_BASE >> 2)
        reg = addr[:REG_BITS]
        m.d.comb += [self.cfg.payload.addr.eq(reg), self.cfg.payload.data.eq(wdata)]
        allowed = write_allowed(reg, wdata, self.writable)
        w_engine = self._w_engine
        with m.If(~w_engine):
            with m.If(aw_full & w_full & ~axi.bvalid):
                with m.If(engine):
                    m.d.sync += w_engine.eq(1)
                with m.Else():
                    with m.If(addr == _word_address("IRQ")):
                        with m.If(wdata[0]):
                            m.d.sync += pending.eq(0)
                        m.d.sync += axi.bresp.eq(RESP_OKAY)
                    with m.Elif(addr == _word_address("IRQ_ENABLE")):
                        m.d.sync += [enable.eq(wdata[0]), axi.bresp.eq(RESP_OKAY)]
                    with m.Elif(self._mapped(addr)):
                        m.d.sync += axi.bresp.eq(RESP_SLVERR)       # a read-only word
                    with m.Else():
                        m.d.sync += axi.bresp.eq(RESP_DECERR)
                    m.d.sync += [axi.bvalid.eq(1), aw_full.eq(0), w_full.eq(0)]
        with m.Else():
            m.d.comb += self.cfg.valid.eq(1)
            with m.If(self.cfg.ready):
                m.d.sync += [axi.bvalid.eq(1), aw_full.eq(0), w_full.eq(0),
                             axi.bresp.eq(Mux(allowed, RESP_OKAY, RESP_SLVERR)),
                             w_engine.eq(0)]
        with m.If(axi.bvalid & axi.bready):
            m.d.sync += axi.bvalid.eq(0)

    def _mapped(self, addr):
        """1 where ``addr`` (a word address) is one of the map's local words."""
        return address_in(addr[:8], [a >> 2 for a, _, _ in AXI_REGS.values()]) & \
            (addr < (AXI_ENGINE_BASE >> 2))

    def _reads(self, m, pending, enable):
        axi = self.axi
        held = Signal()             # the result block held for a read
        decode, waiting = self._r_decode, self._r_engine
        busy = decode | waiting     # an address taken, its answer not yet given
        addr = Signal(AXI_ADDR_BITS - 2)
        m.d.comb += axi.arready.eq(~busy & ~axi.rvalid)
        result = self.result.payload
        words = {"VERSION": C((0xA71 << 20) | REGMAP_VERSION, 32),
                 "STATUS": self.status.as_value(), "IRQ": pending, "IRQ_ENABLE": enable,
                 "FILTERED": self.counters.filtered, "LOST": self.counters.lost,
                 "DROPPED": self.dropped, "REFUSED": self.refused,
                 **dict(zip(AXI_RESULT_WORDS,
                            [*result.quat, *result.angles, *result.bias, result.counter,
                             result.flags.as_value()]))}
        engine = addr >= (AXI_ENGINE_BASE >> 2)
        m.d.comb += self.cfg_read.payload.eq(addr[:REG_BITS])
        m.d.comb += self.hold.eq(held)
        with m.If(~busy):
            with m.If(axi.arvalid & ~axi.rvalid):
                m.d.sync += [decode.eq(1), addr.eq(axi.araddr[2:])]
        with m.Elif(decode):
            with m.If(engine):
                m.d.comb += self.cfg_read.valid.eq(1)
                with m.If(self.cfg_read.ready):
                    m.d.sync += [decode.eq(0), waiting.eq(1)]
            with m.Else():
                word = Signal(32)
                with m.Switch(addr):
                    for name, value in words.items():
                        with m.Case(_word_address(name)):
                            m.d.comb += word.eq(value)
                m.d.sync += [axi.rvalid.eq(1), axi.rdata.eq(word), decode.eq(0),
                             axi.rresp.eq(Mux(self._mapped(addr), RESP_OKAY, RESP_DECERR))]
                # the result block: held from its first word to its last, or to a read
                # of a word outside it (a read given up)
                first = _word_address(AXI_RESULT_WORDS[0])
                last = _word_address(AXI_RESULT_WORDS[-1])
                with m.If(addr == first):
                    # held from this cycle: a result the tap would take now is not
                    # taken (the word read now is the block's)
                    m.d.comb += self.hold.eq(1)
                    m.d.sync += held.eq(1)
                with m.Elif((addr == last) | (addr < first) | (addr > last)):
                    m.d.sync += held.eq(0)
        with m.Elif(waiting):
            m.d.comb += self.cfg_read_data.ready.eq(1)
            with m.If(self.cfg_read_data.valid):
                m.d.sync += [axi.rvalid.eq(1), axi.rdata.eq(self.cfg_read_data.payload),
                             axi.rresp.eq(RESP_OKAY), waiting.eq(0)]
        with m.If(axi.rvalid & axi.rready):
            m.d.sync += axi.rvalid.eq(0)
