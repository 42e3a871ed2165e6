"""Register executor: the host's register reads and writes (engine, board, PWM), checked by the
one set of rules and counted, for the front ends that parse them: the UART's command decoder
and the AXI4-Lite slave."""


import operator
from functools import reduce

from amaranth import *
from amaranth.lib import data, enum, stream, wiring
from amaranth.lib.wiring import In, Out

from ..contract.commands import BOARD_REGS, REGMAP_VERSION, RESULTS, SPACES
from ..engine.attitude_isa import REG_BITS
from ..engine.config_write import ConfigWrite
from ..engine.host_port import address_in, write_allowed
from ..sensor.driver_status import ReadLevelStatus, SelfTestStatus
from .board_bus import BoardBusSignature
from .event_counters import EventCounters


__all__ = ["RegisterOp", "RegisterRequest", "RegisterResponse", "RegisterExecutor",
           "COMMAND_STATS", "COUNTED", "COUNTER_WORDS", "counter_word"]


# The command channel's counters (16 bits each, saturating, in the executor's
# ``EventCounters``), in the order of their board registers (CMD_DISCARDED ... CMD_REFUSED):
COMMAND_STATS = (
    "discarded",    # bytes outside any frame (hunting for the sync pattern)
    "crc_errors",   # frames whose CRC did not match
    "malformed",    # too long, cut off (no byte for ``timeout`` cycles), bad type or length
    "ok",           # requests done (either front end's)
    "refused",      # requests refused (read-only, out of range, no address; either's)
)
# The board registers counted in the ``EventCounters``, the receiver's two and the sample
# reader's early samples included, and its words: a power of two, so that a board address less
# CMD_DISCARDED's, cut to its low bits, is the word (``counter_word``)
COUNTED = ("RX_FRAMING_ERRORS", "RX_OVERRUNS", *(f"CMD_{name.upper()}" for name in COMMAND_STATS),
           "RATE_ERRORS")
COUNTER_WORDS = 8
# RATE_ERRORS's address would share RX_FRAMING_ERRORS's word: it has the one word left
RATE_ERRORS_WORD = 5


def counter_word(name):
    """A counted board register's word in the counters' RAM: its address less CMD_DISCARDED's,
    modulo ``COUNTER_WORDS`` (the receiver's two, before it, are words 6 and 7; the discarded
    bytes, which come fastest, word 0: the first served), but RATE_ERRORS's, word 5. A read
    names its word with its address's low bits (``RegisterExecutor._counters``)."""
    if name == "RATE_ERRORS":
        return RATE_ERRORS_WORD
    return (BOARD_REGS[name] - BOARD_REGS["CMD_DISCARDED"]) % COUNTER_WORDS


assert sorted(counter_word(name) for name in COUNTED) == list(range(COUNTER_WORDS))


class RegisterOp(enum.Enum, shape=2):
    READ = 0
    WRITE = 1
    ANSWER = 2      # no access: answered with the request's own result, address and value


class RegisterRequest(data.Struct):
    """A register access: ``op``; the register, ``space`` (``SPACES``) and ``addr``; a write's
    ``value`` (an ANSWER's value and address are echoed, its ``result`` given)."""
    op: RegisterOp
    space: 8
    addr: 8
    value: 32
    result: 8


class RegisterResponse(data.Struct):
    """The answer: ``result`` (``RESULTS``), the address (space in the high byte) and the value:
    a read's word, a write's value echoed (the fields of a ``Reply`` frame)."""
    result: 8
    addr: 16
    value: 32


