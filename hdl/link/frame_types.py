"""The link's frames (``hdl/FRAMES.md``): the format's constants, the payload layouts and
their type bytes. The framers, the scheduler and the command decoder build frames from these.

Frame (all bytes on the wire in this order)
    ``0xA5 0x5A``  sync
    ``type``       frame type (``FRAME_TYPES``): 0x01 ``SensorFrame`` (a sample and the driver
                   status), 0x02 ``AttitudeFrame`` (an attitude result, the sample it came
                   from, the driver status latched with it, telemetry counters;
                   made by ``hdl/link/telemetry_scheduler.py``), 0x81 ``Reply`` (to a host command,
                   made by ``hdl/link/command_decoder.py``)
    ``seq``        sequence number: the board's frames are numbered 0, 1, 2 ... (mod 256) in
                   the order they leave (``FrameArbiter``), whatever their type, so a gap is a
                   lost frame
    ``length``     payload length in bytes
    payload        the frame struct packed as its ``lib.data`` layout says, least significant
                   byte first (padded with zeros to whole bytes)
    ``crc``        CRC-16/IBM-3740 (polynomial 0x1021, initial 0xFFFF, no reflection, no final
                   XOR) over type, seq, length and payload, most significant byte first; why
                   this one: ``hdl/FRAMES.md``

``mpu9250_ahrs.host.protocol`` decodes frames with the same layouts, so the gateware and the
host never disagree on a field position.
"""

from amaranth.lib import data
from amaranth.lib.crc.catalog import CRC16_IBM_3740

from ..engine.attitude_result import Attitude
from ..sensor.driver_status import DriverStatus
from ..sensor.sample import Sample


__all__ = ["SYNC", "CRC", "HEADER_BYTES", "FrameByte", "SensorFrame", "payload_bytes",
           "frame_bytes", "TelemetryCounters", "FramedAttitude", "AttitudeFrame", "Reply",
           "FRAME_TYPES", "SENSOR", "ATTITUDE", "REPLY"]


SYNC = (0xA5, 0x5A)
# Every 1-, 2- and 3-bit error in any frame up to 4,095 bytes: hdl/FRAMES.md says why.
CRC = CRC16_IBM_3740
HEADER_BYTES = 5                       # sync (2), type, seq, length; then payload, CRC (2)


class FrameByte(data.Struct):
    """A byte of a frame on its way to the UART; ``last`` marks the frame's final byte (the
    ``FrameArbiter`` hands the link to another framer only after it)."""
    data: 8
    last: 1


class SensorFrame(data.Struct):
    sample: Sample
    status: DriverStatus


def payload_bytes(layout):
    return (data.Layout.cast(layout).size + 7) // 8


def frame_bytes(layout):
    """Bytes on the wire for a frame of ``layout``: sync (2), type, seq, length, payload,
    CRC (2)."""
    return payload_bytes(layout) + HEADER_BYTES + 2


class TelemetryCounters(data.Struct):
    """Counters carried in every attitude frame (all since reset, wrapping at 2³²).

    - ``filtered``: results the engine produced, this frame's included.
    - ``lost``: sensor samples that were never filtered: the sum of ``Sample.skipped`` (made
      by the sensor but never read, or read and dropped because the engine was busy). The
      engine integrates the time they cover, so the attitude stays right; only their
      measurements are missing.
    - ``not_sent``: results that were due for telemetry (every ``divider``-th) while the
      previous frame was still being sent.
    """
    filtered: 32
    lost: 32
    not_sent: 32


# An ``Attitude`` without its counter, which is the sample's (framed beside it).
FramedAttitude = data.StructLayout({name: field.shape
                                    for name, field in data.Layout.cast(Attitude)
                                    if name != "counter"})


class AttitudeFrame(data.Struct):
    """Frame type 0x02: the sample an attitude result came from and the driver status latched
    with that sample (first, and padded to whole bytes: these 29 bytes are exactly a
    ``SensorFrame``'s payload, which raw-sample mode sends alone as frame type 0x01), the
    result (its counter is the sample's), the telemetry counters at the time the result was
    taken, and the host writes the engine refused so far (``cfg_refused``: to read-only or
    state registers)."""
    sample: Sample
    status: DriverStatus
    attitude: FramedAttitude
    counters: TelemetryCounters
    cfg_refused: 16


class Reply(data.Struct):
    """Frame type 0x81: the answer to a command that arrived whole and with a good CRC.
    ``command`` and ``cmd_seq`` are the command's type and sequence number; ``result`` a
    ``RESULTS`` code; ``addr`` and ``value``: a read's address and word, a write's address
    and the value written; for "who": ``addr`` the register-map version, ``value`` the
    version/build word."""
    command: 8
    cmd_seq: 8
    result: 8
    addr: 16
    value: 32


SENSOR, ATTITUDE, REPLY = 0x01, 0x02, 0x81
FRAME_TYPES = {SENSOR: SensorFrame, ATTITUDE: AttitudeFrame, REPLY: Reply}

# raw-sample mode sends an attitude frame's first bytes as a sensor frame
assert data.Layout.cast(AttitudeFrame).size >= 8 * payload_bytes(SensorFrame)
assert data.Layout.cast(SensorFrame).size % 8 == 0, "a SensorFrame is whole bytes"
