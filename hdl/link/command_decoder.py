"""Command decoder: the host's commands, framed like the telemetry (``hdl/FRAMES.md``),
checked whole before anything is done, executed, and answered with a reply frame."""

from contextlib import contextmanager
from types import SimpleNamespace

from amaranth import *
from amaranth.lib import stream, wiring
from amaranth.lib.wiring import In, Out

from ..primitives.clocking import ticks
from ..engine.attitude_isa import REG_BITS
from ..contract.commands import (BOARD_REGS, COMMAND_FIFO_BYTES, COMMANDS, MAX_COMMAND_PAYLOAD,
                                 REGMAP_VERSION, RESULT_INPUT_LOST, RESULTS, SPACES)
from ..engine.register_map import CONTROL_ADDR, CONTROL_KEEP, CONTROL_RESET, TELEMETRY_DIV_ADDR
from ..contract.filter_registry import FILTER_CODES
from .board_bus import BoardBusSignature
from ..engine.config_write import ConfigWrite
from ..sensor.driver_status import ReadLevelStatus, SelfTestStatus
from .frame_types import CRC, SYNC, Reply
from .register_executor import (COMMAND_STATS, COUNTED, COUNTER_WORDS, RegisterExecutor,
                                RegisterOp, RegisterRequest, counter_word)
from .rewindable_fifo import RewindableFIFO


# the command channel's counters are the executor's (its board registers): named here too,
# where the tests of the channel look for them
__all__ = ["FIFO_DEPTH", "COMMAND_STATS", "COUNTED", "COUNTER_WORDS", "counter_word",
           "CommandDecoder"]


# The commands whose payload is one or two bytes, a value: kept where a write's value is
# (``CommandDecoder``'s ``payload``, from byte ``VALUE_AT``, after a write's address), so that
# a request's value comes from the same bits in every command
SHORT = ("filter", "rate", "raw")
VALUE_AT = 2
assert all(VALUE_AT + COMMANDS[name][1] <= MAX_COMMAND_PAYLOAD for name in SHORT)
# the command's value in its request (and so in its reply), masked: a write's, or a short
# payload's fewer bytes
ECHOED = {"echo": (1 << 32) - 1, "byte": 0xFF, "half": 0xFFFF, "bit": 1}
# The input FIFO (``COMMAND_FIFO_BYTES``: why its size, the contract's ``commands``). A byte
# that finds it full is dropped, counted (RX_OVERRUNS) and said in the next reply
# (``RESULT_INPUT_LOST``)
FIFO_DEPTH = COMMAND_FIFO_BYTES