class RegisterExecutor(wiring.Component):
    """Executes register requests, one at a time, from ``ports`` front ends.

    The rules, once for every front end: an engine write the engine would refuse (not
    ``writable``, a CONTROL word with no meaning: ``write_allowed``) is answered ``refused``
    without being sent; an engine read or write waits for the engine's port. The board's
    registers (space 0x01, ``BOARD_REGS``) read their sources; RAW_MODE alone is written; the
    others refuse a write; an address outside the map is ``bad_address``. The PWM block's
    (space 0x02) and the balance controller's (0x03): through their buses, refused as they
    say (``ok``), ``bad_address`` if the
    build has none. Each answer counts in CMD_OK or CMD_REFUSED (any result but ``ok``), and
    an ``ok`` pulses ``kick`` (the PWM watchdog: a front end stuck sending refused requests is
    as good as a silent one).

    Parameters
        ``writable``: engine addresses a host may write (``HOST_WRITABLE``).
        ``version``: the version/build word VERSION reads.
        ``ports`` (1): front ends; the lowest waiting is served first, a request keeps the
            executor until its response is taken.
    Members
        ``request`` (in, ``ports`` streams of ``RegisterRequest``): taken (``ready``) when
            done, with its response then offered: the payload must hold still meanwhile (the
            stream rule).
        ``response`` (out, ``ports`` streams of ``RegisterResponse``): held until taken.
        ``cfg``, ``cfg_read``, ``cfg_read_data``: to the engine's register port.
        ``pwm``, ``control`` (out, ``BoardBusSignature``): the PWM block's registers (space
            0x02) and the balance controller's (0x03).
        ``raw_mode`` (out): RAW_MODE bit 0. ``kick`` (out): a pulse per ``ok``.
        ``discarded``, ``crc_errors``, ``malformed`` (in): the command decoder's pulses;
        ``rx_framing_error``, ``rx_overrun`` (in): the receiver's; ``early_sample`` (in): the
            sample reader's (RATE_ERRORS): counted in ``counters``.
        ``counters``: the ``EventCounters`` of the ``COUNTED`` board registers (word
            ``counter_word(name)``), its ``ram`` for ``report`` and for tests.
        ``frames_sent``, ``who_am_i``, ``self_test``, ``level`` (in): read back as board
            registers.
        ``frames_stable`` (in, 1 unless driven): ``frames_sent`` holds the count (the frame
            arbiter's): a request waits until it does (24 cycles at most, after every 256th
            frame), so that a read of FRAMES_SENT gets the count.
    Latency: a board, PWM or ANSWER request is answered (its response valid, its request
    taken) two cycles after it is offered (three with more than one port: the request is
    copied first), or once ``frames_stable`` rises; an engine access
    waits in addition until the engine takes it (``WORST_UPDATE_CYCLES`` at most) and, for a
    read, its word (one cycle). Throughput: a request at a time.
    """
    def __init__(self, *, writable, version, ports=1):
        self.writable = frozenset(writable)
        self.version = version
        self.ports = ports
        self.counters = EventCounters(COUNTER_WORDS)
        # the front end served and whether a request is being served, named here so that
        # ``documented_use`` can state what a front end must do
        self._port = Signal(range(max(ports, 2)))
        self._idle = Signal()
        super().__init__({
            "request": In(stream.Signature(RegisterRequest)).array(ports),
            "response": Out(stream.Signature(RegisterResponse)).array(ports),
            "cfg": Out(stream.Signature(ConfigWrite)),
            "cfg_read": Out(stream.Signature(REG_BITS)),
            "cfg_read_data": In(stream.Signature(signed(32))),
            "pwm": Out(BoardBusSignature()),
            "control": Out(BoardBusSignature()),
            "raw_mode": Out(1),
            "kick": Out(1),
            "discarded": In(1),
            "crc_errors": In(1),
            "malformed": In(1),
            "rx_framing_error": In(1),
            "rx_overrun": In(1),
            "early_sample": In(1),
            "frames_sent": In(32),
            "frames_stable": In(1, init=1),
            "who_am_i": In(8),
            "self_test": In(SelfTestStatus),
            "level": In(ReadLevelStatus),
        })

    def documented_use(self):
        """What a front end must do: keep its request valid (and still) until it is taken;
        the stream rule, stated for every state the executor reaches (with one port its
        response's address is the request's)."""
        valid = Array(r.valid for r in self.request)[self._port] if self.ports > 1 else \
            self.request[0].valid
        return self._idle | valid

    def elaborate(self, platform):
        m = Module()
        m.submodules.counters = counters = self.counters
        # the front end served (a one-port executor has no choice to make): in IDLE the lowest
        # waiting (``pick``), then the one chosen (``port``) until its response is taken
        # (a front end holds its request still until it is taken; the command decoder's is
        # registers, so that what EXECUTE decides starts from registers)
        port = self._port
        idle = self._idle
        offered = Cat(r.valid for r in self.request).any()
        if self.ports == 1:
            req = self.request[0].payload
        else:
            pick = Signal.like(port)
            for k in reversed(range(self.ports)):
                with m.If(self.request[k].valid):
                    m.d.comb += pick.eq(k)
            # the chosen request copied as it is taken up (LOAD follows IDLE): what the
            # register blocks and EXECUTE see starts from registers, not from the ports'
            # multiplexer (in the AXI build that path into the PWM block's registers was the
            # core's longest, report --timing)
            req = Signal(RegisterRequest, reset_less=True)
            with m.If(idle & offered):
                m.d.sync += [port.eq(pick),
                             req.eq(Array(r.payload for r in self.request)[pick])]
        loading = Signal()                  # the cycle before EXECUTE's first
        low, space, value = req.addr, req.space, req.value
        response, fields, load_fields, load_result, result = self._response(
            m, req, counters.r_data)
        # the response's address is the request's (held until the response is taken), not a
        # register of its own; so are the engine's addresses
        for r in self.response:
            m.d.comb += [r.payload.result.eq(response.result), r.payload.value.eq(response.value),
                         r.payload.addr.eq(Cat(req.addr, req.space))]
        # the engine's address, registered with the response's value (as an engine access is
        # set up): from a register, not through the front ends' multiplexer (with the AXI
        # slave's port, that path into the engine's register file was the core's longest)
        engine_addr = Signal(8, reset_less=True)
        with m.If(load_fields):
            m.d.sync += engine_addr.eq(req.addr)
        m.d.comb += [self.cfg.payload.addr.eq(engine_addr),
                     self.cfg.payload.data.eq(response.value),
                     self.cfg_read.payload.eq(engine_addr),
                     *(bus.addr.eq(low) for bus in self._blocks().values()),
                     *(bus.w_data.eq(value) for bus in self._blocks().values())]

        def count(name):
            m.d.comb += counters.events[counter_word(f"CMD_{name.upper()}")].eq(1)

        def answer(result_, value_="echo", *, keep=False):
            """The response (``keep``: its fields as they are: an engine write's)."""
            m.d.comb += [load_result.eq(1), result.eq(result_)]
            if not keep:
                fields(value_)
            if result_ == RESULTS["ok"]:
                m.d.comb += self.kick.eq(1)
                count("ok")
            else:
                count("refused")
            m.next = "RESPOND"

        def answer_given():
            m.d.comb += [load_result.eq(1), result.eq(req.result)]
            fields("echo")
            with m.If(req.result == RESULTS["ok"]):
                m.d.comb += self.kick.eq(1)
                count("ok")
            with m.Else():
                count("refused")
            m.next = "RESPOND"

        board_regs = self._board_regs()
        with m.FSM() as fsm:
            with m.State("IDLE"):
                m.d.comb += idle.eq(1)
                with m.If(offered):
                    m.next = "EXECUTE" if self.ports == 1 else "LOAD"
            if self.ports > 1:
                with m.State("LOAD"):
                    m.d.comb += loading.eq(1)
                    m.next = "EXECUTE"
            with m.State("EXECUTE"):
                # while the frame count is not stable (``frames_stable``), every request
                # waits here: one condition, not one on FRAMES_SENT's read alone
                with m.If(self.frames_stable):
                    self._execute(m, req, board_regs, fields, answer, answer_given)
            with m.State("ENGINE_WRITE"):
                m.d.comb += self.cfg.valid.eq(1)
                with m.If(self.cfg.ready):
                    answer(RESULTS["ok"], keep=True)
            with m.State("ENGINE_READ"):
                m.d.comb += self.cfg_read.valid.eq(1)
                with m.If(self.cfg_read.ready):
                    m.next = "ENGINE_READ_DATA"
            with m.State("ENGINE_READ_DATA"):
                m.d.comb += self.cfg_read_data.ready.eq(1)
                with m.If(self.cfg_read_data.valid):
                    answer(RESULTS["ok"], value_="engine")
            with m.State("RESPOND"):
                for k, r in enumerate(self.response):
                    with m.If(port == k):
                        m.d.comb += r.valid.eq(1)
                        with m.If(r.ready):
                            m.d.comb += self.request[k].ready.eq(1)
                            m.next = "IDLE"
        # the counter a board read names is read the cycle before it is answered: as the
        # request comes (IDLE, any request), and each cycle it waits in EXECUTE for
        # ``frames_stable`` (the RAM's read port goes back to the counting otherwise)
        def board_read(r):
            return (r.op == RegisterOp.READ) & (r.space == SPACES["board"])
        first = (idle & offered) if self.ports == 1 else loading
        self._counters(m, counters, low=low, read=board_read(req) & (
            first | (fsm.ongoing("EXECUTE") & ~self.frames_stable)))
        return m

    def _response(self, m, req, count):
        """The response's registers, its result and value (returned, with ``fields``, the
        FSM's way to choose what the value is loaded with (``load_fields``: now),
        ``load_result`` and ``result``): an engine write's value is loaded before it is sent
        (``cfg``'s data is it), its result once the engine took it."""
        response = Signal(RegisterResponse, reset_less=True)     # its ``addr`` unused
        # What the response's value is loaded with: each source an AND with its own select,
        # OR-ed, the selects set by the FSM's branches (``fields``), so that the decisions are
        # made once for all the bits rather than a multiplexer's per bit. The request's own
        # value is one source (a write's, echoed)
        sources = {
            "engine": self.cfg_read_data.payload,
            **{name: bus.r_data for name, bus in self._blocks().items()},
            **self._board_sources(count),
        }
        load_fields = Signal()
        load_result = Signal()
        chosen = {name: Signal(name=f"response_{name}") for name in sources}
        echo = Signal()                         # the request's value
        value_const = Signal(32)                # OR-ed in: a constant's value
        result = Signal(8)
        with m.If(load_result):
            m.d.sync += response.result.eq(result)
        with m.If(load_fields):
            m.d.sync += [
                response.value.eq(reduce(operator.or_, (
                    Mux(chosen[name], source.as_unsigned(), 0)
                    for name, source in sources.items()), value_const | Mux(echo, req.value, 0)))]

        def fields(value_):
            """The response's value: "echo" (the request's), a source's name (``sources``),
            or a constant; its address is the request's."""
            m.d.comb += load_fields.eq(1)
            if value_ == "echo":
                m.d.comb += echo.eq(1)
            elif isinstance(value_, str):
                m.d.comb += chosen[value_].eq(1)
            else:
                m.d.comb += value_const.eq(value_)

        return response, fields, load_fields, load_result, result

    def _blocks(self):
        """The register blocks on a bus, by their space's name: the PWM block's, the balance
        controller's (``exists`` low where a build has none: ``bad_address``)."""
        return {"pwm": self.pwm, "control": self.control}

    def _counters(self, m, counters, *, read, low):
        """The events into the counters, and the read of the counter a board read names
        (``low``, the cycle before it is answered: ``read``)."""
        m.d.comb += [
            counters.events[counter_word("RX_FRAMING_ERRORS")].eq(self.rx_framing_error),
            counters.events[counter_word("RX_OVERRUNS")].eq(self.rx_overrun),
            counters.events[counter_word("RATE_ERRORS")].eq(self.early_sample),
            counters.events[counter_word("CMD_DISCARDED")].eq(self.discarded),
            counters.events[counter_word("CMD_CRC_ERRORS")].eq(self.crc_errors),
            counters.events[counter_word("CMD_MALFORMED")].eq(self.malformed),
            counters.r_en.eq(read),
            counters.r_addr.eq(Mux(low == BOARD_REGS["RATE_ERRORS"], RATE_ERRORS_WORD,
                                   low - BOARD_REGS["CMD_DISCARDED"]))]

    def _board_sources(self, count):
        """The board registers' sources that are not constants, by name (each a source of the
        response's value); ``count``: the counter the request addresses (``EventCounters``'
        ``r_data``, read the cycle before: ``elaborate``)."""
        return {"raw_mode": self.raw_mode, "count": count, "frames_sent": self.frames_sent,
                "who_am_i": self.who_am_i, "self_test": self.self_test.as_value(),
                "level": self.level.as_value()}

    def _board_regs(self):
        """What each board register reads back, by address (``BOARD_REGS``: the one map of
        names and addresses, which the host's register map reads too): a source of
        ``_board_sources`` by name, or a constant."""
        sources = {
            "RAW_MODE": "raw_mode", "VERSION": self.version, "REGMAP_VERSION": REGMAP_VERSION,
            **{name: "count" for name in COUNTED},
            "FRAMES_SENT": "frames_sent", "WHO_AM_I": "who_am_i", "SELF_TEST": "self_test",
            "SPI_TRAINING": "level",
        }
        assert set(sources) == set(BOARD_REGS), "a board register without its source"
        return {BOARD_REGS[name]: sources[name] for name in BOARD_REGS}

    def _execute(self, m, req, board_regs, fields, answer, answer_given):
        """EXECUTE, once the frame count is stable: the request checked and done, or answered
        at once: a board register, a PWM register, an ANSWER; an engine write or read goes on
        to ENGINE_WRITE / ENGINE_READ."""
        space, low, value = req.space, req.addr, req.value
        with m.If(req.op == RegisterOp.ANSWER):
            answer_given()
        with m.Elif(req.op == RegisterOp.WRITE):
            with m.If(space == SPACES["engine"]):
                # a write the engine would refuse is answered "refused" here (the front end
                # learns why): an address it may not write, or a CONTROL word with no meaning
                with m.If(write_allowed(low, value, self.writable)):
                    fields("echo")
                    m.next = "ENGINE_WRITE"
                with m.Else():
                    answer(RESULTS["refused"])
            with m.Elif(space == SPACES["board"]):
                with m.If(low == BOARD_REGS["RAW_MODE"]):
                    m.d.sync += self.raw_mode.eq(value[0])
                    answer(RESULTS["ok"])
                with m.Elif(address_in(low, BOARD_REGS.values())):
                    answer(RESULTS["refused"])
                with m.Else():
                    answer(RESULTS["bad_address"])
            for name, bus in self._blocks().items():
                with m.Elif(space == SPACES[name]):
                    with m.If(bus.exists & bus.ok):
                        m.d.comb += bus.w_en.eq(1)
                        answer(RESULTS["ok"])
                    with m.Elif(bus.exists):
                        answer(RESULTS["refused"])
                    with m.Else():
                        answer(RESULTS["bad_address"])
            with m.Else():
                answer(RESULTS["bad_address"])
        with m.Else():                                  # READ
            with m.If(space == SPACES["engine"]):
                fields("echo")                          # its address, for ``cfg_read``
                m.next = "ENGINE_READ"
            with m.Elif(space == SPACES["board"]):
                with m.Switch(low):
                    for a, signal in board_regs.items():
                        with m.Case(a):
                            answer(RESULTS["ok"], value_=signal)
                    with m.Default():
                        answer(RESULTS["bad_address"], value_=0)
            for name, bus in self._blocks().items():
                with m.Elif(space == SPACES[name]):
                    with m.If(bus.exists):
                        answer(RESULTS["ok"], value_=name)
                    with m.Else():
                        answer(RESULTS["bad_address"], value_=0)
            with m.Else():
                answer(RESULTS["bad_address"], value_=0)
