"""The sample store: the last samples in one block RAM, written by the sample reader (the
sensor bytes as the burst arrives, the rest once the sample is offered), read by the attitude
engine's loader and, through the engine, by the attitude framer.

Why: a sample is 203 bits. Held in flip-flops, every reader of it needs a multiplexer of its
words, and in a LUT4 fabric a multiplexer costs about a LUT per input bit (the engine's
multiplexer of the sample it held, for its loader and the framer, was 286 LUTs of ``report``'s
flow before this store: the engine alone, 3,008 LUTs with it and 2,722 with it tied to 0).
Written where it is kept as the bytes come off the bus, and read through the block RAM's own
read port, it costs no multiplexer in front of its readers.

Layout. The RAM has ``SLOTS`` slots of ``SLOT_WORDS`` 32-bit words (``SAMPLE_STORE_DEPTH`` words,
one M9K). Slot ``s``'s words ``0 .. STORE_WORDS - 1`` (at address ``s·SLOT_WORDS + k``) are a
``Sample``'s bits ``32·k .. 32·k + 31``, the last word padded with zeros: ``accel``, ``temp``,
``gyro``, ``mag`` (the sensor bytes, written as they arrive: ``store_places``), then
``counter``, ``flags`` and ``skipped`` (written in the cycles after the sample is offered, from
the payload, which has them too). ``mag`` is 0 while the magnetometer is not up, as in the
payload: the reader then writes zeros over the field's bytes after them (``SampleReader``).

Slots. The reader writes a burst into slot ``W``; a burst that becomes the sample offered makes
``W`` the offered slot (``sample_slot``, beside the stream: it holds still while the sample is
valid) and the next slot, modulo ``SLOTS``, the one written. The engine holds the slot it last
took until it takes the next (its framer copies the sample from there). With three slots the one
written is never the one offered nor the one the engine holds: the offered slot is ``W − 1``, and
the held one is the offered one or the one before it, ``W + 1`` (the engine takes a sample only
once the result of the one before was framed and taken). The early start (issue #58,
``SampleReader.imu_ready``) makes ``W`` the offered slot once the burst's gyro and
accelerometer bytes are in, while the AK8963's still go there: the engine then holds the slot
being written, reading only the words already in (its field's words at its SYNC, once the
sample is offered and the writes after the offer are in); ``W`` moves on at the offer, as
before.
"""

from amaranth.lib import data, wiring
from amaranth.lib.wiring import Out

from ..contract import ak8963_regs as A
from ..contract import mpu9250_regs as R
from ..primitives.memories import FrameRAM
from .sample import Sample


__all__ = ["SLOTS", "SLOT_WORDS", "STORE_WORDS", "SAMPLE_STORE_DEPTH", "STORE_BITS", "SENSOR_BITS",
           "OFFER_WRITES", "FIELD_LANES",
           "SampleStoreWriteSignature", "store_places", "sample_store_ram"]


SLOTS = 3
SLOT_WORDS = 8                  # a power of two: an address is the slot, then the word
_SAMPLE = data.Layout.cast(Sample)
STORE_BITS = _SAMPLE.size
STORE_WORDS = (STORE_BITS + 31) // 32
SENSOR_BITS = _SAMPLE["mag"].offset + data.Layout.cast(_SAMPLE["mag"].shape).size
SAMPLE_STORE_DEPTH = SLOTS * SLOT_WORDS
assert STORE_WORDS <= SLOT_WORDS
assert SENSOR_BITS % 32 == 0 and all(_SAMPLE[name].offset < SENSOR_BITS
                                     for name in ("accel", "temp", "gyro", "mag")), \
    "the sensor fields are not the first whole words"


class SampleStoreWriteSignature(wiring.Signature):
    """The reader's write port of the store: ``w_en`` (4, a byte lane each), ``w_addr``
    (slot·``SLOT_WORDS`` + word), ``w_data`` (32)."""
    def __init__(self):
        super().__init__({"w_en": Out(4), "w_addr": Out(range(SAMPLE_STORE_DEPTH)),
                          "w_data": Out(32)})


def store_places(sample_bytes, mpu_bytes):
    """Where each byte of a sample burst goes in a slot, by its index in the burst: a dict of
    index: (word, lane), for the bytes of ``accel``, ``temp``, ``gyro`` (big-endian, from index
    1: INT_STATUS first) and ``mag`` (HXL .. HZH, little-endian, after ST1 at ``mpu_bytes``).
    INT_STATUS, ST1 and ST2 are not stored."""
    layout = _SAMPLE
    places = {}
    first = layout["accel"].offset // 8
    for k in range(mpu_bytes - 1):                    # ACCEL_XOUT_H .. GYRO_ZOUT_L
        byte = first + (k ^ 1)                          # big-endian words
        places[1 + k] = divmod(byte, 4)
    first = layout["mag"].offset // 8
    for k in range(2 * 3):                            # HXL .. HZH
        places[mpu_bytes + 1 + k] = divmod(first + k, 4)
    assert max(places) < sample_bytes and all(w < SENSOR_BITS // 32 for w, _ in places.values())
    return places


assert len(store_places(1 + R.SENSOR_BYTES + A.SAMPLE_BYTES, 1 + R.SENSOR_BYTES)) == \
    SENSOR_BITS // 8, "a sensor byte without its place in the burst"


def _field_lanes():
    """The magnetometer field's words in a slot, each with its byte lanes (a mask)."""
    lanes = {}
    for byte in range(_SAMPLE["mag"].offset // 8, SENSOR_BITS // 8):
        word, lane = divmod(byte, 4)
        lanes[word] = lanes.get(word, 0) | 1 << lane
    return tuple(sorted(lanes.items()))


# The reader's writes after a sample is offered, a word a cycle from the first cycle of
# ``valid``: the payload's words after the sensor fields, then (magnetometer down) zeros over
# the field's words (``FIELD_LANES``: word, lanes). A reader of the slot sees the field as the
# payload has it from the cycle after the last of them (the engine's loader reads the
# field's words later than that).
FIELD_LANES = _field_lanes()
OFFER_WRITES = (STORE_WORDS - SENSOR_BITS // 32) + len(FIELD_LANES)


def sample_store_ram():
    """The store's RAM: one M9K (``FrameRAM`` with byte enables)."""
    return FrameRAM(SAMPLE_STORE_DEPTH, 32, lanes=4)
