"""Telemetry framer: packs a struct (a ``Sample`` plus the driver status) into framed bytes.

Frame (all bytes on the wire in this order)
    ``0xA5 0x5A``  sync
    ``type``       frame type: 0x01 = ``SensorFrame`` (sample and driver status),
                   0x02 = ``AttitudeFrame`` (attitude result, the sample it came from, driver
                   status latched with it, telemetry counters; ``hdl/telemetry_scheduler.py``)
    ``length``     payload length in bytes
    payload        the frame struct packed as its ``lib.data`` layout says, least significant
                   byte first (padded with zeros to whole bytes)
    ``crc``        CRC-8/SMBUS (polynomial 0x07, init 0) over type, length and payload

``mpu9250_ahrs.sim.telemetry`` decodes frames with the same layouts, so the gateware and the
host never disagree on a field position.

Interface
    ``i_stream`` (in, stream of the frame layout): one frame per transfer; its payload is read
        byte by byte while it is sent and acknowledged (``ready``) with the last byte.
    ``o_stream`` (out, byte stream): to a UART transmitter.
Throughput: ``length + 5`` bytes per frame, one byte per ``o_stream`` handshake.
``TelemetryFramer`` below has the details (and a buffered mode: the attitude frames).
"""

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.crc.catalog import CRC8_SMBUS
from amaranth.lib.wiring import In, Out

from .memories import FrameRAM
from .sample import DriverStatus, Sample
from .telemetry_scheduler import AttitudeFrame


__all__ = ["SYNC", "CRC", "SensorFrame", "AttitudeFrame", "FRAME_TYPES", "TelemetryFramer"]


SYNC = (0xA5, 0x5A)
CRC = CRC8_SMBUS


class SensorFrame(data.Struct):
    sample: Sample
    status: DriverStatus


FRAME_TYPES = {0x01: SensorFrame, 0x02: AttitudeFrame}


def payload_bytes(layout):
    return (data.Layout.cast(layout).size + 7) // 8


def frame_bytes(layout):
    """Bytes on the wire for a frame of ``layout``: sync (2), type, length, payload, CRC."""
    return payload_bytes(layout) + 5


class TelemetryFramer(wiring.Component):
    """Frames a struct: sync, type, length, payload, CRC, one byte per ``o_stream`` transfer.

    Parameters
        ``layout``, ``frame_type``: the payload struct and its type byte.
        ``buffered``: False: the payload is read byte by byte while it is sent, so the producer
            holds it (``valid``, payload still) for the whole frame, and ``ready`` comes with
            the last byte. True: the payload is first copied into a ``FrameRAM`` (one M9K), a
            32-bit word per cycle, and acknowledged when the copy ends (⌈``length``/4⌉ cycles
            after ``valid``, if ``idle``); the frame is then sent from the copy, so the
            producer is free to change the payload after those cycles, whatever the UART's
            rate.
        ``blackbox``: the RAM as an empty module (``report``'s synthesis).
    Members
        ``i_stream`` (in, stream of ``layout``); ``o_stream`` (out, byte stream, to a UART).
        ``idle`` (out): buffered: no frame is being copied or sent (a frame offered now is
            copied at once). Unbuffered: no frame is being sent.
    Throughput: ``length + 5`` bytes per frame.
    """
    def __init__(self, layout=SensorFrame, frame_type=0x01, *, buffered=False, blackbox=False):
        self.layout = layout
        self.frame_type = frame_type
        self.buffered = buffered
        self.length = payload_bytes(layout)
        if self.length > 255:
            raise ValueError("telemetry payload longer than 255 bytes")
        self.frame_bytes = frame_bytes(layout)
        # the copy goes a 32-bit word per cycle: a 21-way multiplexer of words costs fewer
        # LUTs than an 81-way one of bytes
        self.words = (self.length + 3) // 4
        self.ram = FrameRAM(self.words, 32, blackbox=blackbox) if buffered else None
        super().__init__({
            "i_stream": In(stream.Signature(layout)),
            "o_stream": Out(stream.Signature(8)),
            "idle": Out(1),
        })

    def elaborate(self, platform):
        m = Module()
        n = self.length
        index = Signal(range(n + 5))
        m.submodules.crc = crc = CRC(data_width=8).create()

        value = self.i_stream.payload.as_value()
        bits = Cat(value, C(0, 8 * n - len(value)))
        payload_bytes = Array(bits[8 * i:8 * i + 8] for i in range(n))
        sent = self.o_stream.valid & self.o_stream.ready
        last = sent & (index == n + 4)

        if self.buffered:
            m.submodules.ram = ram = self.ram
            sending = Signal()
            words = self.words
            copy_index = Signal(range(words))
            wide = Cat(value, C(0, 32 * words - len(value)))
            payload_words = Array(wide[32 * i:32 * i + 32] for i in range(words))
            # copy: the payload's words into the RAM, one per cycle, through one multiplexer
            with m.If(self.i_stream.valid & ~sending):
                m.d.comb += [ram.w_en.eq(1), ram.w_addr.eq(copy_index),
                             ram.w_data.eq(payload_words[copy_index])]
                m.d.sync += copy_index.eq(copy_index + 1)
                with m.If(copy_index == words - 1):
                    m.d.comb += self.i_stream.ready.eq(1)
                    m.d.sync += [copy_index.eq(0), sending.eq(1)]
            with m.If(last):
                m.d.sync += sending.eq(0)
            # send: each handshake reads the word of the next payload byte (the read data holds
            # between), and the byte is picked from it
            ahead = Signal(range(n + 5))
            m.d.comb += [ahead.eq(index - 3),
                         self.o_stream.valid.eq(sending), ram.r_en.eq(sent),
                         ram.r_addr.eq(ahead[2:]),
                         self.idle.eq(~sending & (copy_index == 0))]
            payload_byte = ram.r_data.word_select((index - 4)[:2], 8)
        else:
            m.d.comb += [self.o_stream.valid.eq(self.i_stream.valid),
                         self.i_stream.ready.eq(last), self.idle.eq(index == 0)]
            # straight from the payload: the stream keeps it still until ``ready``
            payload_byte = payload_bytes[index - 4]

        byte = Signal(8)
        with m.Switch(index):
            with m.Case(0):
                m.d.comb += byte.eq(SYNC[0])
            with m.Case(1):
                m.d.comb += byte.eq(SYNC[1])
            with m.Case(2):
                m.d.comb += byte.eq(self.frame_type)
            with m.Case(3):
                m.d.comb += byte.eq(n)
            with m.Case(n + 4):
                m.d.comb += byte.eq(crc.crc)
            with m.Default():
                m.d.comb += byte.eq(payload_byte)

        m.d.comb += [
            self.o_stream.payload.eq(byte),
            crc.data.eq(byte),
            crc.start.eq(sent & (index == 0)),
            crc.valid.eq(sent & (index >= 2) & (index < n + 4)),
        ]
        with m.If(sent):
            m.d.sync += index.eq(Mux(index == n + 4, 0, index + 1))
        return m
