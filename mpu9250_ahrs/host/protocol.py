"""The link's frames (``hdl/FRAMES.md``) on the host: encode, decode, check, count.

One decoder serves the tests, the co-simulation and the host tool, with the layouts the
gateware is built from (``hdl.frame_types.FRAME_TYPES``), so the two never disagree on a
field position.
"""

from dataclasses import dataclass

from amaranth.lib import data

from ..hdl.contract.commands import (COMMANDS, MAX_COMMAND_PAYLOAD, RESULT_INPUT_LOST, RESULTS,
                                     SPACES)
from ..hdl.link.frame_types import FRAME_TYPES
from ..hdl.link.frame_types import CRC, HEADER_BYTES, SYNC, payload_bytes


__all__ = ["FrameError", "unpack", "to_python", "crc16", "encode_frame", "encode_command",
           "decode_frames", "FrameDecoder", "LinkStats", "RESULT_NAMES", "answers", "reply_of",
           "corrupted_share"]


RESULT_NAMES = {code: name for name, code in RESULTS.items()}


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


def crc16(body):
    """CRC-16/IBM-3740 of ``body`` (the frame's type, seq, length and payload)."""
    return CRC(data_width=8).compute(bytes(body))


def encode_frame(frame_type, seq, payload):
    """A whole frame: sync, type, seq, length, payload, CRC (most significant byte first)."""
    payload = bytes(payload)
    if len(payload) > 255:
        raise ValueError("payload longer than 255 bytes")
    body = bytes([frame_type, seq & 0xFF, len(payload)]) + payload
    return bytes(SYNC) + body + crc16(body).to_bytes(2, "big")


def encode_command(name, seq, *, addr=None, value=None, space="engine"):
    """A command frame (``hdl.contract.commands.COMMANDS``): ``write`` (addr, value), ``read``
    (addr), ``filter`` (value: a filter code), ``reset``, ``rate`` (value: divider), ``raw``
    (value: 0/1), ``who``. ``addr`` is the 8-bit address within ``space`` (``SPACES``)."""
    code, n = COMMANDS[name]
    if name in ("write", "read"):
        full = (SPACES[space] << 8) | addr
        payload = full.to_bytes(2, "little")
        if name == "write":
            payload += (value & 0xFFFFFFFF).to_bytes(4, "little")
    elif name == "rate":
        payload = int(value).to_bytes(2, "little")
    elif name in ("filter", "raw"):
        payload = bytes([int(value)])
    else:
        payload = b""
    assert len(payload) == n <= MAX_COMMAND_PAYLOAD
    return encode_frame(code, seq, payload)


@dataclass
class LinkStats:
    """What a decoder saw: good frames, frames with a bad CRC (or a length its type does not
    have), bytes outside frames, and frames missing by the sequence numbers."""
    frames: int = 0
    crc_errors: int = 0
    skipped_bytes: int = 0
    lost: int = 0


def _scan(buf, strict, stats, state):
    """Good frames in ``buf`` and how many leading bytes no later data can complete."""
    frames = []
    i = 0
    header = HEADER_BYTES
    while i + header <= len(buf):
        if (buf[i], buf[i + 1]) != SYNC:
            i += 1
            stats.skipped_bytes += 1
            continue
        ftype, seq, length = buf[i + 2], buf[i + 3], buf[i + 4]
        layout = FRAME_TYPES.get(ftype)
        if layout is None or payload_bytes(layout) != length:
            # not a frame of ours (or corrupt): only a sync pattern's look-alike
            if strict:
                raise FrameError(f"bad frame at byte {i}: type 0x{ftype:02X}, length {length}")
            i += 1
            stats.skipped_bytes += 1
            continue
        end = i + header + length + 2
        if end > len(buf):
            break                               # maybe a frame still arriving
        body = bytes(buf[i + 2:end - 2])
        if crc16(body) != int.from_bytes(buf[end - 2:end], "big"):
            if strict:
                raise FrameError(f"bad CRC at byte {i}: type 0x{ftype:02X}")
            stats.crc_errors += 1
            i += 1                              # resynchronise on the next sync pattern
            continue
        if state.get("seq") is not None:
            stats.lost += (seq - state["seq"] - 1) % 256
        state["seq"] = seq
        stats.frames += 1
        fields = unpack(layout, int.from_bytes(body[3:], "little"))
        frames.append((ftype, seq, fields))
        i = end
    return frames, min(i, max(0, len(buf) - header + 1))


def decode_frames(stream_bytes, *, strict=False, with_seq=False):
    """``(frame_type, fields)`` (``with_seq``: ``(frame_type, seq, fields)``) for each good
    frame in ``stream_bytes``, in order.

    Bad CRCs, unknown types and noise are skipped (``strict=True`` raises ``FrameError``
    instead), so a reader that joins mid-stream resynchronises on the next sync pattern.
    """
    frames = _scan(bytes(stream_bytes), strict, LinkStats(), {})[0]
    return frames if with_seq else [(t, f) for t, _, f in frames]


