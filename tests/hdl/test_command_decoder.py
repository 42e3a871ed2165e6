"""Command decoder: every command against an engine-port model and the PWM block; damaged
commands (bits flipped, bytes dropped, cut off, noise) fuzzed: nothing half done, nothing
done that was not sent whole, every failure counted."""

import random

from amaranth import Elaboratable, Module
from amaranth.lib import wiring
from amaranth.sim import Simulator
from hypothesis import example, given, settings, strategies as st

from mpu9250_ahrs.hdl.engine.register_map import (CONFIG_REGS, CONTROL_ADDR, CONTROL_KEEP,
                                                  CONTROL_RESET, HOST_WRITABLE, TELEMETRY_DIV_ADDR)
from mpu9250_ahrs.hdl.contract.commands import (BOARD_REGS, COMMANDS, REGMAP_VERSION,
                                                RESULT_INPUT_LOST, RESULTS)
from mpu9250_ahrs.hdl.link.command_decoder import (COMMAND_STATS, COUNTED, COUNTER_WORDS,
                                                   FIFO_DEPTH, CommandDecoder, counter_word)
from mpu9250_ahrs.hdl.sensor.driver_status import SelfTestStatus
from mpu9250_ahrs.hdl.contract.pwm_regs import PWM_REGS
from mpu9250_ahrs.hdl.link.pwm import PWMOutputs
from mpu9250_ahrs.host.protocol import encode_command, encode_frame, to_python
from mpu9250_ahrs.sim.bench.streams import check_stream_rules

TIMEOUT = 200
VERSION = 0x0002ABCD


class Harness(Elaboratable):
    def __init__(self):
        self.decoder = CommandDecoder(writable=HOST_WRITABLE, version=VERSION, timeout=TIMEOUT)
        self.pwm = PWMOutputs(clk_freq=4e6)

    def elaborate(self, platform):
        m = Module()
        m.submodules.decoder = self.decoder
        m.submodules.pwm = self.pwm
        wiring.connect(m, self.decoder.pwm, self.pwm.bus)
        m.d.comb += self.pwm.kick.eq(self.decoder.kick)
        return m


def run(data, *, gaps=None, busy_cycles=3, inputs=None, pulses=None):
    """Feed ``data`` (bytes; ``gaps``: {index: idle cycles before that byte}); the engine port
    model takes a write after ``busy_cycles`` and answers a read of address a with 3a + 1.
    ``inputs``: {name: value} of the decoder's inputs to drive (the board registers' sources);
    ``pulses``: {name: n}: n one-cycle pulses of that event input, every other cycle, first.
    Returns (engine writes, replies, stats, raw_mode)."""
    h = Harness()
    dec = h.decoder
    sim = Simulator(h)
    sim.add_clock(1e-6)
    for name in ("replies", "cfg", "cfg_read"):
        check_stream_rules(sim, getattr(dec, name), name)
    writes, replies = [], []
    out = {}

    async def engine(ctx):
        ctx.set(dec.replies.ready, 1)
        ctx.set(dec.cfg_read.ready, 1)
        wait, read_addr = 0, None
        # each step sees the signals as they were in the cycle that just ended
        async for (_, _, w_valid, w_ready, w_payload, r_valid, r_addr, d_valid, d_ready,
                   rep_valid, rep) in ctx.tick().sample(
                dec.cfg.valid, dec.cfg.ready, dec.cfg.payload, dec.cfg_read.valid,
                dec.cfg_read.payload, dec.cfg_read_data.valid, dec.cfg_read_data.ready,
                dec.replies.valid, dec.replies.payload):
            if w_valid and w_ready:
                p = to_python(w_payload)
                writes.append((p["addr"], p["data"]))
                wait = 0
            elif w_valid:
                wait += 1
            ctx.set(dec.cfg.ready, w_valid and not w_ready and wait >= busy_cycles)
            if d_valid and d_ready:
                read_addr = None
            if r_valid:
                read_addr = r_addr
            ctx.set(dec.cfg_read_data.valid, read_addr is not None)
            ctx.set(dec.cfg_read_data.payload, 3 * (read_addr or 0) + 1)
            if rep_valid:
                replies.append(to_python(rep))
    sim.add_testbench(engine, background=True)

    async def host(ctx):
        for name, value in (inputs or {}).items():
            ctx.set(getattr(dec, name), value)
        for name, n in (pulses or {}).items():
            for _ in range(n):
                ctx.set(getattr(dec, name), 1)
                await ctx.tick()
                ctx.set(getattr(dec, name), 0)
                await ctx.tick()
        for k, byte in enumerate(data):
            if gaps and k in gaps:
                await ctx.tick().repeat(gaps[k])
            ctx.set(dec.i_stream.valid, 1)
            ctx.set(dec.i_stream.payload, byte)
            await ctx.tick().until(dec.i_stream.ready)
            ctx.set(dec.i_stream.valid, 0)
        # the decoder takes a byte every two cycles: a FIFO's worth of bytes and their
        # commands may still wait when the host stops, then a cut-off frame's time-out
        await ctx.tick().repeat(TIMEOUT + 200)
        out["stats"] = {name: ctx.get(dec.counters.ram.data[k])
                        for k, name in enumerate(COMMAND_STATS)}
        out["raw"] = ctx.get(dec.raw_mode)
    sim.add_testbench(host)
    sim.run()
    return writes, replies, out["stats"], out["raw"]


