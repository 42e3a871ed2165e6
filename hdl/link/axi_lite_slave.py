"""An AXI4-Lite slave for a soft CPU or an SoC bus: the last result, the driver's status and
counters, an interrupt, and the host's registers (engine, board, PWM) read and written through
the command channel's executor (``hdl/contract/axi_regs.py`` is the map)."""

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..contract.axi_regs import (AXI_ADDR_BITS, AXI_ENGINE_RESULT_WORDS, AXI_REGISTER_BASE,
                                 AXI_REGS, AXI_RESULT_WORDS)
from ..contract.commands import REGMAP_VERSION, RESULTS, SPACES
from ..engine.attitude_engine import PEEK_BASE, PEEKED
from ..engine.attitude_result import AttitudeFlags
from ..engine.host_port import address_in
from ..sensor.driver_status import DriverStatus
from .frame_types import TelemetryCounters
from .register_executor import RegisterOp, RegisterRequest, RegisterResponse


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


# The block's first words are the engine's registers that hold the result (``PEEKED``, from a
# multiple of 16), and the block starts at a multiple of 16 words: a word's engine address is
# its low four bits under the registers' base's high ones, no table
_BLOCK = _word_address(AXI_RESULT_WORDS[0])
assert AXI_ENGINE_RESULT_WORDS == len(PEEKED) and _BLOCK % 16 == 0 and PEEK_BASE % 16 == 0


