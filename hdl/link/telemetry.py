"""Telemetry framer: packs a struct (a ``Sample`` plus the driver status, an attitude result,
a reply to a command) into a frame of the link layer (``hdl/link/frame_types.py`` has the format and
the layouts, ``hdl/FRAMES.md`` the reasons).
"""

import operator
from functools import reduce
from types import SimpleNamespace

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out

from .frame_types import CRC, SYNC, FrameByte, SensorFrame, payload_bytes, frame_bytes
from ..primitives.memories import FrameRAM


__all__ = ["TelemetryFramer"]


class TelemetryFramer(wiring.Component):
    """Frames a struct: sync, type, seq, length, payload, CRC-16, one byte per ``o_stream``
    transfer.

    Parameters
        ``layout``, ``frame_type``: the payload struct and its type byte.
        ``buffered``: False: the payload is read byte by byte while it is sent, so the producer
            holds it (``valid``, payload still) for the whole frame, and ``ready`` comes with
            the last byte. True: the payload is first copied into a ``FrameRAM`` (one M9K), a
            32-bit word per cycle, and acknowledged when the copy ends (⌈``length``/4⌉ cycles
            after ``valid``, if ``idle``); the frame is then sent from the copy, so the
            producer is free to change the payload after those cycles, whatever the UART's
            rate.
        ``short`` (buffered only): None, or ``(type, layout)``: a second frame type whose
            payload is the first bytes of ``layout``'s (its layout's bits must be the first
            bits of ``layout``, in whole bytes). A frame offered while the ``short`` input is
            high is sent as that type, cut to that length (raw-sample mode sends the sample
            and status of an attitude frame so).
        ``fetch`` (buffered only): None, or ``(offset, n)``: the payload's ``n`` 32-bit words
            from bit ``offset`` (a multiple of 8) are not read from ``i_stream``'s payload but
            through a read port, one a cycle during the copy, word ``k`` from index ``k``
            (the attitude engine's result, read from its register file: in a LUT4 fabric a
            multiplexer costs about a LUT per input bit, and the copy's is most of the
            framer). The producer's port must give the word the payload would hold, the
            cycle after ``fetch_en``, while ``i_stream`` is valid, and 0 the cycle after one
            without ``fetch_en`` while a frame is offered and in the cycle before (the copy
            ORs the port's word in whatever the word copied: no gate of its own).
        ``borrow`` (buffered only): None, or ``(offset, bits)``: the payload's ``bits`` bits from
            bit ``offset`` (a multiple of 32) are not read from ``i_stream``'s payload either, but
            through a synchronous read port: their word ``k`` is ``borrow_data`` in the cycle
            after ``borrow_index`` was ``k``; the port is read every cycle, a word ahead of the
            copy (word 0 while no frame is copied), and index ``⌈bits/32⌉`` outside the
            borrowed words, for which it must give 0 (the copy ORs the word in whatever the
            word copied). The sample an attitude result came from,
            read from the sample store through the engine's port, which its loader uses too
            (``hdl/sensor/sample_store.py``). The bits of the last word beyond ``bits`` must read 0;
            ``i_stream``'s payload gives the rest of that word.
        ``shared_crc`` (False): the CRC-16 is not computed here but by a processor outside,
            which framers whose frames never interleave (a ``FrameArbiter``'s) share: the
            framer drives ``crc_data``, ``crc_start`` and ``crc_valid`` (out: its
            ``amaranth.lib.crc`` inputs, ``start`` and ``valid`` high only while this framer
            sends) and reads ``crc_value`` (in, 16: its ``crc``).
    Members
        ``i_stream`` (in, stream of ``layout``); ``o_stream`` (out, stream of ``FrameByte``:
            to a ``FrameArbiter``, or a UART taking ``data``).
        ``seq`` (in, 8): the sequence number, read when the type byte (the one before it)
            is sent, and held for the seq byte.
        ``short`` (in): see above; sampled when the copy starts.
        ``idle`` (out): buffered: no frame is being copied or sent (a frame offered now is
            copied at once). Unbuffered: no frame is being sent.
        ``fetch_en``, ``fetch_index`` (out), ``fetch_data`` (in, 32): with ``fetch``, the read
            port (above).
        ``borrow_index`` (out), ``borrow_data`` (in, 32): with ``borrow``, its port (above):
            the producer must keep the words still while it offers the payload and in the
            cycle before.
    Throughput: ``length + 7`` bytes per frame.
    Latency: the first sync byte is offered in the cycle the payload is (unbuffered), or once
    the copy ends, ⌈``length``/4⌉ cycles after it (buffered).
    """
    def __init__(self, layout=SensorFrame, frame_type=0x01, *, buffered=False, short=None,
                 fetch=None, borrow=None, shared_crc=False):
        self.layout = layout
        self.frame_type = frame_type
        self.buffered = buffered
        self.length = payload_bytes(layout)
        if self.length > 255:
            raise ValueError("telemetry payload longer than 255 bytes")
        self.frame_bytes = frame_bytes(layout)
        if short is not None and not buffered:
            raise ValueError("a short frame type needs a buffered framer")
        self.short_type = None if short is None else short[0]
        self.short_length = None if short is None else payload_bytes(short[1])
        # the copy goes a 32-bit word per cycle: a 22-way multiplexer of words costs fewer
        # LUTs than an 85-way one of bytes
        self.words = (self.length + 3) // 4
        self.ram = FrameRAM(self.words, 32) if buffered else None
        members = {
            "i_stream": In(stream.Signature(layout)),
            "o_stream": Out(stream.Signature(FrameByte)),
            "seq": In(8),
            "short": In(1),
            "idle": Out(1),
        }
        self.shared_crc = shared_crc
        if shared_crc:
            members.update({"crc_data": Out(8), "crc_start": Out(1), "crc_valid": Out(1),
                            "crc_value": In(16)})
        self.fetch = fetch
        if fetch is not None:
            offset, n = fetch
            if not buffered:
                raise ValueError("fetched words need a buffered framer")
            # word 0 is fetched the cycle before its frame word is copied: not the first
            if offset % 8 or offset < 32 or n < 1 or \
                    offset + 32 * n > data.Layout.cast(layout).size:
                raise ValueError(f"fetch {fetch}: {n} words from a bit offset that is a "
                                 f"multiple of 8, at least 32, inside the payload")
            members.update({"fetch_en": Out(1), "fetch_index": Out(range(n)),
                            "fetch_data": In(32)})
        self.borrow = borrow
        if borrow is not None:
            offset, bits = borrow
            size = data.Layout.cast(layout).size
            fetched = range(0) if fetch is None else range(fetch[0], fetch[0] + 32 * fetch[1])
            if not buffered or offset % 32 or bits < 1 or offset + bits > size or \
                    (fetched and offset < fetched.stop and fetched.start < offset + bits):
                raise ValueError(f"borrow {borrow}: a buffered framer's bits from a multiple "
                                 f"of 32, inside the payload, apart from the fetched words")
            members.update({"borrow_index": Out(range((bits + 31) // 32 + 1)),
                            "borrow_data": In(32)})
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        n = self.length
        index = Signal(range(n + 7))        # the byte being sent (unbuffered: ``place``)
        if self.shared_crc:
            crc = SimpleNamespace(data=self.crc_data, start=self.crc_start,
                                  valid=self.crc_valid, crc=self.crc_value)
        else:
            m.submodules.crc = crc = CRC(data_width=8).create()

        value = self.i_stream.payload.as_value()
        bits = Cat(value, C(0, 8 * n - len(value)))
        sent = self.o_stream.valid & self.o_stream.ready
        # the frame's length and type: this one's, or (short) the short type's
        length = Signal(8, init=n)
        ftype = Signal(8, init=self.frame_type)
        # the index of the CRC's high byte, length + 5: with a short type (the length a
        # register) a register of its own, loaded with the length, and ``end`` (the byte at the
        # index is the CRC's low one, the last) registered as the high one is sent: no adder
        # before the comparisons with the index. Else constants
        if self.short_type is not None:
            crc_index = Signal(8, init=n + 5)
            end = Signal()
            with m.If(sent):
                m.d.sync += end.eq(index == crc_index)
        else:
            crc_index = C(n + 5, 8)
            # unbuffered, the last place's bit (``_places``), made below
            end = (index == n + 6) if self.buffered else None
        at = self._places(m, index, sent, end)
        if end is None:
            end = at(n + 6)
        last = sent & end

        if self.buffered:
            m.submodules.ram = ram = self.ram
            sending = Signal()
            words = self.words
            copy_index = Signal(range(words))
            copy_oh = Signal(words, init=1)
            wide = Cat(value, C(0, 32 * words - len(value)))
            payload_words = [wide[32 * i:32 * i + 32] for i in range(words)]
            fetched = C(0, 32)
            if self.fetch is not None:
                payload_words, fetched = self._fetched(m, payload_words, copy_index, sending)
            if self.borrow is not None:
                payload_words, borrowed = self._borrowed(m, payload_words, copy_index, sending)
                fetched = fetched | borrowed
            # copy: the payload's words into the RAM, one per cycle, each an AND with its bit
            # of ``copy_oh`` (the copy's word, one-hot beside ``copy_index``, the RAM's
            # address), OR-ed: no decoder of the index in front of the data (the address and
            # data ungated: ``w_en`` says when)
            m.d.comb += [ram.w_addr.eq(copy_index),
                         ram.w_data.eq(reduce(operator.or_, (
                             Mux(copy_oh[i], word, 0)
                             for i, word in enumerate(payload_words)), fetched))]
            with m.If(self.i_stream.valid & ~sending):
                m.d.comb += ram.w_en.eq(1)
                m.d.sync += [copy_index.eq(copy_index + 1), copy_oh.eq(copy_oh.rotate_left(1))]
                if self.short_type is not None:
                    with m.If(copy_oh[0]):
                        m.d.sync += [length.eq(Mux(self.short, self.short_length, n)),
                                     crc_index.eq(Mux(self.short, self.short_length + 5, n + 5)),
                                     ftype.eq(Mux(self.short, self.short_type,
                                                  self.frame_type))]
                with m.If(copy_oh[words - 1]):
                    m.d.comb += self.i_stream.ready.eq(1)
                    m.d.sync += [copy_index.eq(0), sending.eq(1)]
            with m.If(last):
                m.d.sync += sending.eq(0)
            # send: each handshake reads the word of the next payload byte (the read data holds
            # between), and the byte is picked from it
            ahead = Signal(range(n + 7))
            m.d.comb += [ahead.eq(index - 4),
                         self.o_stream.valid.eq(sending), ram.r_en.eq(sent),
                         ram.r_addr.eq(ahead[2:]),
                         self.idle.eq(~sending & copy_oh[0])]
            payload_byte = Mux((index >= 5) & (index < crc_index),
                               ram.r_data.word_select((index - 5)[:2], 8), 0)
        else:
            m.d.comb += [self.o_stream.valid.eq(self.i_stream.valid),
                         self.i_stream.ready.eq(last), self.idle.eq(at(0))]
            # straight from the payload: the stream keeps it still until ``ready``; each byte
            # an AND with its index's decode, OR-ed (a LUT4 takes two bytes' bits and their
            # decodes: no subtraction of the index, no tree of choices on its bits)
            payload_byte = 0
            for i in range(n):
                payload_byte = payload_byte | Mux(at(5 + i), bits[8 * i:8 * i + 8], 0)

        # ``seq`` is taken a byte early, so the seq byte holds still while it waits for
        # ``ready`` whatever the input does (the arbiter's changes only between frames anyway)
        seq = Signal(8)
        with m.If(sent & at(2)):
            m.d.sync += seq.eq(self.seq)

        # the frame's bytes, each an AND with its place's decode, OR-ed (the places are
        # distinct; ``payload_byte`` is 0 outside the payload's, from 5 to the CRC's)
        byte = Signal(8)
        crc_high = (index == crc_index) if self.buffered else at(n + 5)
        m.d.comb += byte.eq(Mux(at(0), SYNC[0], 0) | Mux(at(1), SYNC[1], 0) |
                            Mux(at(2), ftype, 0) | Mux(at(3), seq, 0) |
                            Mux(at(4), length, 0) | Mux(crc_high, crc.crc[8:], 0) |
                            Mux(end, crc.crc[:8], 0) | payload_byte)
        m.d.comb += [
            self.o_stream.payload.data.eq(byte),
            self.o_stream.payload.last.eq(end),
            crc.data.eq(byte),
            crc.start.eq(sent & at(0)),
            crc.valid.eq(sent & ((index >= 2) & (index < crc_index) if self.buffered
                                 else Cat(at(k) for k in range(2, n + 5)).any())),
        ]
        if self.buffered:
            with m.If(sent):
                m.d.sync += index.eq(Mux(end, 0, index + 1))
        return m

    def _places(self, m, index, sent, end):
        """``at(k)``, 1 while the byte at place ``k`` of the frame is offered (returned):
        buffered, for the header's five a bit of ``head`` (one-hot, back to 0 after ``end``,
        the last byte), else ``index == k``; unbuffered, where every place is a constant, a bit of
        ``place``, the places one-hot (rotated as a byte is sent), so that each byte's decode
        is a register."""
        if self.buffered:
            # the header's five places one-hot (0 in the payload and the CRC)
            head = Signal(5, init=1)
            with m.If(sent):
                m.d.sync += head.eq(Mux(end, 1, head << 1))
            return lambda k: head[k] if k < 5 else index == k
        place = Signal(self.length + 7, init=1)
        with m.If(sent):
            m.d.sync += place.eq(place.rotate_left(1))
        return lambda k: place[k]

    def _fetched(self, m, payload_words, copy_index, sending):
        """The copy with ``fetch``: the payload's words with the fetched bits left out (zero:
        no multiplexer inputs), and the fetched bits of the word copied now, to be ORed in.
        Word ``k`` is fetched a cycle before the copy writes the frame word that holds its
        low bits; its high bits (``offset`` not a multiple of 32) go into the next frame
        word, from ``held``."""
        offset, n = self.fetch
        first, shift = divmod(offset, 32)       # the frame word of fetched word 0, bit shift
        low = 32 - shift                        # the fetched word's bits in its first frame word
        copying = self.i_stream.valid & ~sending
        m.d.comb += [self.fetch_en.eq(copying & (copy_index >= first - 1) &
                                      (copy_index < first + n - 1)),
                     self.fetch_index.eq(copy_index - first + 1)]
        # The port gives 0 outside the fetched words (``fetch``), so neither its word nor
        # ``held`` (loaded from it in every cycle of the copy: 0 again by the word after the
        # last) needs a gate: a gate is a LUT a bit in the copy's multiplexer
        held = Signal(max(shift, 1), reset_less=True)
        if shift:
            with m.If(copying):
                m.d.sync += held.eq(self.fetch_data[low:])
        fetched = Cat(held[:shift], self.fetch_data[:low])
        words = []
        for i, word in enumerate(payload_words):
            keep = [1] * 32
            if first <= i < first + n:
                keep[shift:] = [0] * low
            if first < i <= first + n:
                keep[:shift] = [0] * shift
            mask = sum(b << j for j, b in enumerate(keep))
            words.append(word & mask if mask != (1 << 32) - 1 else word)
        return words, fetched

    def _borrowed(self, m, payload_words, copy_index, sending):
        """The copy with ``borrow``: the payload's words with the borrowed bits left out, and
        the borrowed word of the frame word copied now (0 outside them), to be ORed in. The
        port is asked for the word of the next cycle's copy: ``copy_index`` is 0 between
        copies, so the first word is in before a copy starts."""
        offset, bits = self.borrow
        first, n = offset // 32, (bits + 31) // 32
        copying = self.i_stream.valid & ~sending

        def index_of(k):
            # the port's index for copy word k; outside the borrowed words index n, a word of
            # zeros, so that the port's word needs no gate here (a LUT a bit in the copy's
            # multiplexer)
            return Mux((k >= first) & (k < first + n), k - first, n)
        # the next cycle's copy word is ``copy_index`` + ``copying``: the index for each case
        # from the register, and the choice last, so that only it follows ``copying`` (the
        # producer's valid) into the port's address, not the adder and comparisons (that
        # path, into the sample store's address, was the routed critical one on some seeds,
        # report --timing)
        m.d.comb += self.borrow_index.eq(Mux(copying, index_of(copy_index + 1),
                                             index_of(copy_index)))
        words = []
        for i, word in enumerate(payload_words):
            low, high = max(offset, 32 * i), min(offset + bits, 32 * i + 32)
            if low < high:
                mask = ((1 << 32) - 1) ^ (((1 << (high - low)) - 1) << (low - 32 * i))
                word = word & mask
            words.append(word)
        return words, self.borrow_data
