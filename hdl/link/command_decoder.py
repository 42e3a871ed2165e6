"""Command decoder: the host's commands, framed like the telemetry (``hdl/FRAMES.md``),
checked whole before anything is done, executed, and answered with a reply frame."""

import operator
from contextlib import contextmanager
from functools import reduce
from types import SimpleNamespace

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..primitives.clocking import ticks
from ..engine.attitude_isa import REG_BITS
from ..contract.commands import (BOARD_REGS, COMMAND_FIFO_BYTES, COMMANDS,
                                 MAX_COMMAND_PAYLOAD, REGMAP_VERSION, RESULT_INPUT_LOST,
                                 RESULTS, SPACES)
from ..engine.register_map import CONTROL_ADDR, CONTROL_KEEP, CONTROL_RESET, TELEMETRY_DIV_ADDR
from ..contract.filter_registry import FILTER_CODES
from .board_bus import BoardBusSignature
from ..engine.host_port import address_in, write_allowed
from ..engine.config_write import ConfigWrite
from ..sensor.driver_status import SelfTestStatus
from .frame_types import CRC, SYNC, Reply
from .event_counters import EventCounters
from .rewindable_fifo import RewindableFIFO


__all__ = ["FIFO_DEPTH", "COMMAND_STATS", "COUNTED", "COUNTER_WORDS", "counter_word",
           "CommandDecoder"]


# The commands whose payload is one or two bytes, a value: kept where a write's value is
# (``CommandDecoder``'s ``payload``, from byte ``VALUE_AT``, after a write's address), so that
# a reply's or an engine write's value comes from the same bits in every command
SHORT = ("filter", "rate", "raw")
VALUE_AT = 2
assert all(VALUE_AT + COMMANDS[name][1] <= MAX_COMMAND_PAYLOAD for name in SHORT)
# the command's value in a reply, masked: a write's (echo), or a short payload's
ECHOED = {"echo": (1 << 32) - 1, "byte": 0xFF, "half": 0xFFFF, "bit": 1}
# The input FIFO (``COMMAND_FIFO_BYTES``: why its size, the contract's ``commands``). A byte
# that finds it full is dropped, counted (RX_OVERRUNS) and said in the next reply
# (``RESULT_INPUT_LOST``)
FIFO_DEPTH = COMMAND_FIFO_BYTES


# The decoder's counters (16 bits each, saturating, in an ``EventCounters``), in the order of
# their board registers (CMD_DISCARDED ... CMD_REFUSED):
COMMAND_STATS = (
    "discarded",    # bytes outside any frame (hunting for the sync pattern)
    "crc_errors",   # frames whose CRC did not match
    "malformed",    # too long, cut off (no byte for ``timeout`` cycles), bad type or length
    "ok",           # commands done
    "refused",      # well-formed commands refused (read-only, out of range, no address)
)
# The board registers counted in the decoder's ``EventCounters``, the receiver's two and the
# sample reader's early samples included, and its words: a power of two, so that a board
# address less CMD_DISCARDED's, cut to its low bits, is the word (``counter_word``)
COUNTED = ("RX_FRAMING_ERRORS", "RX_OVERRUNS", *(f"CMD_{name.upper()}" for name in COMMAND_STATS),
           "RATE_ERRORS")
COUNTER_WORDS = 8
# RATE_ERRORS's address would share RX_FRAMING_ERRORS's word: it has the one word left
RATE_ERRORS_WORD = 5


def counter_word(name):
    """A counted board register's word in the counters' RAM: its address less CMD_DISCARDED's,
    modulo ``COUNTER_WORDS`` (the receiver's two, before it, are words 6 and 7; the discarded
    bytes, which come fastest, word 0: the first served), but RATE_ERRORS's, word 5. The
    command names its word with its address's low bits (``CommandDecoder._counters``)."""
    if name == "RATE_ERRORS":
        return RATE_ERRORS_WORD
    return (BOARD_REGS[name] - BOARD_REGS["CMD_DISCARDED"]) % COUNTER_WORDS


assert sorted(counter_word(name) for name in COUNTED) == list(range(COUNTER_WORDS))


