"""cocotb tests of the AXI4-Lite slave (``axi_harness.AXIHarness`` exported to Verilog) driven
by ``cocotbext-axi``'s ``AxiLiteMaster``, back-pressure on every channel. Run by
``tests/hdl/test_axi_lite.py`` (``MPU9250_AXI_TRANSACTIONS`` sets how many random ones)."""

import os
import random

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles, RisingEdge
from cocotbext.axi import AxiLiteBus, AxiLiteMaster, AxiResp

from mpu9250_ahrs.hdl.contract.axi_regs import (AXI_ENGINE_BASE, AXI_REGS, AXI_RESULT_WORDS)
from mpu9250_ahrs.hdl.contract.commands import REGMAP_VERSION
from mpu9250_ahrs.hdl.engine.register_map import CONFIG_REGS, CONTROL_ADDR, HOST_WRITABLE

# engine registers the program only reads: what is written reads back
PLAIN = [CONFIG_REGS[f"{n}{i}"] for n in ("GYRO_OFF", "ACC_OFF", "HARD") for i in range(3)]
READ_ONLY = sorted(set(range(256)) - set(HOST_WRITABLE))
LOCAL = {a: name for name, (a, _, _) in AXI_REGS.items()}
BLOCK = [AXI_REGS[n][0] for n in AXI_RESULT_WORDS]


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
    await ClockCycles(dut.clk, 200)             # the engine's reset program
    return axi, rng


def _word(data):
    return int.from_bytes(data, "little")


async def _read(axi, address):
    r = await axi.read(address, 4)
    return _word(r.data), r.resp


async def _write(axi, address, value):
    r = await axi.write(address, (value & 0xFFFFFFFF).to_bytes(4, "little"))
    return r.resp


async def _block(axi):
    """QUAT0 .. FLAGS, in order (held between them)."""
    return [(await _read(axi, a))[0] for a in BLOCK]


@cocotb.test()
async def random_transactions(dut):
    axi, rng = await _start(dut, 1)
    n = int(os.environ.get("MPU9250_AXI_TRANSACTIONS", "10000"))
    shadow = {}
    refused = 0
    done = 0
    while done < n:
        kind = rng.randrange(8)
        if kind == 0:                           # a writable engine register, read back
            a = rng.choice(PLAIN)
            v = rng.getrandbits(32)
            assert await _write(axi, AXI_ENGINE_BASE + 4 * a, v) == AxiResp.OKAY
            shadow[a] = v
            done += 1
        elif kind == 1 and shadow:
            a = rng.choice(sorted(shadow))
            value, resp = await _read(axi, AXI_ENGINE_BASE + 4 * a)
            assert resp == AxiResp.OKAY and value == shadow[a], (a, value, shadow[a])
        elif kind == 2:                         # refused: a read-only engine register
            a = rng.choice(READ_ONLY)
            assert await _write(axi, AXI_ENGINE_BASE + 4 * a, rng.getrandbits(32)) == \
                AxiResp.SLVERR
            refused += 1
        elif kind == 3:                         # refused: CONTROL with a reserved bit
            assert await _write(axi, AXI_ENGINE_BASE + 4 * CONTROL_ADDR, 1 << 20) == \
                AxiResp.SLVERR
            refused += 1
        elif kind == 4:                         # unmapped: DECERR both ways
            a = rng.choice([x for x in range(0, AXI_ENGINE_BASE, 4) if x not in LOCAL])
            if rng.random() < 0.5:
                assert (await _read(axi, a))[1] == AxiResp.DECERR
            else:
                assert await _write(axi, a, 0) == AxiResp.DECERR
        elif kind == 5:                         # read-only local words refuse a write
            a = rng.choice([AXI_REGS[n][0] for n in ("VERSION", "STATUS", "FILTERED")])
            assert await _write(axi, a, 0) == AxiResp.SLVERR
        elif kind == 6:                         # the block: one result, however it is read
            words = await _block(axi)
            assert len(set(words[:11])) == 1, words
        else:
            value, resp = await _read(axi, AXI_REGS["VERSION"][0])
            assert resp == AxiResp.OKAY and value & 0xFFFF == REGMAP_VERSION
        done += 1
    value, _ = await _read(axi, AXI_REGS["REFUSED"][0])
    assert value == min(refused, 0xFFFF), (value, refused)


@cocotb.test()
async def snapshot_holds_while_results_arrive(dut):
    """Results every 97 cycles; a block read slowly (long pauses) spans several: its words
    still come from one result, and the results it did not show are counted."""
    axi, rng = await _start(dut, 2)
    for channel in (axi.read_if.ar_channel, axi.read_if.r_channel):
        channel.set_pause_generator(_pauses(rng, 0.9))
    for _ in range(20):
        words = await _block(axi)
        assert len(set(words[:11])) == 1, words
    dropped, _ = await _read(axi, AXI_REGS["DROPPED"][0])
    assert dropped > 0


@cocotb.test()
async def interrupt_set_and_cleared(dut):
    axi, rng = await _start(dut, 3)
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
    await ClockCycles(dut.clk, 300)
    assert dut.irq.value == 0 and (await _read(axi, irq))[0] & 1
