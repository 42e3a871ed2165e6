"""cocotb tests of the AXI4-Lite slave (``axi_harness.AXIHarness`` exported to Verilog) driven
by ``cocotbext-axi``'s ``AxiLiteMaster``, back-pressure on every channel. Run by
``tests/hdl/test_axi_lite.py`` (``MPU9250_AXI_TRANSACTIONS`` sets how many random ones)."""

import os
import random

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, RisingEdge
from cocotbext.axi import AxiLiteBus, AxiLiteMaster, AxiResp

from mpu9250_ahrs.hdl.contract.axi_regs import (AXI_ENGINE_RESULT_WORDS, AXI_REGISTER_BASE,
                                                 AXI_REGS, AXI_RESULT_WORDS,
                                                 axi_register_address)
from mpu9250_ahrs.hdl.contract.commands import BOARD_REGS, REGMAP_VERSION, SPACES
from mpu9250_ahrs.hdl.engine.register_map import CONFIG_REGS, CONTROL_ADDR, HOST_WRITABLE

from axi_harness import VERSION

# engine registers the program only reads: what is written reads back
PLAIN = [CONFIG_REGS[f"{n}{i}"] for n in ("GYRO_OFF", "ACC_OFF", "HARD") for i in range(3)]
READ_ONLY = sorted(set(range(256)) - set(HOST_WRITABLE))
LOCAL = {a: name for name, (a, _, _) in AXI_REGS.items()}
BLOCK = [AXI_REGS[n][0] for n in AXI_RESULT_WORDS]
SEQUENCE = AXI_REGS["SEQUENCE"][0]
ENGINE = lambda a: axi_register_address(SPACES["engine"], a)        # noqa: E731
BOARD = lambda a: axi_register_address(SPACES["board"], a)          # noqa: E731
PWM = lambda a: axi_register_address(SPACES["pwm"], a)              # noqa: E731
NO_BOARD_REG = sorted(set(range(256)) - set(BOARD_REGS.values()))


def _words(value):
    """An ``Attitude``'s bits as the block's twelve words (unsigned)."""
    fields = [(value >> (32 * i)) & 0xFFFFFFFF for i in range(11)]
    return (*fields, value >> (32 * 11))


async def _monitor(dut, seen):
    """Every result the engine gives, its block's words, into ``seen``."""
    while True:
        await RisingEdge(dut.clk)
        if dut.done.value:
            seen.add(_words(dut.result.value.to_unsigned()))


def _pauses(rng, p):
    while True:
        yield rng.random() < p


async def _start(dut, seed):
    rng = random.Random(seed)
    cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())
    axi = AxiLiteMaster(AxiLiteBus.from_prefix(dut, "s_axi_"), dut.clk, dut.rst,
                        reset_active_level=True)
    for side in (axi.write_if, axi.read_if):   # no line per transaction
        side.log.setLevel("WARNING")
    # back-pressure on every channel: the master pauses its valids (AW, W, AR) and readies
    # (B, R) at random
    for channel in (axi.write_if.aw_channel, axi.write_if.w_channel, axi.write_if.b_channel,
                    axi.read_if.ar_channel, axi.read_if.r_channel):
        channel.set_pause_generator(_pauses(rng, 0.3))
    dut.rst.value = 1
    await ClockCycles(dut.clk, 5)
    dut.rst.value = 0
    SERVED.update(ok=0, refused=0)              # the executor's counters start again
    seen = set()
    cocotb.start_soon(_monitor(dut, seen))
    while not seen:                             # the reset program, then a first result
        await RisingEdge(dut.clk)
    return axi, rng, seen


def _word(data):
    return int.from_bytes(data, "little")


# the executor's answers so far (the AXI answers to its addresses: the host's registers and
# the result block's engine words), as CMD_OK and CMD_REFUSED count them
SERVED = {"ok": 0, "refused": 0}
EXECUTED = set(BLOCK[:AXI_ENGINE_RESULT_WORDS])


def _served(address, resp):
    if address >= AXI_REGISTER_BASE or address in EXECUTED:
        SERVED["ok" if resp == AxiResp.OKAY else "refused"] += 1


async def _read(axi, address):
    r = await axi.read(address, 4)
    _served(address, r.resp)
    return _word(r.data), r.resp


async def _write(axi, address, value):
    r = await axi.write(address, (value & 0xFFFFFFFF).to_bytes(4, "little"))
    _served(address, r.resp)
    return r.resp


async def _block(axi, rng):
    """QUAT0 .. FLAGS in a random order between two reads of SEQUENCE: the words (by address)
    and whether SEQUENCE was the same."""
    before = (await _read(axi, SEQUENCE))[0]
    order = BLOCK[:]
    rng.shuffle(order)
    words = {a: (await _read(axi, a))[0] for a in order}
    after = (await _read(axi, SEQUENCE))[0]
    return tuple(words[a] for a in BLOCK), before == after


async def _coherent(axi, rng, seen):
    """Reads the block until SEQUENCE says it is one result's; checks it is one the engine
    gave; returns how many reads were torn (SEQUENCE moved)."""
    torn = 0
    while True:
        words, same = await _block(axi, rng)
        if same:
            assert words in seen, [hex(w) for w in words]
            return torn
        torn += 1