class AXILiteSlave(wiring.Component):
    """The register map of ``hdl/contract/axi_regs.py`` on an AXI4-Lite port.

    Members
        ``axi`` (slave, ``AXILiteSignature``): the bus. One transaction of each kind at a time;
            the address and data of a write are taken independently (either first), each
            ready while its holding register is empty (the data's, and no read's request
            waits); nothing reaches a valid from a ready
            in the same cycle (the channels' valids and readies are registers).
        ``irq`` (out): IRQ bit 0 and IRQ_ENABLE bit 0.
        ``done`` (in): a result was taken (sets IRQ bit 0).
        ``busy`` (in): the engine's ``busy``: each rise (an update or the reset program
            starts) and each fall (it ends) counts in SEQUENCE.
        ``counter`` (in, 32), ``flags`` (in, ``AttitudeFlags``): the engine's result's (its
            ``results.payload``: COUNTER and FLAGS' ``overrun`` and ``filter`` change as an
            update starts, its other flags as it ends, and all hold between updates), read as
            COUNTER and FLAGS. QUAT0 .. BIAS2 are read from the engine's registers
            through its port, which answers only between updates: no copy of the result here.
            A block read with SEQUENCE the same before and after is one result's.
        ``status`` (in, ``DriverStatus``), ``counters`` (in, ``TelemetryCounters``): shown
            as read-only words.
        ``request`` (out, stream of ``RegisterRequest``) / ``response`` (in, stream of
            ``RegisterResponse``, always taken: its payload is read as the request is taken,
            the executor's way to end a request): to a ``RegisterExecutor`` (the command
            decoder's, its second port): the host's registers (``AXI_REGISTER_BASE`` and up:
            space, then address) and QUAT0 .. BIAS2, one request at a time (a read's or a
            write's), by the command channel's rules: ``ok`` answers OKAY, ``refused`` SLVERR,
            ``bad_address`` DECERR.
    Latency: a local word's read answers two cycles after its address is taken; a host
    register's (and QUAT0 .. BIAS2) when the executor answers (a few cycles; for the engine's,
    its port opens only between updates: up to an update, ``report``'s
    ``cycles_per_update``). SEQUENCE counts a start or an end a cycle after COUNTER or FLAGS
    change with it; reads are three cycles apart at least, so none sees one without the other.
    """

    def __init__(self):
        # the channels' states, named here so that ``invariant`` can state how they relate
        self._w_request = Signal()      # a write's request offered to the executor
        self._aw_full = Signal()        # a write's address taken
        self._w_full = Signal()         # a write's data taken
        self._r_decode = Signal()       # a read address taken, decoded next
        self._r_request = Signal()      # a read's request offered to the executor
        super().__init__({
            "axi": In(AXILiteSignature()),
            "irq": Out(1),
            "done": In(1),
            "busy": In(1),
            "counter": In(32),
            "flags": In(AttitudeFlags),
            "status": In(DriverStatus),
            "counters": In(TelemetryCounters),
            "request": Out(stream.Signature(RegisterRequest)),
            "response": In(stream.Signature(RegisterResponse)),
        })

    def invariant(self):
        """What holds in every state a reset reaches: a response waits only with its
        channel idle (no request offered, no read being decoded), a write's request is offered
        only with its address and data held, and one request at a time."""
        axi = self.axi
        return ~(axi.bvalid & self._w_request) & \
            (~self._w_request | (self._aw_full & self._w_full)) & \
            ~(axi.rvalid & (self._r_decode | self._r_request)) & \
            ~(self._r_decode & self._r_request) & ~(self._w_request & self._r_request)

    def elaborate(self, platform):
        m = Module()
        pending = Signal()          # IRQ bit 0
        enable = Signal()           # IRQ_ENABLE bit 0
        m.d.comb += [self.irq.eq(pending & enable), self.response.ready.eq(1)]
        # the request: a write's while one is offered, else a read's (both held still)
        w_addr, wdata = Signal(AXI_ADDR_BITS - 2), Signal(32)
        r_addr = Signal(AXI_ADDR_BITS - 2)
        w_space, w_reg = _register(w_addr)
        r_space, r_reg = _register(r_addr)
        in_block = (r_addr[4:] == _BLOCK >> 4) & (r_addr[:4] < AXI_ENGINE_RESULT_WORDS)
        req = self.request.payload
        w = self._w_request
        m.d.comb += [
            self.request.valid.eq(w | self._r_request),
            req.op.eq(Mux(w, RegisterOp.WRITE, RegisterOp.READ)), req.value.eq(wdata),
            # QUAT0 .. BIAS2: the engine's registers that hold them
            req.space.eq(Mux(w, w_space, Mux(in_block, SPACES["engine"], r_space))),
            req.addr.eq(Mux(w, w_reg, Mux(in_block, Cat(r_addr[:4], C(PEEK_BASE >> 4, 4)),
                                          r_reg)))]
        resp = Mux(self.response.payload.result == RESULTS["ok"], RESP_OKAY,
                   Mux(self.response.payload.result == RESULTS["refused"], RESP_SLVERR,
                       RESP_DECERR))
        self._writes(m, pending, enable, w_addr, wdata, resp)
        self._reads(m, pending, enable, r_addr, in_block, resp)
        with m.If(self.done):               # after a clear: a result in its cycle raises it
            m.d.sync += pending.eq(1)
        return m

    def _writes(self, m, pending, enable, addr, wdata, resp):
        axi = self.axi
        aw_full, w_full = self._aw_full, self._w_full
        # a write's data is the request's value, a read's too (unused there, but a request's
        # payload holds still while it waits): no data is taken while a read's request waits
        w_open = ~w_full & ~self._r_request
        m.d.comb += [axi.awready.eq(~aw_full), axi.wready.eq(w_open)]
        with m.If(axi.awvalid & ~aw_full):
            m.d.sync += [aw_full.eq(1), addr.eq(axi.awaddr[2:])]
        with m.If(axi.wvalid & w_open):
            m.d.sync += [w_full.eq(1), wdata.eq(axi.wdata)]
        remote = addr >= (AXI_REGISTER_BASE >> 2)
        w_request = self._w_request
        with m.If(~w_request):
            with m.If(aw_full & w_full & ~axi.bvalid):
                with m.If(remote):
                    # the executor is the read's while it has a request there (or one is
                    # about to be: a read decoded now goes first)
                    with m.If(~self._r_request & ~self._r_decode):
                        m.d.sync += w_request.eq(1)
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
        with m.Elif(self.request.ready):
            m.d.sync += [axi.bvalid.eq(1), aw_full.eq(0), w_full.eq(0), axi.bresp.eq(resp),
                         w_request.eq(0)]
        with m.If(axi.bvalid & axi.bready):
            m.d.sync += axi.bvalid.eq(0)

    def _mapped(self, addr):
        """1 where ``addr`` (a word address) is one of the map's local words."""
        return address_in(addr[:8], [a >> 2 for a, _, _ in AXI_REGS.values()]) & \
            (addr < (AXI_REGISTER_BASE >> 2))

    def _reads(self, m, pending, enable, addr, in_block, resp):
        axi = self.axi
        decode, requested = self._r_decode, self._r_request
        busy = decode | requested   # an address taken, its answer not yet given
        m.d.comb += axi.arready.eq(~busy & ~axi.rvalid)
        sequence = Signal(16)
        was_busy = Signal()
        # both edges: COUNTER changes as an update starts, FLAGS' bits as it ends (issue #58's
        # notes: a block whose FLAGS were read before the end and its QUATs after, counted at
        # the start only, held SEQUENCE)
        m.d.sync += [was_busy.eq(self.busy), sequence.eq(sequence + (self.busy ^ was_busy))]
        words = {"VERSION": C((0xA71 << 20) | REGMAP_VERSION, 32),
                 "STATUS": self.status.as_value(), "IRQ": pending, "IRQ_ENABLE": enable,
                 "FILTERED": self.counters.filtered, "LOST": self.counters.lost,
                 "SEQUENCE": sequence,
                 "COUNTER": self.counter, "FLAGS": self.flags.as_value()}
        remote = (addr >= (AXI_REGISTER_BASE >> 2)) | in_block
        with m.If(~busy):
            with m.If(axi.arvalid & ~axi.rvalid):
                m.d.sync += [decode.eq(1), addr.eq(axi.araddr[2:])]
        with m.Elif(decode):
            with m.If(remote):
                # after a write's request (one at a time): the read's waits for its answer
                with m.If(~self._w_request):
                    m.d.sync += [decode.eq(0), requested.eq(1)]
            with m.Else():
                word = Signal(32)
                with m.Switch(addr):
                    for name, value in words.items():
                        with m.Case(_word_address(name)):
                            m.d.comb += word.eq(value)
                m.d.sync += [axi.rvalid.eq(1), axi.rdata.eq(word), decode.eq(0),
                             axi.rresp.eq(Mux(self._mapped(addr), RESP_OKAY, RESP_DECERR))]
        with m.Elif(self.request.ready):
            m.d.sync += [axi.rvalid.eq(1), axi.rdata.eq(self.response.payload.value),
                         axi.rresp.eq(resp), requested.eq(0)]
        with m.If(axi.rvalid & axi.rready):
            m.d.sync += axi.rvalid.eq(0)


def _register(addr):
    """A word address at ``AXI_REGISTER_BASE`` and up as the host's register it names: its
    space (the 1 KiB window above the local words: 0 the engine's, 1 the board's, 2 the PWM
    block's) and address."""
    return addr[8:] - (AXI_REGISTER_BASE >> 10), addr[:8]
