"""The frame types of the link (``hdl/FRAMES.md``): type byte -> payload layout."""

from amaranth.lib import data

from .command_decoder import Reply
from .telemetry import SensorFrame, payload_bytes
from .telemetry_scheduler import AttitudeFrame


__all__ = ["FRAME_TYPES", "SENSOR", "ATTITUDE", "REPLY"]


SENSOR, ATTITUDE, REPLY = 0x01, 0x02, 0x81
FRAME_TYPES = {SENSOR: SensorFrame, ATTITUDE: AttitudeFrame, REPLY: Reply}

# raw-sample mode sends an attitude frame's first bytes as a sensor frame
assert data.Layout.cast(AttitudeFrame).size >= 8 * payload_bytes(SensorFrame)
assert (data.Layout.cast(SensorFrame).size + 1) % 8 == 0, "AttitudeFrame.reserved pads to a byte"
