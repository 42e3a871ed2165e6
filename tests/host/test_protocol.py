"""The link's frames on the host: the CRC's guarantee checked bit by bit, the decoder fuzzed,
commands encoded as the gateware parses them."""

import random

import pytest
from hypothesis import given, settings, strategies as st

from mpu9250_ahrs.hdl.link.frame_types import ATTITUDE, FRAME_TYPES, SENSOR
from mpu9250_ahrs.hdl.link.frame_types import payload_bytes
from mpu9250_ahrs.host.protocol import (FrameDecoder, corrupted_share, crc16, decode_frames,
                                        encode_command, encode_frame, unpack)
from tests.hdl.test_telemetry import crc16_ibm_3740


def raw_crc(data):
    """The CRC's linear part: polynomial 0x1021 from 0."""
    return crc16_ibm_3740(data, initial=0)


def test_every_1_2_3_bit_error_in_the_longest_frame_is_detected():
    """For a fixed length the CRC is affine, so a flipped-bit pattern e goes undetected only
    if its syndrome (the CRC's linear part over the flipped body bits, XOR the flipped CRC
    bits) is zero. With s_i the syndrome of bit i alone over the longest frame's body and CRC:
    no s_i is 0 (1-bit), no two are equal (2-bit), no two XOR to a third (3-bit)."""
    n = 3 + max(payload_bytes(layout) for layout in FRAME_TYPES.values())   # type, seq, length
    syndromes = []
    for bit in range(8 * n):
        message = bytearray(n)
        message[bit // 8] = 1 << (7 - bit % 8)
        syndromes.append(raw_crc(message))
    syndromes += [1 << k for k in range(16)]                # a flipped CRC bit
    assert len(syndromes) == 8 * (n + 2) == 720
    assert 0 not in syndromes
    assert len(set(syndromes)) == len(syndromes)
    seen = set(syndromes)
    for i, a in enumerate(syndromes):
        for b in syndromes[i + 1:]:
            assert a ^ b not in seen


def test_crc_is_the_catalogue_one():
    # the catalogue's check value for "123456789"
    assert crc16(b"123456789") == 0x29B1


def test_corrupted_frames_are_refused():
    """A few thousand corrupted frames: none with 1-3 flipped bits is accepted (the table with
    more trials: ``python -m mpu9250_ahrs.host.protocol``)."""
    share = corrupted_share(600, seed=3)
    for k in (1, 2, 3):
        assert share[f"{k}-bit flips"][0] == 0


def _stream(rng, n):
    frames = []
    out = bytearray()
    for seq in range(n):
        ftype = rng.choice([SENSOR, ATTITUDE])
        payload = rng.randbytes(payload_bytes(FRAME_TYPES[ftype]))
        frames.append((ftype, seq, unpack(FRAME_TYPES[ftype], int.from_bytes(payload, "little"))))
        out += encode_frame(ftype, seq, payload)
    return frames, bytes(out)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), damage=st.sampled_from(["flip", "drop", "truncate",
                                                                  "noise", "insert"]),
       chunk=st.integers(1, 97))
