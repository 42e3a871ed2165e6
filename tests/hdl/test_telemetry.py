"""Telemetry: UART transmitter, frame format, host decoder, and the whole core end to end."""

import random

import pytest
from amaranth.hdl import Array, C, Cat, Module
from amaranth.lib import data
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.link.frame_types import ATTITUDE, SENSOR, SYNC, AttitudeFrame, SensorFrame
from mpu9250_ahrs.hdl.link.telemetry import TelemetryFramer
from mpu9250_ahrs.hdl.board.top import result_fetch, sample_borrow
from mpu9250_ahrs.hdl.link.uart_tx import UARTTransmitter
from mpu9250_ahrs.reference.engine_model import attitude_fixed
from mpu9250_ahrs.sim.scenarios.attitude_bench import EngineRun, first_mismatch
from mpu9250_ahrs.sim.scenarios.setup import QUICK_CORE_BAUD, SimSetup, quick_core_setup
from mpu9250_ahrs.sim.scenarios.frontend import sample_matches
from mpu9250_ahrs.sim.scenarios.core import run_core as cosim_run_core
from mpu9250_ahrs.sim.bench.streams import check_stream_rules, stream_put
from mpu9250_ahrs.host.protocol import (FrameDecoder, FrameError, crc16, decode_frames,
                                        encode_frame, unpack)
from mpu9250_ahrs.sim.bench.uart import attach_uart_receiver


def random_frame(rng):
    """Any bit pattern is a valid frame: draw one and let the layout name the fields."""
    return unpack(SensorFrame, rng.getrandbits(data.Layout.cast(SensorFrame).size))


def test_uart_transmitter_bytes():
    dut = UARTTransmitter(divisor=5)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    got = []
    attach_uart_receiver(sim, dut.tx, 5, got)
    sent = [0x00, 0xFF, 0xA5, 0x5A, 0x01, 0x80]

    async def tb(ctx):
        for byte in sent:
            await stream_put(ctx, dut.i_stream, byte)
        await ctx.tick().repeat(5 * 12)
    sim.add_testbench(tb)
    sim.run()
    assert got == sent


def test_uart_baud_error_checked():
    assert UARTTransmitter.divisor_for(12e6, 921_600) == 13
    with pytest.raises(ValueError, match="off by"):
        UARTTransmitter.divisor_for(12e6, 1_600_000)


@pytest.mark.parametrize("buffered", [False, True])
def test_framer_against_decoder(buffered):
    """Random frames with back-pressure, decoded. Buffered: the producer takes its payload
    back as soon as the copy is acknowledged (it writes garbage over it then), and the frame on
    the wire is still the one it offered."""
    rng = random.Random(1)
    frames = [random_frame(rng) for _ in range(4)]
    dut = TelemetryFramer(buffered=buffered)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.o_stream, "frame bytes")
    out = []
    copy_cycles = []

    async def producer(ctx):
        ctx.set(dut.seq, 0x42)
        for f in frames:
            start = ctx.get(dut.idle)
            ctx.set(dut.i_stream.payload, f)
            ctx.set(dut.i_stream.valid, 1)
            cycles = 0
            while True:
                _, _, ready = await ctx.tick().sample(dut.i_stream.ready)
                cycles += 1
                if ready:
                    break
            ctx.set(dut.i_stream.valid, 0)
            ctx.set(dut.i_stream.payload, random_frame(rng))      # no longer the framer's
            if buffered and start:
                copy_cycles.append(cycles)

    async def consumer(ctx):
        n = 0
        while len(out) < 4 * dut.frame_bytes:
            ctx.set(dut.o_stream.ready, n % 3 != 0)      # with back-pressure
            _, _, valid, ready, byte = await ctx.tick().sample(
                dut.o_stream.valid, dut.o_stream.ready, dut.o_stream.payload)
            if valid and ready:
                out.append(byte.data)
                # ``last`` marks exactly each frame's final byte
                assert byte.last == (len(out) % dut.frame_bytes == 0)
            n += 1
    sim.add_testbench(producer)
    sim.add_testbench(consumer)
    sim.run()

    n = dut.length
    assert bytes(out[:2]) == bytes(SYNC) and out[2:5] == [0x01, 0x42, n]
    assert crc16(out[2:n + 5]) == int.from_bytes(bytes(out[n + 5:n + 7]), "big")
    decoded = [fields for _, fields in decode_frames(out, strict=True)]
    assert decoded == frames
    if buffered:
        assert copy_cycles and set(copy_cycles) == {dut.words}


