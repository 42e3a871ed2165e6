"""Host-side decoder for the gateware's telemetry frames (see ``hdl/telemetry.py``)."""

from amaranth.lib import data

from ..hdl.telemetry import CRC, FRAME_TYPES, SYNC, payload_bytes


__all__ = ["FrameError", "unpack", "to_python", "decode_frames", "FrameDecoder"]


class FrameError(ValueError):
    pass


def unpack(layout, value):
    """Integer ``value`` packed as ``layout`` -> nested dicts and lists of ints."""
    layout = data.Layout.cast(layout)
    return to_python(data.Const(layout, value & ((1 << layout.size) - 1)))


def to_python(const):
    """A ``data.Const`` (e.g. a simulator sample of a view) -> nested dicts and lists of ints."""
    layout = data.Layout.cast(const.shape())
    if isinstance(layout, data.ArrayLayout):
        return [_element(const[i]) for i in range(layout.length)]
    return {name: _element(const[name]) for name, _ in layout}


def _element(value):
    return to_python(value) if isinstance(value, data.Const) else int(value)


def _scan(buf, strict):
    """Good frames in ``buf`` and how many leading bytes no later data can complete."""
    frames = []
    i = 0
    while i + 4 <= len(buf):
        if (buf[i], buf[i + 1]) != SYNC:
            i += 1
            continue
        ftype, length = buf[i + 2], buf[i + 3]
        end = i + 4 + length + 1
        if end > len(buf):
            break                               # maybe a frame still arriving
        layout = FRAME_TYPES.get(ftype)
        body = bytes(buf[i + 2:end - 1])
        good = layout is not None and payload_bytes(layout) == length and \
            CRC(data_width=8).compute(body) == buf[end - 1]
        if not good:
            if strict:
                raise FrameError(f"bad frame at byte {i}: type 0x{ftype:02X}, length {length}")
            i += 1                              # resynchronise on the next sync pattern
            continue
        frames.append((ftype, unpack(layout, int.from_bytes(body[2:], "little"))))
        i = end
    return frames, min(i, max(0, len(buf) - 3))


def decode_frames(stream_bytes, *, strict=False):
    """``(frame_type, fields)`` for each good frame in ``stream_bytes``, in order.

    Bad CRCs, unknown types and noise are skipped (``strict=True`` raises ``FrameError``
    instead), so a reader that joins mid-stream resynchronises on the next sync pattern.
    """
    return _scan(bytes(stream_bytes), strict)[0]


class FrameDecoder:
    """Incremental decoder for a byte stream that arrives in pieces (a serial port)."""

    def __init__(self):
        self._buf = bytearray()

    def feed(self, chunk):
        self._buf += chunk
        frames, used = _scan(self._buf, False)
        del self._buf[:used]
        return frames