class FrameDecoder:
    """Incremental decoder for a byte stream that arrives in pieces (a serial port).
    ``stats`` (``LinkStats``) counts as it goes; ``feed`` returns ``(type, seq, fields)``."""

    def __init__(self):
        self._buf = bytearray()
        self._state = {}
        self.stats = LinkStats()

    def drop(self):
        """Forget the bytes of a frame not yet complete (the stream starts again)."""
        self._buf.clear()
        self._state.clear()

    def feed(self, chunk):
        self._buf += chunk
        frames, used = _scan(self._buf, False, self.stats, self._state)
        del self._buf[:used]
        return frames


def answers(fields, name, seq, *, addr=None, space="engine", **_):
    """Whether a reply's ``fields`` answer the command ``name`` sent with ``seq`` (and, for a
    read or write, ``addr`` in ``space``): its sequence number, its command code and, unless
    the board found the command malformed (its reply's address 0), the address it names."""
    code, _n = COMMANDS[name]
    if fields["cmd_seq"] != seq or fields["command"] != code:
        return False
    if name in ("write", "read") and _result_code(fields) != RESULTS["bad_command"]:
        return fields["addr"] == (SPACES[space] << 8) | addr
    return True


def reply_of(fields):
    """A reply's fields with its result named (``RESULT_NAMES``, from the result's code) and
    ``input_lost``: the board dropped bytes from the host before this command (its input
    FIFO full: ``RESULT_INPUT_LOST``), so commands sent since the last reply may have had
    none."""
    return {**fields, "result_name": RESULT_NAMES.get(_result_code(fields), "unknown"),
            "input_lost": bool(fields["result"] & RESULT_INPUT_LOST)}


def _result_code(fields):
    """A reply's result code (``RESULTS``), without the ``RESULT_INPUT_LOST`` bit."""
    return fields["result"] & ~RESULT_INPUT_LOST


def corrupted_share(trials=20_000, *, seed=0, flips=(1, 2, 3, 4)):
    """How often the decoder accepts a corrupted frame: the longest frame (an attitude frame,
    random payload) with ``k`` random bits flipped anywhere in it, for each ``k`` in
    ``flips``, and random bodies behind a valid header. Returns {case: (accepted, trials)};
    a frame counts as accepted when the decoder returns one that differs from the original."""
    import random
    from ..hdl.link.frame_types import ATTITUDE
    rng = random.Random(seed)
    n = payload_bytes(FRAME_TYPES[ATTITUDE])
    out = {}
    from ..progress import bar
    # progress on stderr, on a terminal only (100,000 trials take minutes)
    shown = bar(trials * (len(flips) + 1), "corrupted frames", "frame")
    for k in flips:
        accepted = 0
        shown.set_postfix_str(f"{k}-bit flips")
        for _ in range(trials):
            shown.update(1)
            payload, seq = rng.randbytes(n), rng.randrange(256)
            sent = (ATTITUDE, seq, unpack(FRAME_TYPES[ATTITUDE], int.from_bytes(payload, "little")))
            frame = bytearray(encode_frame(ATTITUDE, seq, payload))
            for bit in rng.sample(range(8 * len(frame)), k):
                frame[bit // 8] ^= 1 << (bit % 8)
            # compared with the frame as sent (a flipped seq byte accepted counts too)
            accepted += any(f != sent for f in decode_frames(frame, with_seq=True))
        out[f"{k}-bit flips"] = (accepted, trials)
    accepted = 0
    shown.set_postfix_str("random bodies")
    for _ in range(trials):
        shown.update(1)
        body = bytes([ATTITUDE, rng.randrange(256), n]) + rng.randbytes(n + 2)
        accepted += bool(decode_frames(bytes(SYNC) + body))
    out["random bodies"] = (accepted, trials)
    shown.close()
    return out


def main(argv=None):
    import argparse
    import json
    from ..reference.entry_point import count
    p = argparse.ArgumentParser(prog="python -m mpu9250_ahrs.host.protocol",
                                description="The share of corrupted frames the decoder accepts.")
    p.add_argument("trials", nargs="?", type=count, default=20_000,
                   help="frames per case (20000)")
    args = p.parse_args(argv)
    for case, (accepted, n) in corrupted_share(args.trials).items():
        print(json.dumps({"case": case, "accepted": accepted, "trials": n,
                          "share": accepted / n}))
    return 0


if __name__ == "__main__":
    import sys
    from ..reference.entry_point import run_main
    sys.exit(run_main("python -m mpu9250_ahrs.host.protocol", main))