def test_a_reply_after_dropped_bytes_says_so():
    """A byte the receiver dropped (the FIFO full: its ``overrun``) is said by the next reply
    (result bit 7), once: the command it belonged to had none."""
    _, replies, _, _ = run(encode_command("who", 1) + encode_command("who", 2),
                           pulses={"rx_overrun": 1})
    assert [r["result"] for r in replies] == [RESULTS["ok"] | RESULT_INPUT_LOST, RESULTS["ok"]]


def test_every_command():
    r = CONFIG_REGS
    commands = [
        encode_command("write", 1, addr=r["R"], value=3 << 24),
        encode_command("write", 2, addr=r["ZERO"], value=5),                 # read-only
        encode_command("read", 3, addr=0x40),
        encode_command("filter", 4, value=1),
        encode_command("filter", 5, value=7),                                 # no such filter
        encode_command("reset", 6),
        encode_command("rate", 7, value=5),
        encode_command("raw", 8, value=1),
        encode_command("who", 9),
        encode_command("read", 10, addr=BOARD_REGS["CMD_OK"], space="board"),
        encode_command("write", 11, addr=PWM_REGS["PWM_SERVO_PERIOD"], value=2_500,
                       space="pwm"),
        encode_command("write", 12, addr=PWM_REGS["PWM_MOTOR_PERIOD"], value=100,
                       space="pwm"),                                   # over 20 kHz
        encode_command("read", 13, addr=PWM_REGS["PWM_SERVO_PERIOD"], space="pwm"),
        encode_command("read", 14, addr=0x77, space="pwm"),                   # no register
        encode_frame(0x1F, 15, b""),                                          # unknown type
        encode_frame(COMMANDS["read"][0], 16, b"\x01"),                       # wrong length
        encode_command("write", 17, addr=BOARD_REGS["VERSION"], value=1, space="board"),
    ]
    writes, replies, stats, raw = run(b"".join(commands))
    assert writes == [(r["R"], 3 << 24), (CONTROL_ADDR, 1),
                      (CONTROL_ADDR, CONTROL_KEEP | CONTROL_RESET), (TELEMETRY_DIV_ADDR, 5)]
    assert [x["cmd_seq"] for x in replies] == list(range(1, 18))
    res = {x["cmd_seq"]: x["result"] for x in replies}
    ok, refused = RESULTS["ok"], RESULTS["refused"]
    assert [res[k] for k in range(1, 18)] == [
        ok, refused, ok, ok, refused, ok, ok, ok, ok, ok, ok, refused, ok,
        RESULTS["bad_address"], RESULTS["bad_command"], RESULTS["bad_command"], refused]
    by_seq = {x["cmd_seq"]: x for x in replies}
    assert by_seq[3]["value"] == 3 * 0x40 + 1
    assert by_seq[9]["value"] == VERSION and by_seq[9]["addr"] == REGMAP_VERSION
    assert by_seq[10]["value"] == 7                          # seven done (ok) before it
    assert by_seq[13]["value"] == 2_500
    # a bad command's reply echoes nothing (its payload bytes are not those of a command)
    assert all(by_seq[k]["addr"] == 0 and by_seq[k]["value"] == 0 for k in (15, 16))
    assert raw == 1
    assert stats["ok"] == 10 and stats["refused"] == 7 and stats["malformed"] == 2
    assert stats["crc_errors"] == 0 and stats["discarded"] == 0