class CommandDecoder(wiring.Component):
    """Parses command frames from a byte stream and executes them.

    A command is parsed into a buffer and its CRC checked before anything is done: a
    truncated, corrupt or malformed command changes nothing (it is counted, and a corrupt one
    gets no reply: its sequence number cannot be trusted). A good one is executed whole (an
    engine write is one ``cfg`` transfer; a board write one cycle) and answered with a
    ``Reply``.

    The bytes come through a ``RewindableFIFO`` (``FIFO_DEPTH``) that keeps a frame's bytes
    until it is done: when a frame fails (bad CRC, a length over the longest), the search for
    a header starts again at the byte after its first, so a good frame that began inside a
    cut-off or corrupt one (half a frame, then a new one at once; a stray ``A5 A5 5A``) is
    still found and executed. The bytes searched again that belong to no frame count in
    ``discarded`` too. A frame that timed out is dropped whole (no byte of it is followed by
    anything within the time-out, so none can start a good frame).

    Parameters
        ``writable``: engine addresses a host may write (``HOST_WRITABLE``).
        ``version``: the version/build word "who" returns and VERSION reads.
        ``timeout``: cycles without a byte after which a frame in progress is dropped.
        ``tick_cycles`` (1): the time-out is counted in ticks (``tick``, in: a pulse every
            ``tick_cycles`` cycles; the core's is the sample reader's prescaler), so that its
            count is 9 bits rather than 18 (5 ms at 48 MHz): ``clocking.ticks``, at least
            ``timeout`` cycles and at most two ticks more. With 1, every cycle is a tick and
            the time-out is exact.
    Members
        ``i_stream`` (in, byte stream): from the UART receiver; taken while the FIFO has room
            (bytes that arrive while a command executes wait there).
        ``cfg``, ``cfg_read``, ``cfg_read_data``: to the engine's register port.
        ``pwm`` (out, ``BoardBusSignature``): the PWM block's registers (space 0x02).
        ``replies`` (out, stream of ``Reply``): to an unbuffered framer (held until sent).
        ``raw_mode`` (out): RAW_MODE bit 0.
        ``kick`` (out): a pulse per accepted command (result ``ok``; the PWM watchdog).
        ``fifo``: the ``RewindableFIFO`` (its ``ram``, one M9K, for ``report``).
        ``rx_framing_error``, ``rx_overrun`` (in): the receiver's pulses, counted.
        ``early_sample`` (in): the sample reader's pulse per sample that came early, counted
            (RATE_ERRORS).
        ``counters``: the ``EventCounters`` of the ``COUNTED`` board registers
            (RX_FRAMING_ERRORS ... CMD_REFUSED, RATE_ERRORS; word ``counter_word(name)``:
            ``COMMAND_STATS`` are words 0-4), its ``ram`` for ``report`` and for tests
            (``ram.data[k]``).
        ``frames_sent``, ``who_am_i``, ``self_test`` (in): read back as board registers.
        ``frames_stable`` (in, 1 unless driven): ``frames_sent`` holds the count (the frame
            arbiter's ``frames_stable``): a command waits in EXECUTE until it does (24 cycles
            at most, after every 256th frame), so that a read of FRAMES_SENT gets the count.
    Latency: a board command's reply is offered two cycles after its last (CRC) byte is
    taken (or once ``frames_stable`` rises, if it is low then); an engine write or read
    waits in addition until the engine takes it (at once while it is idle,
    ``WORST_UPDATE_CYCLES`` at most) and, for a read, its word (one cycle).
    Throughput: a byte every two cycles while parsing (each is looked at, then taken); a
    command then takes a few cycles, or until
    the engine is idle (``WORST_UPDATE_CYCLES`` at most), and its reply's time on the link.
    """
    def __init__(self, *, writable, version, timeout, tick_cycles=1):
        self.writable = frozenset(writable)
        self.version = version
        self.timeout = timeout
        self.timeout_ticks = ticks(timeout, tick_cycles, exact=timeout)
        self.fifo = RewindableFIFO(FIFO_DEPTH)
        self.counters = EventCounters(COUNTER_WORDS)
        super().__init__({
            "i_stream": In(stream.Signature(8)),
            "cfg": Out(stream.Signature(ConfigWrite)),
            "cfg_read": Out(stream.Signature(REG_BITS)),
            "cfg_read_data": In(stream.Signature(signed(32))),
            "pwm": Out(BoardBusSignature()),
            "replies": Out(stream.Signature(Reply)),
            "raw_mode": Out(1),
            "kick": Out(1),
            "rx_framing_error": In(1),
            "rx_overrun": In(1),
            "frames_sent": In(32),
            "frames_stable": In(1, init=1),
            "early_sample": In(1),
            "who_am_i": In(8),
            "self_test": In(SelfTestStatus),
            "tick": In(1, init=1),
        })

    def elaborate(self, platform):
        m = Module()
        # the CRC takes a byte in two halves, high then low (the algorithm reflects nothing:
        # the same CRC as a byte at once), in the two cycles each byte is parsed in: looked
        # at, then taken (``_look``). Half the XORs of a byte-wide one
        m.submodules.crc = crc = CRC(data_width=4).create()
        m.submodules.fifo = fifo = self.fifo
        m.submodules.counters = counters = self.counters
        wiring.connect(m, wiring.flipped(self.i_stream), fifo.w_stream)
        src = fifo.r_stream
        byte = src.payload
        take = src.valid & src.ready

        looked, is_sync0, is_sync1, too_long, empty, crc_ok, high_ok = self._look(
            m, src, take, crc)

        # data registers, written before they are read in every frame, need no reset (on a
        # MAX10 a synchronous reset costs logic per bit)
        ctype = Signal(8, reset_less=True)
        seq = Signal(8, reset_less=True)
        length = Signal(8, reset_less=True)
        left = Signal(range(MAX_COMMAND_PAYLOAD + 1), reset_less=True)    # payload bytes to come
        # The payload's bytes in the order they come, but a short payload's (``SHORT``) from
        # byte ``VALUE_AT`` on, where a write's value begins: the reply and an engine write
        # take their value from those bits in every command
        payload = Signal(8 * MAX_COMMAND_PAYLOAD, reset_less=True)
        # the next byte's place in ``payload``, one-hot (a register bit is each byte's
        # enable: no decoder of a count)
        place = Signal(MAX_COMMAND_PAYLOAD, reset_less=True)
        gap = Signal(range(self.timeout_ticks + 1))          # ticks without a byte
        addr = payload[:8 * VALUE_AT]
        value = payload[8 * VALUE_AT:8 * VALUE_AT + 32]
        space, low = addr[8:], addr[:8]
        reply, fields, load_header, result = self._reply(m, ctype, seq, addr, value,
                                                         counters.r_data)
        m.d.comb += [self.replies.payload.eq(reply), self.cfg.payload.addr.eq(reply.addr[:8]),
                     self.cfg.payload.data.eq(reply.value),
                     # an engine read's address, offered in ENGINE_READ (not gated by it: a
                     # LUT a bit)
                     self.cfg_read.payload.eq(low)]

        def count_up(name):
            m.d.comb += counters.events[counter_word(f"CMD_{name.upper()}")].eq(1)

        def answer(result_, value_="echo", addr_="echo", *, keep=False):
            """The reply (``keep``: its address and value as they are: an engine write's)."""
            m.d.comb += [load_header.eq(1), result.eq(result_)]
            if not keep:
                fields(value_, addr_)
            if result_ == RESULTS["ok"]:
                # only an accepted command restarts the PWM watchdog: a host stuck sending
                # refused or unknown commands is as good as a silent one
                m.d.comb += self.kick.eq(1)
                count_up("ok")
            else:
                count_up("refused")
            m.next = "REPLY"

        m.d.comb += [crc.data.eq(Mux(looked, byte[:4], byte[4:]))]
        board_regs = self._board_regs()
        # an engine write the engine would refuse is answered "refused" here (the host learns
        # why): an address it may not write, or a CONTROL word with no meaning
        writable = write_allowed(low, value, self.writable)
        m.d.comb += [self.pwm.addr.eq(low), self.pwm.w_data.eq(value)]

        parsing = ("HUNT", "SYNC1", "TYPE", "SEQ", "LENGTH", "PAYLOAD", "CRC_HIGH", "CRC_LOW")
        in_frame = Signal()
        timed_out = (gap == self.timeout_ticks) & ~take & in_frame
        with m.FSM() as fsm:
            self._parse(m, SimpleNamespace(
                src=src, fifo=fifo, crc=crc, take=take, byte=byte, looked=looked,
                is_sync0=is_sync0, is_sync1=is_sync1, too_long=too_long, empty=empty,
                crc_ok=crc_ok, high_ok=high_ok, timed_out=timed_out, ctype=ctype, seq=seq,
                length=length, left=left, place=place, payload=payload, count_up=count_up))

            with m.State("EXECUTE"):
                # while the frame count is not stable (``frames_stable``), every command
                # waits here: one condition, not one on FRAMES_SENT's read alone
                with m.If(self.frames_stable):
                    self._execute(m, SimpleNamespace(
                        ctype=ctype, length=length, space=space, low=low,
                        value=value, fields=fields, writable=writable, board_regs=board_regs,
                        answer=answer, count_up=count_up))

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
            with m.State("REPLY"):
                m.d.comb += self.replies.valid.eq(1)
                with m.If(self.replies.ready):
                    m.next = "HUNT"

        # the counter a board read names is read as the frame's last byte is taken, and again
        # each cycle the command waits in EXECUTE for ``frames_stable`` (the RAM's read port
        # goes back to the counting otherwise: its word would be another counter's)
        self._counters(m, counters, low=low, read=(fsm.ongoing("CRC_LOW") & take) |
                       (fsm.ongoing("EXECUTE") & ~self.frames_stable))
        # a frame cut off: no byte for ``timeout`` cycles while one is being parsed
        m.d.comb += in_frame.eq(sum(fsm.ongoing(state) for state in parsing[1:]) != 0)
        with m.If(take | ~in_frame):
            m.d.sync += gap.eq(0)
        with m.Elif(~timed_out):
            m.d.sync += gap.eq(gap + self.tick)
        with m.If(timed_out):
            count_up("malformed")
            m.d.sync += gap.eq(0)
        return m

    def _reply(self, m, ctype, seq, addr, value, count):
        """The reply register (returned, with ``fields``, the FSM's way to load its address
        and value, and ``load_header`` and ``result``, its header's load and result code):
        ``ctype``, ``seq``, the command's ``addr`` and ``value`` fields and ``count``, the
        counter read (``EventCounters.r_data``)."""
        # the reply is written before it is offered: no reset. An engine write is made from
        # its address and value fields (a write's reply echoes them), set before ENGINE_WRITE:
        # one register and one multiplexer in front of it, not two
        reply = Signal.like(self.replies.payload, reset_less=True)
        # What the reply's fields are loaded with: each source of the value an AND with its
        # own select, OR-ed, the selects set by the FSM's branches (``fields``), so that the
        # decisions are made once for all the bits rather than a multiplexer's per bit. The
        # command's own value is one source, masked to its bytes (``ECHOED``: a write's
        # four, a short payload's fewer)
        sources = {
            "engine": self.cfg_read_data.payload, "pwm": self.pwm.r_data,
            **self._board_sources(count),
        }
        echo_mask = Signal(32)
        load_fields = Signal()                  # the address and value are loaded
        load_header = Signal()                  # the type, sequence number and result
        chosen = {name: Signal(name=f"reply_{name}") for name in sources}
        addr_echo = Signal()                    # the address the command named
        addr_const = Signal(16)                 # OR-ed in: a command's own address
        value_const = Signal(32)                # OR-ed in: a constant's value
        result = Signal(8)
        # a byte from the host dropped (the input FIFO full) since the last reply was made:
        # the next reply says so (``RESULT_INPUT_LOST``), for a command lost with it had none
        input_lost = Signal()
        with m.If(load_header):
            m.d.sync += [reply.command.eq(ctype), reply.cmd_seq.eq(seq),
                         reply.result.eq(result | Mux(input_lost, RESULT_INPUT_LOST, 0)),
                         input_lost.eq(0)]
        with m.If(self.rx_overrun):
            m.d.sync += input_lost.eq(1)
        with m.If(load_fields):
            m.d.sync += [
                reply.addr.eq(Mux(addr_echo, addr, 0) | addr_const),
                reply.value.eq(reduce(operator.or_, (
                    Mux(chosen[name], source.as_unsigned(), 0)
                    for name, source in sources.items()), value_const | (value & echo_mask)))]

        def fields(value_, addr_="echo"):
            """The reply's address and value (an engine write's too): ``value_`` the command's
            value (a key of ``ECHOED``), a source's name (``sources``) or a constant;
            ``addr_`` "echo" or a constant."""
            m.d.comb += load_fields.eq(1)
            if value_ in ECHOED:
                m.d.comb += echo_mask.eq(ECHOED[value_])
            elif isinstance(value_, str):
                m.d.comb += chosen[value_].eq(1)
            else:
                m.d.comb += value_const.eq(value_)
            if addr_ == "echo":
                m.d.comb += addr_echo.eq(1)
            else:
                m.d.comb += addr_const.eq(addr_)

        return reply, fields, load_header, result

    def _look(self, m, src, take, crc):
        """The facts about the FIFO's head byte the parser decides on (``looked`` says they
        are in), and ``high_ok``, the CRC's high byte's match (the parser sets it)."""
        byte = src.payload
        # The byte at the FIFO's head is looked at a cycle before it is taken: what the parser
        # decides from it (a sync byte, a length too long, the CRC matching) is registered
        # first, so that the FIFO's pointers (take, mark, release, rewind) follow registers,
        # not the FIFO's own output through the comparisons (that loop was the longest path
        # of the core, report --timing). The head changes only when a byte is taken (a rewind
        # comes with a take), so the facts hold until then. A byte every two cycles: the UART
        # brings one every ten bit times.
        looked = Signal()
        is_sync0 = Signal(reset_less=True)
        is_sync1 = Signal(reset_less=True)
        too_long = Signal(reset_less=True)
        empty = Signal(reset_less=True)
        crc_ok = Signal(reset_less=True)
        # the CRC's high byte matched: judged when it is taken (the CRC holds from then on),
        # so that the low byte's look compares 8 bits, not 16
        high_ok = Signal(reset_less=True)
        with m.If(take):
            m.d.sync += looked.eq(0)
        with m.Elif(src.valid):
            m.d.sync += [looked.eq(1), is_sync0.eq(byte == SYNC[0]), is_sync1.eq(byte == SYNC[1]),
                         too_long.eq(byte > MAX_COMMAND_PAYLOAD), empty.eq(byte == 0),
                         crc_ok.eq(high_ok & (byte == crc.crc[:8]))]
        return looked, is_sync0, is_sync1, too_long, empty, crc_ok, high_ok

    def _counters(self, m, counters, *, read, low):
        """The receiver's events into the counters, and the read of the counter a board read
        names (``low``): a board read answers in EXECUTE, so its counter is read the cycle
        before (``read``: as the frame's last byte is taken, when the address is in, and
        while EXECUTE waits)."""
        m.d.comb += [
            counters.events[counter_word("RX_FRAMING_ERRORS")].eq(self.rx_framing_error),
            counters.events[counter_word("RX_OVERRUNS")].eq(self.rx_overrun),
            counters.events[counter_word("RATE_ERRORS")].eq(self.early_sample),
            counters.r_en.eq(read),
            counters.r_addr.eq(Mux(low == BOARD_REGS["RATE_ERRORS"], RATE_ERRORS_WORD,
                                   low - BOARD_REGS["CMD_DISCARDED"]))]

    def _board_sources(self, count):
        """The board registers' sources that are not constants, by name (each a source of the
        reply's value); ``count``: the decoder's counter the command addresses
        (``EventCounters.r_data``, read as the frame's last byte was taken: ``elaborate``)."""
        return {"raw_mode": self.raw_mode, "count": count, "frames_sent": self.frames_sent,
                "who_am_i": self.who_am_i, "self_test": self.self_test.as_value()}

    def _board_regs(self):
        """What each board register reads back, by address (``BOARD_REGS``: the one map of
        names and addresses, which the host's register map reads too): a source of
        ``_board_sources`` by name, or a constant."""
        sources = {
            "RAW_MODE": "raw_mode", "VERSION": self.version, "REGMAP_VERSION": REGMAP_VERSION,
            **{name: "count" for name in COUNTED},
            "FRAMES_SENT": "frames_sent", "WHO_AM_I": "who_am_i", "SELF_TEST": "self_test",
        }
        assert set(sources) == set(BOARD_REGS), "a board register without its source"
        return {BOARD_REGS[name]: sources[name] for name in BOARD_REGS}

    def _parse(self, m, c):
        """The parsing states of the decoder's FSM, HUNT to CRC_LOW (EXECUTE follows a frame
        that passed its CRC). ``c``: the parser's registers, the FIFO's head and helpers."""
        (src, fifo, crc, take, byte, looked, is_sync0, is_sync1, too_long, empty, crc_ok,
         high_ok, timed_out, ctype, seq, length, left, place, payload, count_up) = (
            c.src, c.fifo, c.crc, c.take, c.byte, c.looked, c.is_sync0, c.is_sync1,
            c.too_long, c.empty, c.crc_ok, c.high_ok, c.timed_out, c.ctype, c.seq, c.length,
            c.left, c.place, c.payload, c.count_up)
        with m.State("HUNT"):
            m.d.comb += src.ready.eq(looked)
            with m.If(take):
                with m.If(is_sync0):
                    # a frame may start here: kept until it is done or failed
                    m.d.comb += fifo.mark.eq(1)
                    m.next = "SYNC1"
                with m.Else():
                    m.d.comb += fifo.release.eq(1)
                    count_up("discarded")

        @contextmanager
        def receiving(state, *, checked=True, first=False):
            """A parsing state: takes a byte (into the CRC if ``checked``: its high half as
            it is looked at, its low half as it is taken; the CRC starts with it if
            ``first``), or gives up on the frame at the time-out."""
            with m.State(state):
                with m.If(timed_out):
                    m.d.comb += fifo.release.eq(1)
                    m.next = "HUNT"
                m.d.comb += src.ready.eq(looked)
                if checked:
                    # a byte looked at in a parsing state is taken the cycle after (or the
                    # frame times out, and the CRC starts again with the next one)
                    m.d.comb += crc.valid.eq(src.valid)
                if first:
                    m.d.comb += crc.start.eq(~looked)
                with m.If(take):
                    yield

        with m.State("SYNC1"):
            with m.If(timed_out):
                m.d.comb += fifo.release.eq(1)
                m.next = "HUNT"
            # a byte other than the sync's second goes back to the hunt untaken (the hunt
            # counts it, or starts on it if it is 0xA5); the 0xA5 before it began nothing
            m.d.comb += src.ready.eq(looked & is_sync1)
            with m.If(looked):
                with m.If(is_sync1):
                    m.next = "TYPE"
                with m.Else():
                    count_up("discarded")
                    m.next = "HUNT"
        with receiving("TYPE", first=True):
            m.d.sync += ctype.eq(byte)
            m.next = "SEQ"
        with receiving("SEQ"):
            m.d.sync += seq.eq(byte)
            m.next = "LENGTH"
        with receiving("LENGTH"):
            # the payload's bytes are not cleared (a LUT a bit on a MAX10): a command reads only
            # the bytes its length brings, checked in EXECUTE; a bad one's reply is all zeros
            short = Const(sum(1 << COMMANDS[name][0] for name in SHORT), 256).bit_select(
                ctype, 1)
            m.d.sync += [length.eq(byte), left.eq(byte),
                         place.eq(Mux(short, 1 << VALUE_AT, 1))]
            with m.If(too_long):
                count_up("malformed")
                m.d.comb += fifo.rewind.eq(1)           # search the rest for a header
                m.next = "HUNT"
            with m.Elif(empty):
                m.next = "CRC_HIGH"
            with m.Else():
                m.next = "PAYLOAD"
        with receiving("PAYLOAD"):
            for k in range(MAX_COMMAND_PAYLOAD):
                with m.If(place[k]):
                    m.d.sync += payload[8 * k:8 * k + 8].eq(byte)
            m.d.sync += [left.eq(left - 1), place.eq(place << 1)]
            with m.If(left == 1):
                m.next = "CRC_HIGH"
        with receiving("CRC_HIGH", checked=False):
            m.d.sync += high_ok.eq(byte == crc.crc[8:])
            m.next = "CRC_LOW"
        with receiving("CRC_LOW", checked=False):
            with m.If(crc_ok):
                m.d.comb += fifo.release.eq(1)
                m.next = "EXECUTE"
            with m.Else():
                count_up("crc_errors")
                m.d.comb += fifo.rewind.eq(1)           # search the rest for a header
                m.next = "HUNT"

    def _execute(self, m, c):
        """EXECUTE, the cycle after a whole command passed its CRC: the command checked
        against its type (known, its length) and done, or answered at once: a board
        register, a PWM register, the raw-sample mode, "who"; an engine write or read
        goes on to ENGINE_WRITE / ENGINE_READ. ``c``: the parser's registers and helpers."""
        (ctype, length, space, low, value,
         fields, writable, board_regs, answer, count_up) = (
            c.ctype, c.length, c.space, c.low, c.value,
            c.fields, c.writable, c.board_regs, c.answer, c.count_up)
        expected = Signal(8)
        known = Signal()
        with m.Switch(ctype):
            for name, (code, n) in COMMANDS.items():
                with m.Case(code):
                    m.d.comb += [expected.eq(n), known.eq(1)]
        with m.If(~known | (length != expected)):
            count_up("malformed")
            answer(RESULTS["bad_command"], value_=0, addr_=0)
        with m.Elif(ctype == COMMANDS["write"][0]):
            with m.If(space == SPACES["engine"]):
                with m.If(writable):
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
            with m.Elif(space == SPACES["pwm"]):
                with m.If(self.pwm.exists & self.pwm.ok):
                    m.d.comb += self.pwm.w_en.eq(1)
                    answer(RESULTS["ok"])
                with m.Elif(self.pwm.exists):
                    answer(RESULTS["refused"])
                with m.Else():
                    answer(RESULTS["bad_address"])
            with m.Else():
                answer(RESULTS["bad_address"])
        with m.Elif(ctype == COMMANDS["read"][0]):
            with m.If(space == SPACES["engine"]):
                m.next = "ENGINE_READ"
            with m.Elif(space == SPACES["board"]):
                with m.Switch(low):
                    for a, signal in board_regs.items():
                        with m.Case(a):
                            answer(RESULTS["ok"], value_=signal)
                    with m.Default():
                        answer(RESULTS["bad_address"], value_=0)
            with m.Elif(space == SPACES["pwm"]):
                with m.If(self.pwm.exists):
                    answer(RESULTS["ok"], value_="pwm")
                with m.Else():
                    answer(RESULTS["bad_address"], value_=0)
            with m.Else():
                answer(RESULTS["bad_address"], value_=0)
        with m.Elif(ctype == COMMANDS["filter"][0]):
            with m.If(value[:8] <= max(FILTER_CODES.values())):
                fields("byte", CONTROL_ADDR)
                m.next = "ENGINE_WRITE"
            with m.Else():
                answer(RESULTS["refused"], addr_=CONTROL_ADDR, value_="byte")
        with m.Elif(ctype == COMMANDS["reset"][0]):
            fields(CONTROL_KEEP | CONTROL_RESET, CONTROL_ADDR)
            m.next = "ENGINE_WRITE"
        with m.Elif(ctype == COMMANDS["rate"][0]):
            fields("half", TELEMETRY_DIV_ADDR)
            m.next = "ENGINE_WRITE"
        with m.Elif(ctype == COMMANDS["raw"][0]):
            m.d.sync += self.raw_mode.eq(value[0])
            answer(RESULTS["ok"], addr_=(SPACES["board"] << 8) | BOARD_REGS["RAW_MODE"],
                   value_="bit")
        with m.Else():                                  # who
            answer(RESULTS["ok"], addr_=REGMAP_VERSION, value_=self.version)