def test_decoder_fuzzed(seed, damage, chunk):
    """Frames with damage (bits flipped, bytes dropped, the stream cut short, random bytes
    instead of a frame, noise between frames), fed in pieces: the decoder never raises, every
    frame it returns is one that was sent, unchanged, in order; the undamaged ones all come
    out, and the sequence numbers count the ones that did not."""
    rng = random.Random(seed)
    frames, data = _stream(rng, 6)
    data = bytearray(data)
    victim = rng.randrange(6)
    sizes = [len(encode_frame(t, 0, b"\0" * payload_bytes(FRAME_TYPES[t]))) for t, _, _ in frames]
    start = sum(sizes[:victim])
    end = start + sizes[victim]
    if damage == "flip":
        for bit in rng.sample(range(8 * start, 8 * end), rng.randint(1, 3)):
            data[bit // 8] ^= 1 << (bit % 8)
    elif damage == "drop":
        del data[rng.randrange(start, end)]
    elif damage == "truncate":
        data = data[:rng.randrange(start, end)]
    elif damage == "noise":
        data[start:end] = rng.randbytes(end - start)
    else:
        data[start:start] = rng.randbytes(rng.randint(1, 40))
    decoder = FrameDecoder()
    got = []
    for i in range(0, len(data), chunk):
        got += decoder.feed(bytes(data[i:i + chunk]))
    assert all(f in frames for f in got)
    assert [f[1] for f in got] == sorted(f[1] for f in got)
    intact = [f for k, f in enumerate(frames) if k != victim and
              (damage != "truncate" or k < victim)]
    if damage == "insert":
        intact = [f for k, f in enumerate(frames) if k != victim] + [frames[victim]]
    for f in intact:
        if damage != "insert" or f is not frames[victim]:
            assert f in got
    if damage in ("flip", "drop", "noise") and 0 < victim < 5:
        # (a first frame lost leaves nothing to count from)
        assert decoder.stats.lost == 6 - len(got)


def test_decoder_random_bytes_never_raise():
    rng = random.Random(5)
    decoder = FrameDecoder()
    for _ in range(200):
        decoder.feed(rng.randbytes(rng.randint(0, 300)))
    assert decoder.stats.frames == 0 or decoder.stats.frames < 2


@pytest.mark.parametrize("name, kwargs, payload", [
    ("write", {"addr": 0x05, "value": 2 << 24}, bytes.fromhex("0500 00000002")),
    ("write", {"addr": 0x10, "value": -1, "space": "pwm"}, bytes.fromhex("1002 ffffffff")),
    ("read", {"addr": 0x0A, "space": "board"}, bytes.fromhex("0a01")),
    ("filter", {"value": 1}, b"\x01"), ("reset", {}, b""), ("rate", {"value": 300}, b"\x2c\x01"),
    ("raw", {"value": 1}, b"\x01"), ("who", {}, b""),
])
def test_commands_encoded(name, kwargs, payload):
    frame = encode_command(name, 9, **kwargs)
    assert frame[:2] == b"\xa5\x5a" and frame[3] == 9 and frame[4] == len(payload)
    assert frame[5:-2] == payload
    assert crc16(frame[2:-2]) == int.from_bytes(frame[-2:], "big")
    assert decode_frames(frame) == []                       # not a frame the board sends


def test_a_reply_to_another_command_with_the_same_seq_is_not_taken():
    """Issue #60: ``Link.command`` took the first reply whose sequence number matched; a
    CRC-good reply to another command (or another address) with that number was read as the
    value asked for (``config get T`` -> -33.3 s)."""
    from mpu9250_ahrs.hdl.contract.commands import COMMANDS, RESULTS, SPACES
    from mpu9250_ahrs.hdl.link.frame_types import REPLY, Reply
    from mpu9250_ahrs.host.link import Link

    def reply(command, addr, value, seq=1):
        fields = {"command": COMMANDS[command][0], "cmd_seq": seq, "result": RESULTS["ok"],
                  "addr": addr, "value": value}
        raw = Reply.const(fields).as_value().value
        return encode_frame(REPLY, 0, raw.to_bytes(9, "little"))

    asked = (SPACES["engine"] << 8) | 5

    class Port:
        port = "fake"

        def __init__(self):
            # first a read of another address, then a write's reply to the same address,
            # both with the command's seq 1; then the right one
            self.chunks = [reply("read", asked + 1, 111), reply("write", asked, 222),
                           reply("read", asked, 333)]

        def write(self, data):
            pass

        def flush(self):
            pass

        def read(self, n):
            return self.chunks.pop(0) if self.chunks else b""

    link = Link(Port(), timeout=2.0)
    got = link.command("read", addr=5)
    assert got["value"] == 333 and got["addr"] == asked
    assert [f[2]["value"] for f in link.backlog] == [111, 222]