def test_discarded_bytes_two_cycles_in_a_row_count_twice():
    """``A5 00``: the second sync byte's check turns 00 back and counts the A5 that began
    nothing, and the hunt takes 00 and counts it the next cycle (the counters in their RAM
    take both, and a board read of CMD_DISCARDED after them says so)."""
    good = encode_command("who", 1)
    board_read = encode_command("read", 2, addr=BOARD_REGS["CMD_DISCARDED"], space="board")
    writes, replies, stats, _ = run(b"\xA5\x00" + good + b"\x11\xA5\x00\x22" + board_read)
    assert stats["discarded"] == 6 and stats["ok"] == 2
    assert [r["value"] for r in replies if r["cmd_seq"] == 2] == [6]


def _commands(rng, n):
    writable = sorted(a for a in HOST_WRITABLE if a < 0x80)
    out = []
    for seq in range(n):
        addr = rng.choice(writable)
        value = rng.randrange(-2 ** 31, 2 ** 31)
        out.append(((addr, value), encode_command("write", seq, addr=addr, value=value)))
    return out


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1),
       damage=st.sampled_from(["flip", "drop", "cut", "noise", "garbage"]))
# a frame cut before its CRC's last byte (0xA5), then the next frame's 0xA5: it completes the
# cut frame unless the host's silence covers the decoder's backlog too (it did not)
@example(seed=4837, damage="cut")
def test_damaged_commands_change_nothing(seed, damage):
    """Five writes, one damaged: the writes done are exactly the intact commands', whole and
    in order (the one after a dropped byte too: its header, taken into the damaged frame, is
    searched again when that frame fails); the damaged one did nothing and was counted."""
    rng = random.Random(seed)
    commands = _commands(rng, 5)
    victim = rng.randrange(5)
    data = bytearray()
    gaps = {}
    for k, (_, frame) in enumerate(commands):
        frame = bytearray(frame)
        if k == victim:
            if damage == "flip":
                for bit in rng.sample(range(8 * len(frame)), rng.randint(1, 3)):
                    frame[bit // 8] ^= 1 << (bit % 8)
            elif damage == "drop":
                del frame[rng.randrange(len(frame))]
            elif damage == "cut":
                frame = frame[:rng.randrange(3, len(frame))]
                # the host goes quiet: the time-out runs from the last byte the decoder
                # took, and it takes one every two cycles, so the bytes still in its FIFO
                # (at most those sent so far, and FIFO_DEPTH) add to the host's silence
                sent = len(data) + len(frame)
                gaps[sent] = TIMEOUT + 10 + 2 * min(FIFO_DEPTH, sent)
            elif damage == "noise":
                frame = bytearray(rng.randbytes(len(frame)))
            else:
                frame = bytearray(rng.randbytes(rng.randint(1, 30))) + frame
        data += frame
    writes, replies, stats, _ = run(bytes(data), gaps=gaps)
    intact = [w for k, (w, _) in enumerate(commands) if k != victim]
    if damage == "garbage":
        intact = [w for w, _ in commands]
    assert all(w in intact for w in writes)
    assert writes == [w for w in intact if w in writes]                   # in order
    assert writes == intact
    assert len(replies) == len(writes)
    if damage != "garbage" or stats["discarded"] == 0:
        failures = stats["crc_errors"] + stats["malformed"] + stats["discarded"]
        assert failures >= 1 or damage == "garbage"


def test_cut_off_command_times_out():
    frame = encode_command("write", 1, addr=CONFIG_REGS["R"], value=1)
    good = encode_command("write", 2, addr=CONFIG_REGS["P0"], value=2)
    data = frame[:8] + good
    # the time-out runs from the last byte the decoder took: it takes one every two cycles,
    # so the eight bytes fed one a cycle are all taken 8 cycles after the host's last
    writes, replies, stats, _ = run(data, gaps={8: TIMEOUT + 5 + 8})
    assert writes == [(CONFIG_REGS["P0"], 2)] and stats["malformed"] == 1
    assert [r["cmd_seq"] for r in replies] == [2]


def _writes(*seqs):
    return [encode_command("write", seq, addr=CONFIG_REGS["R"], value=seq) for seq in seqs]


def test_a_frame_begun_inside_a_failed_one_is_found():
    """Issue #25: half a frame, then a new frame at once; a stray ``A5 A5 5A`` before a frame;
    a frame whose length byte was hit (over 6): the good frame after each is executed, with
    no retry. (Before, each swallowed it: its header was parsed as the broken frame's.)"""
    first, second, third, fourth = _writes(1, 2, 3, 4)
    bad_length = bytearray(third)
    bad_length[4] = 0x40
    data = first[:7] + second + b"\xA5\xA5\x5A" + third + bytes(bad_length[:6]) + fourth
    writes, replies, stats, _ = run(data)
    assert writes == [(CONFIG_REGS["R"], k) for k in (2, 3, 4)]
    assert [r["cmd_seq"] for r in replies] == [2, 3, 4]
    assert stats["crc_errors"] >= 1 and stats["malformed"] >= 1


def test_only_accepted_commands_kick_the_watchdog():
    """Issue #25: a host stuck sending refused or unknown commands (good CRC) is as good as a
    silent one: the PWM watchdog trips. Accepted commands keep the outputs running."""
    setup = [encode_command("write", 1, addr=PWM_REGS["PWM_MODE"], value=1, space="pwm"),
             encode_command("write", 2, addr=PWM_REGS["PWM_HIGH0"], value=100, space="pwm"),
             encode_command("write", 3, addr=PWM_REGS["PWM_WATCHDOG_MS"], value=1,
                            space="pwm"),                  # 4,000 cycles at the PWM's 4 MHz
             encode_command("write", 4, addr=PWM_REGS["PWM_ENABLE"], value=1, space="pwm")]

    def ends_tripped(repeat):
        h = Harness()
        dec = h.decoder
        sim = Simulator(h)
        sim.add_clock(1e-6)
        out = {}

        async def tb(ctx):
            ctx.set(dec.replies.ready, 1)
            ctx.set(dec.cfg.ready, 1)
            data = b"".join(setup) + repeat * 30
            for byte in data:
                ctx.set(dec.i_stream.valid, 1)
                ctx.set(dec.i_stream.payload, byte)
                await ctx.tick().until(dec.i_stream.ready)
                ctx.set(dec.i_stream.valid, 0)
                await ctx.tick().repeat(40)          # the commands keep coming, 30 of them
            out["tripped"] = ctx.get(h.pwm.tripped)
        sim.add_testbench(tb)
        sim.run()
        return out["tripped"]

    refused = encode_command("write", 9, addr=CONFIG_REGS["ZERO"], value=1)
    unknown = encode_frame(0x1F, 9, b"")
    accepted = encode_command("read", 9, addr=BOARD_REGS["CMD_OK"], space="board")
    assert ends_tripped(refused) and ends_tripped(unknown)
    assert not ends_tripped(accepted)


def test_control_words_the_engine_refuses_are_refused():
    """Issue #25: CONTROL takes a filter code only if it names a filter (with four filters in
    the registry every code does), and no reserved bit; a reset with keep is taken whatever
    bits 1:0 say. Refused words are not sent to the engine (``control_fields`` is the rule)."""
    from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_NAMES
    from mpu9250_ahrs.hdl.contract.numeric_contract import control_fields
    words = [3, 2, 0x10, 0x8 | 0x3, -1, 1 << 31, 0x4 | 0x1]
    commands = [encode_command("write", k, addr=CONTROL_ADDR, value=w)
                for k, w in enumerate(words)]
    writes, replies, stats, _ = run(b"".join(commands))
    ok, refused = RESULTS["ok"], RESULTS["refused"]
    taken = [control_fields(w, len(FILTER_NAMES)) is not None for w in words]
    assert [r["result"] for r in replies] == [ok if t else refused for t in taken]
    assert refused in [r["result"] for r in replies]                  # the reserved bits
    assert writes == [(CONTROL_ADDR, w) for w, t in zip(words, taken) if t]


def test_each_counted_register_has_a_word_of_its_own():
    words = [counter_word(name) for name in COUNTED]
    assert len(set(words)) == len(words) and all(0 <= w < COUNTER_WORDS for w in words)
    assert [counter_word(f"CMD_{name.upper()}") for name in COMMAND_STATS] == [0, 1, 2, 3, 4]


def test_time_out_counted_in_ticks():
    """With ``tick_cycles`` > 1 the cut-off time-out counts ticks (a pulse every so many cycles,
    at any phase): a frame cut off is dropped at least ``timeout`` cycles after its last byte,
    and at most two ticks later than when counted in cycles (``tick_cycles`` 1, exact)."""
    malformed = counter_word("CMD_MALFORMED")

    def dropped_after(tick_cycles, phase=0):
        dut = CommandDecoder(writable=HOST_WRITABLE, version=VERSION, timeout=50,
                             tick_cycles=tick_cycles)
        seen = []

        async def bench(ctx):
            data = list(encode_command("write", 1, addr=CONFIG_REGS["R"], value=1)[:5])
            for cycle in range(400):
                ctx.set(dut.tick, (cycle + phase) % tick_cycles == 0)
                ctx.set(dut.i_stream.valid, bool(data))
                if data:
                    ctx.set(dut.i_stream.payload, data[0])
                if ctx.get(dut.counters.events[malformed]):
                    seen.append(cycle)
                    return
                await ctx.tick()
                if data and ctx.get(dut.i_stream.ready):
                    data.pop(0)
        sim = Simulator(dut)
        sim.add_clock(1e-6)
        sim.add_testbench(bench)
        sim.run()
        return seen[0]

    exact = dropped_after(1)
    for phase in range(4):
        assert exact <= dropped_after(4, phase) <= exact + 2 * 4


def test_board_registers_read_their_sources():
    """Every read-only board register answers with its source: the build's words, the frames
    sent, WHO_AM_I and the self-test status as the core drives them, and the rate errors as
    the early-sample pulses counted."""
    inputs = {"frames_sent": 0x89ABCDEF, "who_am_i": 0x71,
              "self_test": {"fail": 0b101000011, "done": 1, "mag_done": 1}}
    names = ["VERSION", "REGMAP_VERSION", "FRAMES_SENT", "RATE_ERRORS", "WHO_AM_I",
             "SELF_TEST", "RAW_MODE"]
    commands = [encode_command("read", k, addr=BOARD_REGS[name], space="board")
                for k, name in enumerate(names)]
    _, replies, _, _ = run(b"".join(commands), inputs=inputs, pulses={"early_sample": 37})
    got = {names[x["cmd_seq"]]: (x["result"], x["value"]) for x in replies}
    status = SelfTestStatus.const(inputs["self_test"]).as_value().value
    assert got == {name: (RESULTS["ok"], value) for name, value in (
        ("VERSION", VERSION), ("REGMAP_VERSION", REGMAP_VERSION), ("FRAMES_SENT", 0x89ABCDEF),
        ("RATE_ERRORS", 37), ("WHO_AM_I", 0x71), ("SELF_TEST", status), ("RAW_MODE", 0))}


def _answered_once_stable(commands, *, before=None, meanwhile=None, after=None):
    """The replies of a decoder sent ``commands`` (bytes) while the frame arbiter's count is
    not stable (``frames_stable`` low, then high): ``before``, ``meanwhile``, ``after``:
    steps (async, of ``(ctx, decoder)``) before the commands, after them (no reply comes
    meanwhile) and as the count turns stable."""
    h = Harness()
    dec = h.decoder
    sim = Simulator(h)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dec.replies, "replies")
    replies = []

    async def tb(ctx):
        ctx.set(dec.replies.ready, 1)
        if before:
            await before(ctx, dec)
        ctx.set(dec.frames_stable, 0)
        for byte in commands:
            ctx.set(dec.i_stream.valid, 1)
            ctx.set(dec.i_stream.payload, byte)
            await ctx.tick().until(dec.i_stream.ready)
        ctx.set(dec.i_stream.valid, 0)
        if meanwhile:
            await meanwhile(ctx, dec)
        for _ in range(100):
            await ctx.tick()
            assert not ctx.get(dec.replies.valid)       # the read waits, and the one after it
        if after:
            await after(ctx, dec)
        ctx.set(dec.frames_stable, 1)
        for _ in range(100):
            if ctx.get(dec.replies.valid):
                replies.append(to_python(ctx.get(dec.replies.payload)))
            await ctx.tick()
    sim.add_testbench(tb)
    sim.run()
    return replies