@cocotb.test()
async def random_transactions(dut):
    """Random reads and writes of every kind, each answered as the map says; the executor's
    counters (CMD_OK, CMD_REFUSED, through the board window) count what it answered."""
    axi, rng, seen = await _start(dut, 1)
    n = int(os.environ.get("MPU9250_AXI_TRANSACTIONS", "10000"))
    shadow = {}
    raw_mode = 0
    for _ in range(n):
        kind = rng.randrange(11)
        if kind == 0:                           # a writable engine register, read back
            a = rng.choice(PLAIN)
            v = rng.getrandbits(32)
            assert await _write(axi, ENGINE(a), v) == AxiResp.OKAY
            shadow[a] = v
        elif kind == 1 and shadow:
            a = rng.choice(sorted(shadow))
            value, resp = await _read(axi, ENGINE(a))
            assert resp == AxiResp.OKAY and value == shadow[a], (a, value, shadow[a])
        elif kind == 2:                         # refused: a read-only engine register
            a = rng.choice(READ_ONLY)
            assert await _write(axi, ENGINE(a), rng.getrandbits(32)) == AxiResp.SLVERR
        elif kind == 3:                         # refused: CONTROL with a reserved bit
            assert await _write(axi, ENGINE(CONTROL_ADDR), 1 << 20) == AxiResp.SLVERR
        elif kind == 4:                         # unmapped: DECERR both ways
            a = rng.choice([x for x in range(0, AXI_REGISTER_BASE, 4) if x not in LOCAL] +
                           [BOARD(rng.choice(NO_BOARD_REG)), PWM(rng.randrange(256))])
            if rng.random() < 0.5:
                assert (await _read(axi, a))[1] == AxiResp.DECERR, hex(a)
            else:
                assert await _write(axi, a, 0) == AxiResp.DECERR, hex(a)
        elif kind == 5:                         # read-only words refuse a write
            a = rng.choice([AXI_REGS[n][0] for n in ("VERSION", "STATUS", "FILTERED")] +
                           [BOARD(BOARD_REGS[n]) for n in ("VERSION", "FRAMES_SENT")])
            assert await _write(axi, a, 0) == AxiResp.SLVERR
        elif kind == 6:                         # the block: one result, however it is read
            await _coherent(axi, rng, seen)
        elif kind == 7:                         # the board's RAW_MODE, written and read
            if rng.random() < 0.5:
                raw_mode = rng.getrandbits(1)
                assert await _write(axi, BOARD(BOARD_REGS["RAW_MODE"]), raw_mode) == \
                    AxiResp.OKAY
            else:
                assert await _read(axi, BOARD(BOARD_REGS["RAW_MODE"])) == \
                    (raw_mode, AxiResp.OKAY)
        elif kind == 8:                         # the board's build words
            assert await _read(axi, BOARD(BOARD_REGS["VERSION"])) == (VERSION, AxiResp.OKAY)
            assert await _read(axi, BOARD(BOARD_REGS["REGMAP_VERSION"])) == \
                (REGMAP_VERSION, AxiResp.OKAY)
        elif kind == 9:                         # the executor's counts of what it answered
            expected = dict(SERVED)
            ok, resp = await _read(axi, BOARD(BOARD_REGS["CMD_OK"]))
            assert resp == AxiResp.OKAY and ok == min(expected["ok"], 0xFFFF), (ok, expected)
            expected = dict(SERVED)
            refused, _ = await _read(axi, BOARD(BOARD_REGS["CMD_REFUSED"]))
            assert refused == min(expected["refused"], 0xFFFF), (refused, expected)
        else:
            value, resp = await _read(axi, AXI_REGS["VERSION"][0])
            assert resp == AxiResp.OKAY and value & 0xFFFF == REGMAP_VERSION


@cocotb.test()
async def sequence_tells_a_torn_block(dut):
    """Blocks read slowly (long pauses), so that results come while one is read: a block with
    SEQUENCE the same before and after is one result's, bit for bit; some are torn (SEQUENCE
    moved: read again), so the rule was put to the test."""
    axi, rng, seen = await _start(dut, 2)
    for channel in (axi.read_if.ar_channel, axi.read_if.r_channel):
        channel.set_pause_generator(_pauses(rng, 0.9))
    torn = 0
    for _ in range(int(os.environ.get("MPU9250_AXI_BLOCKS", "20"))):
        torn += await _coherent(axi, rng, seen)
    assert torn > 0


@cocotb.test()
async def interrupt_set_and_cleared(dut):
    axi, rng, seen = await _start(dut, 3)
    irq, enable = AXI_REGS["IRQ"][0], AXI_REGS["IRQ_ENABLE"][0]
    assert dut.irq.value == 0                   # not enabled
    assert await _write(axi, enable, 1) == AxiResp.OKAY
    for _ in range(5):
        while not dut.irq.value:
            await RisingEdge(dut.clk)
        assert (await _read(axi, irq))[0] & 1
        assert await _write(axi, irq, 1) == AxiResp.OKAY          # write one to clear
        await RisingEdge(dut.clk)
        assert dut.irq.value == 0
    assert await _write(axi, irq, 0) == AxiResp.OKAY              # writing 0 leaves it
    assert await _write(axi, enable, 0) == AxiResp.OKAY
    await ClockCycles(dut.clk, 2500)           # two results at least
    assert dut.irq.value == 0 and (await _read(axi, irq))[0] & 1
