"""Command decoder: every command against an engine-port model and the PWM block; damaged
commands (bits flipped, bytes dropped, cut off, noise) fuzzed: nothing half done, nothing
done that was not sent whole, every failure counted."""

import random

from amaranth import Elaboratable, Module
from amaranth.lib import wiring
from amaranth.sim import Simulator
from hypothesis import given, settings, strategies as st

from mpu9250_ahrs.hdl.attitude_program import (CONFIG_REGS, CONTROL_ADDR, CONTROL_KEEP,
                                               CONTROL_RESET, HOST_WRITABLE, TELEMETRY_DIV_ADDR)
from mpu9250_ahrs.hdl.command_decoder import (BOARD_REGS, COMMANDS, REGMAP_VERSION, RESULTS,
                                              CommandDecoder)
from mpu9250_ahrs.hdl.pwm import PWM_REGS, PWMOutputs
from mpu9250_ahrs.host.protocol import encode_command, encode_frame, to_python
from mpu9250_ahrs.sim.streams import check_stream_rules

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


def run(data, *, gaps=None, busy_cycles=3):
    """Feed ``data`` (bytes; ``gaps``: {index: idle cycles before that byte}); the engine port
    model takes a write after ``busy_cycles`` and answers a read of address a with 3a + 1.
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
        for k, byte in enumerate(data):
            if gaps and k in gaps:
                await ctx.tick().repeat(gaps[k])
            ctx.set(dec.i_stream.valid, 1)
            ctx.set(dec.i_stream.payload, byte)
            await ctx.tick().until(dec.i_stream.ready)
            ctx.set(dec.i_stream.valid, 0)
        await ctx.tick().repeat(TIMEOUT + 60)
        out["stats"] = to_python(ctx.get(dec.stats))
        out["raw"] = ctx.get(dec.raw_mode)
    sim.add_testbench(host)
    sim.run()
    return writes, replies, out["stats"], out["raw"]


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
    assert raw == 1
    assert stats["ok"] == 10 and stats["refused"] == 7 and stats["malformed"] == 2
    assert stats["crc_errors"] == 0 and stats["discarded"] == 0


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
def test_damaged_commands_change_nothing(seed, damage):
    """Five writes, one damaged: the writes done are exactly the intact commands' (the one
    after a dropped byte may be lost with it: its sync was taken as the damaged one's CRC),
    whole and in order; the damaged one did nothing and was counted."""
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
                gaps[len(data) + len(frame)] = TIMEOUT + 10      # the host went quiet
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
    lost = [w for w in intact if w not in writes]
    after = commands[victim + 1][0] if victim + 1 < len(commands) else None
    assert lost in ([], [after]) if damage in ("drop", "flip", "noise") else lost == []
    assert len(replies) == len(writes)
    if damage != "garbage" or stats["discarded"] == 0:
        failures = stats["crc_errors"] + stats["malformed"] + stats["discarded"]
        assert failures >= 1 or damage == "garbage"


def test_cut_off_command_times_out():
    frame = encode_command("write", 1, addr=CONFIG_REGS["R"], value=1)
    good = encode_command("write", 2, addr=CONFIG_REGS["P0"], value=2)
    data = frame[:8] + good
    writes, replies, stats, _ = run(data, gaps={8: TIMEOUT + 5})
    assert writes == [(CONFIG_REGS["P0"], 2)] and stats["malformed"] == 1
    assert [r["cmd_seq"] for r in replies] == [2]