def test_frames_sent_read_waits_for_a_stable_count():
    """A FRAMES_SENT read while the frame arbiter's count is not stable (its serial increment,
    ``frames_stable`` low) is answered once it is, with the count then; the command after it
    follows."""
    async def before(ctx, dec):
        ctx.set(dec.frames_sent, 0x1234)               # not the count yet

    async def after(ctx, dec):
        ctx.set(dec.frames_sent, 0x5678)
    replies = _answered_once_stable(b"".join(
        encode_command("read", seq, addr=BOARD_REGS[name], space="board")
        for seq, name in enumerate(("FRAMES_SENT", "WHO_AM_I"))), before=before, after=after)
    assert [(r["cmd_seq"], r["result"]) for r in replies] == [(0, RESULTS["ok"]),
                                                              (1, RESULTS["ok"])]
    assert replies[0]["value"] == 0x5678


def test_counter_read_while_the_frame_count_is_not_stable():
    """A counter's read waits in EXECUTE like every command while ``frames_stable`` is low
    (24 cycles at most, after every 256th frame): its word is the count once it is answered,
    not the word the counters' RAM read meanwhile (the lowest pending counter's, or word 0)."""
    async def pulses(ctx, signal, n):
        for _ in range(n):
            ctx.set(signal, 1)
            await ctx.tick()
            ctx.set(signal, 0)
            await ctx.tick()

    async def before(ctx, dec):
        await pulses(ctx, dec.early_sample, 37)

    async def meanwhile(ctx, dec):
        # a receiver's events: the counters count them (the RAM reads their word)
        await pulses(ctx, dec.rx_overrun, 30)
    replies = _answered_once_stable(
        encode_command("read", 3, addr=BOARD_REGS["RATE_ERRORS"], space="board"),
        before=before, meanwhile=meanwhile)
    # (the receiver's overruns meanwhile are bytes dropped: the reply says so, bit 7)
    assert [(r["cmd_seq"], r["result"], r["value"]) for r in replies] == [
        (3, RESULTS["ok"] | RESULT_INPUT_LOST, 37)]


def test_frames_md_states_the_burst_bound_the_decoder_has():
    import pathlib
    from mpu9250_ahrs.hdl.contract.commands import MAX_BURST_COMMANDS
    text = (pathlib.Path(__file__).resolve().parents[2] / "hdl" / "FRAMES.md").read_text()
    assert f"`MAX_BURST_COMMANDS` = {MAX_BURST_COMMANDS} commands" in text
    assert f"more than {MAX_BURST_COMMANDS} commands sent back to back" in text
    assert f"({FIFO_DEPTH:,} bytes, `COMMAND_FIFO_BYTES`" in text