def test_framer_fetch_equals_payload():
    """The attitude framer as the core builds it (``fetch``: the result's quaternion, angles
    and bias read through a port during the copy, a cycle after asked; ``borrow``: the sample's
    sensor fields through a synchronous port read every cycle, a word ahead) sends the frames
    the payload holds, when the ports give the payload's words (and 0 between reads, as the
    engine's and the sample store's do); the words it asks for are those."""
    rng = random.Random(2)
    size = data.Layout.cast(AttitudeFrame).size
    frames = [unpack(AttitudeFrame, rng.getrandbits(size)) for _ in range(3)]
    offset, n = result_fetch()
    first, bits = sample_borrow()
    dut = TelemetryFramer(AttitudeFrame, ATTITUDE, buffered=True, short=(SENSOR, SensorFrame),
                          fetch=(offset, n), borrow=(first, bits))
    # the borrow port, synchronous: the payload's word (its borrowed bits only) the cycle
    # after it is asked for, as the engine reads the sample store
    top = Module()
    top.submodules.dut = dut
    borrowed = Cat(dut.i_stream.payload.as_value()[first:first + bits], C(0, 32))
    top.d.sync += dut.borrow_data.eq(Array(borrowed[32 * k:32 * k + 32]
                                           for k in range(bits // 32 + 1))[dut.borrow_index])
    sim = Simulator(top)
    sim.add_clock(1e-6)
    out, asked = [], []

    async def producer(ctx):
        for f in frames:
            # the borrowed words are still from the cycle before the payload is offered (the
            # engine's sample is held from its load, long before its result is framed)
            ctx.set(dut.i_stream.payload, f)
            await ctx.tick()
            ctx.set(dut.i_stream.valid, 1)
            await ctx.tick().until(dut.i_stream.ready)
            ctx.set(dut.i_stream.valid, 0)
            ctx.set(dut.i_stream.payload, unpack(AttitudeFrame, rng.getrandbits(size)))

    async def port(ctx):
        # a synchronous read: the word the cycle after ``fetch_en``, from the payload offered
        async for _, _, en, index in ctx.tick().sample(dut.fetch_en, dut.fetch_index):
            if en:      # the payload holds still while it is copied
                asked.append(index)
                word = ctx.get(dut.i_stream.payload.as_value()) >> (offset + 32 * index)
                ctx.set(dut.fetch_data, word & 0xFFFF_FFFF)
            else:
                ctx.set(dut.fetch_data, 0)      # 0 between reads (the engine reads ZERO)

    async def consumer(ctx):
        ctx.set(dut.o_stream.ready, 1)
        while len(out) < len(frames) * dut.frame_bytes:
            _, _, valid, byte = await ctx.tick().sample(dut.o_stream.valid, dut.o_stream.payload)
            if valid:
                out.append(byte.data)
    sim.add_testbench(producer)
    sim.add_testbench(port, background=True)
    sim.add_testbench(consumer)
    sim.run()
    assert [fields for _, fields in decode_frames(out, strict=True)] == frames
    assert asked == list(range(n)) * len(frames)


def test_decoder_resynchronises_and_rejects_bad_crc():
    rng = random.Random(2)
    frame = random_frame(rng)
    value = data.Layout.cast(SensorFrame).const(frame).as_bits()
    n = (data.Layout.cast(SensorFrame).size + 7) // 8
    good = encode_frame(0x01, 0, value.to_bytes(n, "little"))
    bad = bytearray(good)
    bad[10] ^= 0x40
    stream = b"\x00\xA5\x13" + bytes(bad) + good[:7] + good + good
    decoded = list(decode_frames(stream))
    assert [f for _, f in decoded] == [frame, frame]
    with pytest.raises(FrameError):
        list(decode_frames(bytes(bad), strict=True))
    assert unpack(SensorFrame, value) == frame
    # Fed in pieces of any size, the incremental decoder finds the same frames exactly once.
    for size in (1, 5, 33):
        decoder = FrameDecoder()
        pieces = [stream[i:i + size] for i in range(0, len(stream), size)]
        assert [f for piece in pieces for _, _, f in decoder.feed(piece)] == [frame, frame]


def run_core(setup, n_frames, *, baud, max_cycles, vcd=None, writes=(), compiled=None,
             **core_kw):
    """Model -> core -> UART -> decoder until ``n_frames`` frames came (``sim.scenarios.core.run_core``)
    and no protocol violation; (core, model, frames, asa). ``compiled``: as ``run_core``'s,
    but a waveform asked for (``vcd``) is always Amaranth's simulator's."""
    path = vcd and vcd()
    run = cosim_run_core(setup, n_frames=n_frames, baud=baud, max_cycles=max_cycles,
                         core_kwargs=core_kw, writes=writes, vcd=path,
                         compiled=None if path else compiled)
    assert run.model.violations == []
    return run.core, run.model, run.frames, run.asa


def model_reference(core, model, n, asa, select):
    """The fixed-point engine over the first ``n`` samples the model was read for (the AK8963's
    bytes from the same bursts), whether or not their results were sent."""
    from mpu9250_ahrs.sim.scenarios.frontend import expected_mag
    reads = [model.samples[k] for k in model.sample_reads[:n]]
    mags = [expected_mag(model.ext_reads[i], core.config.magnetometer,
                         model.ext_reads[i - 1] if i else None) for i in range(n)]
    return attitude_fixed([s.gyro for s in reads], [s.accel for s in reads],
                          [m for m, _ in mags], [f["mag_valid"] for _, f in mags],
                          asa=asa or (128, 128, 128), config=core.engine.config,
                          flagship=core.engine.flagship, select=select), reads


def test_core_end_to_end_over_uart(vcd):
    """Model -> SPI -> driver -> attitude engine (flagship, the reset default) -> scheduler ->
    framer -> UART -> host decoder, bit for bit: each frame's sample equals the model's, its
    attitude (quaternion, angles, bias, every flag) the fixed-point reference's for that sample,
    over every sample read, sent or not; the counters add up (the first two samples come closer
    than a frame lasts, so one result is not sent)."""
    # the quick set-up's compiled build where it can run (checked against Amaranth's simulator
    # by test_core_same_on_both_paths): 0.3 s rather than 12
    core, model, frames, asa = run_core(quick_core_setup(), 6, baud=QUICK_CORE_BAUD,
                                        max_cycles=120_000, vcd=vcd, compiled="prefer")
    assert core.telemetry_divider == 1
    n = frames[-1]["sample"]["counter"] + 1
    ref, reads = model_reference(core, model, n, asa, "flagship")
    for k, frame in enumerate(frames):
        s = frame["sample"]
        i = s["counter"]
        assert s["flags"]["overrun"] == 0 and s["skipped"] == 0
        assert sample_matches(s, reads[i])
        assert frame["status"]["streaming"] == 1 and frame["status"]["self_test_fail"] == 0
        c = frame["counters"]
        assert c["filtered"] == i + 1 and c["lost"] == 0
        assert c["not_sent"] + k + 1 == c["filtered"]
    run = EngineRun.from_results([{**f["attitude"], "counter": f["sample"]["counter"]}
                                  for f in frames])
    sent = [f["sample"]["counter"] for f in frames]
    assert first_mismatch(run, ref.take(sent)) is None, first_mismatch(run, ref.take(sent))
    assert list(run.counter) == sent and frames[-1]["counters"]["not_sent"] <= 1


def test_engine_never_waits_for_a_slow_uart():
    """A UART far too slow for the sample rate (921,600 baud, one 86-byte frame every ~0.9 ms,
    samples every 0.1 ms compressed) with the divider forced to 1: every sample is still
    filtered (``filtered`` = the sample counter + 1, nothing ``lost``), the results the UART had
    no time for are counted in ``not_sent``, and each frame that goes out is the engine's
    result for exactly its sample (six-axis, so the reference sees every sample's input)."""
    from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
    setup = SimSetup(clk_freq=12e6, config=MPU9250Config(magnetometer=False), odr_scale=0.1)
    core, model, frames, _ = run_core(setup, 3, baud=921_600, max_cycles=200_000,
                                      telemetry_divider=1, filter="complementary")
    counters = [f["counters"] for f in frames]
    for frame, c in zip(frames, counters):
        assert c["filtered"] == frame["sample"]["counter"] + 1 and c["lost"] == 0
    assert counters[-1]["not_sent"] > 0
    # sent + not sent = all results that were due (every one, divider 1) before the last frame
    assert counters[-1]["not_sent"] + len(frames) == counters[-1]["filtered"]
    n = frames[-1]["sample"]["counter"] + 1
    ref, reads = model_reference(core, model, n, None, "complementary")
    for frame in frames:
        k = frame["sample"]["counter"]
        assert sample_matches(frame["sample"], reads[k])
        assert frame["attitude"]["quat"] == [int(v) for v in ref.quat[k]], k


def test_telemetry_divider_is_a_run_time_register():
    """``TELEMETRY_DIV`` (0xFE) written through ``cfg``: every third result is framed from
    then on (the counters in consecutive frames step by 3)."""
    from mpu9250_ahrs.hdl.engine.register_map import TELEMETRY_DIV_ADDR
    # the quick set-up's compiled build where it can run (setup.quick_core_setup)
    core, _, frames, _ = run_core(quick_core_setup(), 4, baud=QUICK_CORE_BAUD,
                                  max_cycles=160_000, writes=[(TELEMETRY_DIV_ADDR, 3)],
                                  compiled="prefer")
    filtered = [f["counters"]["filtered"] for f in frames]
    assert [b - a for a, b in zip(filtered, filtered[1:])] == [3] * (len(frames) - 1)
    assert all(f["counters"]["not_sent"] == 0 for f in frames)


# The sensor frame's wire format written out independently of the layouts: (field, bits) in
# order from bit 0 of the payload, packed least significant byte first.
SENSOR_FRAME_FIELDS = [
    *[(f"accel{i}", 16) for i in range(3)], ("temp", 16), *[(f"gyro{i}", 16) for i in range(3)],
    *[(f"mag{i}", 16) for i in range(3)], ("counter", 32),
    ("data_ready", 1), ("overrun", 1), ("mag_valid", 1), ("mag_overflow", 1), ("mag_new", 1),
    ("mag_dor", 1), ("resumed", 1), ("skipped", 4),
    ("streaming", 1), ("whoami_error", 1), ("no_response", 1), ("int_timeout", 1),
    ("restarts", 6), ("spi_trained", 1), ("mag_ok", 1), ("mag_absent", 1), ("mag_wia_error", 1),
    ("mag_stale", 1), ("bad_burst", 1), ("bus_timeout", 1), ("bus_stuck", 1),
    ("bus_arbitration", 1), ("rate_error", 1), ("self_test_fail", 9),
]
KNOWN = {"accel0": 1, "accel1": -2, "accel2": 0x3FF, "temp": 0x1234, "gyro0": -1, "gyro1": 0,
         "gyro2": 32767, "mag0": -32768, "mag1": 5, "mag2": 6, "counter": 0x01020304,
         "data_ready": 1, "mag_valid": 1, "mag_new": 1, "skipped": 2, "streaming": 1,
         "restarts": 3, "mag_ok": 1, "bad_burst": 1, "self_test_fail": 0x010}
def known_frame():
    """The frame written out in the frame format page (``hdl/FRAMES.md``)."""
    from pathlib import Path
    page = (Path(__file__).parents[2] / "hdl" / "FRAMES.md").read_text()
    block = page.split("```known-answer\n", 1)[1].split("```", 1)[0]
    return bytes.fromhex(block)


def crc16_ibm_3740(data, initial=0xFFFF):
    """CRC-16/IBM-3740 bit by bit: polynomial 0x1021, initial 0xFFFF (0: the CRC's linear
    part), no reflection, no final XOR."""
    crc = initial
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def test_sensor_frame_known_answer():
    """The frame written out byte for byte in the frame format page: built here from the
    field list above with a bitwise CRC, equal to the page's, to what the gateware framer
    sends (sequence number 7), and decoded back."""
    KNOWN_FRAME = known_frame()
    value, pos = 0, 0
    for name, bits in SENSOR_FRAME_FIELDS:
        value |= (KNOWN.get(name, 0) & ((1 << bits) - 1)) << pos
        pos += bits
    payload = value.to_bytes((pos + 7) // 8, "little")
    body = bytes([0x01, 7, len(payload)]) + payload
    built = bytes(SYNC) + body + crc16_ibm_3740(body).to_bytes(2, "big")
    assert built == KNOWN_FRAME

    frame = {"sample": {"accel": [1, -2, 0x3FF], "temp": 0x1234, "gyro": [-1, 0, 32767],
                        "mag": [-32768, 5, 6], "counter": 0x01020304, "skipped": 2,
                        "flags": {"data_ready": 1, "mag_valid": 1, "mag_new": 1}},
             "status": {"streaming": 1, "restarts": 3, "mag_ok": 1, "bad_burst": 1,
                        "self_test_fail": 0x010}}
    dut = TelemetryFramer()
    out = []

    async def producer(ctx):
        ctx.set(dut.seq, 7)
        await stream_put(ctx, dut.i_stream, frame)

    async def consumer(ctx):
        ctx.set(dut.o_stream.ready, 1)
        for _ in range(10 * len(KNOWN_FRAME)):
            _, _, valid, byte = await ctx.tick().sample(dut.o_stream.valid, dut.o_stream.payload)
            if valid:
                out.append(byte.data)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(producer)
    sim.add_testbench(consumer)
    sim.run()
    assert bytes(out) == KNOWN_FRAME
    (ftype, fields), = decode_frames(KNOWN_FRAME, strict=True)
    assert ftype == 0x01 and fields["sample"]["counter"] == 0x01020304
    assert fields["sample"]["mag"] == [-32768, 5, 6] and fields["status"]["self_test_fail"] == 0x10