class CommandDecoder(wiring.Component):
    """Parses command frames from a byte stream and has them executed.

    A command is parsed into a buffer and its CRC checked before anything is done: a
    truncated, corrupt or malformed command changes nothing (it is counted, and a corrupt one
    gets no reply: its sequence number cannot be trusted). A good one becomes one request to
    a ``RegisterExecutor`` (``executor``, inside: the rules of reads and writes, the
    refusals, the counters), executed whole (an engine write is one ``cfg`` transfer; a board
    write one cycle), and its response is sent back as a ``Reply``: "write" and "read" are the
    executor's WRITE and READ; "filter", "reset" and "rate" writes of CONTROL and
    TELEMETRY_DIV; "raw" a write of RAW_MODE; "who", a bad type or length, a filter code that
    names none, ANSWERs (the reply given here).

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
        ``ports`` (1): the executor's front ends; this decoder is port 0, the others are for
            another front end (the AXI slave: ``executor.request[1]``, ``response[1]``).
        ``tick_cycles`` (1): the time-out is counted in ticks (``tick``, in: a pulse every
            ``tick_cycles`` cycles; the core's is the sample reader's prescaler), so that its
            count is 9 bits rather than 18 (5 ms at 48 MHz): ``clocking.ticks``, at least
            ``timeout`` cycles and at most two ticks more. With 1, every cycle is a tick and
            the time-out is exact.
    Members
        ``i_stream`` (in, byte stream): from the UART receiver; taken while the FIFO has room
            (bytes that arrive while a command executes wait there).
        ``cfg``, ``cfg_read``, ``cfg_read_data``: to the engine's register port.
        ``pwm`` (out, ``BoardBusSignature``): the PWM block's registers (space 0x02);
        ``control`` (out, likewise): the balance controller's (space 0x03).
        ``replies`` (out, stream of ``Reply``): to an unbuffered framer (held until sent).
        ``raw_mode`` (out): RAW_MODE bit 0.
        ``kick`` (out): a pulse per accepted command (result ``ok``; the PWM watchdog).
        ``fifo``: the ``RewindableFIFO`` (its ``ram``, one M9K, for ``report``).
        ``executor``: its ``RegisterExecutor``; ``cfg`` ... ``self_test`` are its ports.
        ``rx_framing_error``, ``rx_overrun`` (in): the receiver's pulses, counted.
        ``early_sample`` (in): the sample reader's pulse per sample that came early, counted
            (RATE_ERRORS).
        ``counters``: the executor's ``EventCounters`` of the ``COUNTED`` board registers
            (RX_FRAMING_ERRORS ... CMD_REFUSED, RATE_ERRORS; word ``counter_word(name)``:
            ``COMMAND_STATS`` are words 0-4), its ``ram`` for ``report`` and for tests
            (``ram.data[k]``).
        ``frames_sent``, ``who_am_i``, ``self_test``, ``level`` (in): read back as board
            registers.
        ``frames_stable`` (in, 1 unless driven): ``frames_sent`` holds the count (the frame
            arbiter's ``frames_stable``): a command waits in the executor until it does (24
            cycles at most, after every 256th frame), so that a read of FRAMES_SENT gets the
            count.
    Latency: a board command's reply is offered three cycles after its last (CRC) byte is
    taken (or once ``frames_stable`` rises, if it is low then); an engine write or read
    waits in addition until the engine takes it (at once while it is idle,
    ``WORST_UPDATE_CYCLES`` at most) and, for a read, its word (one cycle).
    Throughput: a byte every two cycles while parsing (each is looked at, then taken); a
    command then takes a few cycles, or until
    the engine is idle (``WORST_UPDATE_CYCLES`` at most), and its reply's time on the link.
    """
    def __init__(self, *, writable, version, timeout, tick_cycles=1, ports=1):
        self.writable = frozenset(writable)
        self.version = version
        self.timeout = timeout
        self.timeout_ticks = ticks(timeout, tick_cycles, exact=timeout)
        self.fifo = RewindableFIFO(FIFO_DEPTH)
        self.executor = RegisterExecutor(writable=writable, version=version, ports=ports)
        self.counters = self.executor.counters
        self._executing = Signal()          # the parser offers its request (EXECUTE)
        super().__init__({
            "i_stream": In(stream.Signature(8)),
            "cfg": Out(stream.Signature(ConfigWrite)),
            "cfg_read": Out(stream.Signature(REG_BITS)),
            "cfg_read_data": In(stream.Signature(signed(32))),
            "pwm": Out(BoardBusSignature()),
            "control": Out(BoardBusSignature()),
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
            "level": In(ReadLevelStatus),
            "tick": In(1, init=1),
        })

    def invariant(self):
        """What holds in every state a reset reaches: the executor serves this decoder's
        request (port 0) only while the decoder offers it."""
        ex = self.executor
        return ex._idle | (ex._port != 0) | self._executing

    def elaborate(self, platform):
        m = Module()
        # the CRC takes a byte in two halves, high then low (the algorithm reflects nothing:
        # the same CRC as a byte at once), in the two cycles each byte is parsed in: looked
        # at, then taken (``_look``). Half the XORs of a byte-wide one
        m.submodules.crc = crc = CRC(data_width=4).create()
        m.submodules.fifo = fifo = self.fifo
        m.submodules.executor = executor = self.executor
        wiring.connect(m, wiring.flipped(self.i_stream), fifo.w_stream)
        self._executor_ports(m, executor)
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
        # byte ``VALUE_AT`` on, where a write's value begins: a request takes its value from
        # those bits in every command
        payload = Signal(8 * MAX_COMMAND_PAYLOAD, reset_less=True)
        # the next byte's place in ``payload``, one-hot (a register bit is each byte's
        # enable: no decoder of a count)
        place = Signal(MAX_COMMAND_PAYLOAD, reset_less=True)
        gap = Signal(range(self.timeout_ticks + 1))          # ticks without a byte
        addr = payload[:8 * VALUE_AT]
        value = payload[8 * VALUE_AT:8 * VALUE_AT + 32]
        counts = {"discarded": executor.discarded, "crc_errors": executor.crc_errors,
                  "malformed": executor.malformed}

        def count_up(name):
            m.d.comb += counts[name].eq(1)

        m.d.comb += [crc.data.eq(Mux(looked, byte[:4], byte[4:]))]
        request, response = executor.request[0], executor.response[0]
        # The request is made from the command's registers and registered itself as the
        # command passes its CRC (``lost`` pulses then): the executor's decisions start from
        # registers, not from the type's decode in series with them (that chain, into the
        # write check and the PWM block's, was the core's longest path, report --timing)
        asked = Signal(RegisterRequest)
        bad_now = self._request(m, asked, ctype=ctype, length=length, addr=addr, value=value)
        bad = Signal(reset_less=True)
        lost = self._reply(m, ctype, seq, response)
        with m.If(lost):
            m.d.sync += [request.payload.eq(asked), bad.eq(bad_now)]

        parsing = ("HUNT", "SYNC1", "TYPE", "SEQ", "LENGTH", "PAYLOAD", "CRC_HIGH", "CRC_LOW")
        in_frame = Signal()
        timed_out = (gap == self.timeout_ticks) & ~take & in_frame
        with m.FSM() as fsm:
            self._parse(m, SimpleNamespace(
                src=src, fifo=fifo, crc=crc, take=take, byte=byte, looked=looked,
                is_sync0=is_sync0, is_sync1=is_sync1, too_long=too_long, empty=empty,
                crc_ok=crc_ok, high_ok=high_ok, timed_out=timed_out, ctype=ctype, seq=seq,
                length=length, left=left, place=place, payload=payload, count_up=count_up,
                lost=lost))

            with m.State("EXECUTE"):
                # the request, held until the executor is done; its response goes out as the
                # reply (the request is taken as the reply is)
                m.d.comb += [request.valid.eq(1), self._executing.eq(1),
                             self.replies.valid.eq(response.valid),
                             response.ready.eq(self.replies.ready)]
                with m.If(request.ready):
                    with m.If(bad):
                        count_up("malformed")
                    m.next = "HUNT"

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

    def _executor_ports(self, m, executor):
        """The decoder's engine, PWM and board-register ports are its executor's."""
        wiring.connect(m, executor.cfg, wiring.flipped(self.cfg))
        wiring.connect(m, executor.cfg_read, wiring.flipped(self.cfg_read))
        wiring.connect(m, wiring.flipped(self.cfg_read_data), executor.cfg_read_data)
        wiring.connect(m, executor.pwm, wiring.flipped(self.pwm))
        wiring.connect(m, executor.control, wiring.flipped(self.control))
        m.d.comb += [self.raw_mode.eq(executor.raw_mode), self.kick.eq(executor.kick),
                     *(getattr(executor, name).eq(getattr(self, name)) for name in (
                         "rx_framing_error", "rx_overrun", "early_sample", "frames_sent",
                         "frames_stable", "who_am_i", "self_test", "level"))]

    def _reply(self, m, ctype, seq, response):
        """The reply: the command's type and sequence number, the executor's response; and
        ``lost`` (returned: the parser sets it as a command passes its CRC), a byte from the
        host dropped (the input FIFO full) since the last command was taken: its reply says so
        (``RESULT_INPUT_LOST``), for a command lost with it had none."""
        input_lost = Signal()
        said = Signal()                         # this reply's flag, held while it waits
        lost = Signal()
        with m.If(lost):
            m.d.sync += [said.eq(input_lost), input_lost.eq(0)]
        with m.If(self.rx_overrun):
            m.d.sync += input_lost.eq(1)
        reply = self.replies.payload
        m.d.comb += [reply.command.eq(ctype), reply.cmd_seq.eq(seq),
                     reply.result.eq(response.payload.result | Mux(said, RESULT_INPUT_LOST, 0)),
                     reply.addr.eq(response.payload.addr),
                     reply.value.eq(response.payload.value)]
        return lost

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
                m.d.comb += [fifo.release.eq(1), c.lost.eq(1)]
                m.next = "EXECUTE"
            with m.Else():
                count_up("crc_errors")
                m.d.comb += fifo.rewind.eq(1)           # search the rest for a header
                m.next = "HUNT"

    def _request(self, m, req, *, ctype, length, addr, value):
        """The executor's request for the command parsed (combinational, from its registers:
        it holds still while the request waits). Each field an AND-OR of the command's own
        bytes and constants, the selects set by the command's type. Returns ``bad``: a type
        unknown or a length not its."""
        expected = Signal(8)
        known = Signal()
        with m.Switch(ctype):
            for name, (code, n) in COMMANDS.items():
                with m.Case(code):
                    m.d.comb += [expected.eq(n), known.eq(1)]
        bad = ~known | (length != expected)
        echo_mask = Signal(32)                  # the command's value, these bits of it
        value_const = Signal(32)                # OR-ed in: a constant's value
        addr_echo = Signal()                    # the address the command named
        addr_const = Signal(16)                 # OR-ed in: a command's own address
        m.d.comb += [req.value.eq((value & echo_mask) | value_const),
                     Cat(req.addr, req.space).eq(Mux(addr_echo, addr, 0) | addr_const)]

        def ask(op, value_="echo", addr_="echo", result=RESULTS["ok"]):
            m.d.comb += [req.op.eq(op), req.result.eq(result)]
            if value_ in ECHOED:
                m.d.comb += echo_mask.eq(ECHOED[value_])
            else:
                m.d.comb += value_const.eq(value_)
            if addr_ == "echo":
                m.d.comb += addr_echo.eq(1)
            else:
                m.d.comb += addr_const.eq(addr_)

        with m.If(bad):
            ask(RegisterOp.ANSWER, 0, 0, RESULTS["bad_command"])
        with m.Elif(ctype == COMMANDS["write"][0]):
            ask(RegisterOp.WRITE)
        with m.Elif(ctype == COMMANDS["read"][0]):
            ask(RegisterOp.READ, 0)
        with m.Elif(ctype == COMMANDS["filter"][0]):
            with m.If(value[:8] <= max(FILTER_CODES.values())):
                ask(RegisterOp.WRITE, "byte", CONTROL_ADDR)
            with m.Else():
                ask(RegisterOp.ANSWER, "byte", CONTROL_ADDR, RESULTS["refused"])
        with m.Elif(ctype == COMMANDS["reset"][0]):
            ask(RegisterOp.WRITE, CONTROL_KEEP | CONTROL_RESET, CONTROL_ADDR)
        with m.Elif(ctype == COMMANDS["rate"][0]):
            ask(RegisterOp.WRITE, "half", TELEMETRY_DIV_ADDR)
        with m.Elif(ctype == COMMANDS["raw"][0]):
            ask(RegisterOp.WRITE, "bit", (SPACES["board"] << 8) | BOARD_REGS["RAW_MODE"])
        with m.Else():                                  # who
            ask(RegisterOp.ANSWER, self.version, REGMAP_VERSION)
        return bad
