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
"""

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.crc.catalog import CRC8_SMBUS
from amaranth.lib.wiring import In, Out

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


class TelemetryFramer(wiring.Component):
    def __init__(self, layout=SensorFrame, frame_type=0x01):
        self.layout = layout
        self.frame_type = frame_type
        self.length = payload_bytes(layout)
        if self.length > 255:
            raise ValueError("telemetry payload longer than 255 bytes")
        self.frame_bytes = self.length + 5
        super().__init__({
            "i_stream": In(stream.Signature(layout)),
            "o_stream": Out(stream.Signature(8)),
        })

    def elaborate(self, platform):
        m = Module()
        n = self.length
        index = Signal(range(n + 5))
        m.submodules.crc = crc = CRC(data_width=8).create()

        # Bytes straight from the payload through a byte multiplexer: the stream keeps the
        # payload stable until ``ready``, which comes with the last byte, so no copy of the
        # frame is needed (a copy would cost a register per payload bit).
        value = self.i_stream.payload.as_value()
        bits = Cat(value, C(0, 8 * n - len(value)))
        payload_bytes = Array(bits[8 * i:8 * i + 8] for i in range(n))
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
                m.d.comb += byte.eq(payload_bytes[index - 4])

        sent = self.o_stream.valid & self.o_stream.ready
        m.d.comb += [
            self.o_stream.valid.eq(self.i_stream.valid),
            self.o_stream.payload.eq(byte),
            crc.data.eq(byte),
            crc.start.eq(sent & (index == 0)),
            crc.valid.eq(sent & (index >= 2) & (index < n + 4)),
            self.i_stream.ready.eq(sent & (index == n + 4)),
        ]
        with m.If(sent):
            m.d.sync += index.eq(Mux(index == n + 4, 0, index + 1))
        return m
