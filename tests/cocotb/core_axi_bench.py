"""cocotb test of the exported core's AXI4-Lite slave (``build --verilog-only --axi-lite``, the
Verilog a user instantiates) driven by ``cocotbext-axi``'s ``AxiLiteMaster``, back-pressure on
every channel. No sensor on its pins (the driver retries its bring-up): the engine is idle, so
this checks the slave's wiring in the core: the host's registers through the command decoder's
executor (engine, board, PWM), the board's RAW_MODE on the core's own pin, the local words. Run
by ``tests/hdl/test_axi_lite.py`` (``MPU9250_AXI_TRANSACTIONS``, ``MPU9250_CORE_VERSION``)."""

import os
import random

import cocotb
from cocotb.clock import Clock
from cocotb.triggers import ClockCycles
from cocotbext.axi import AxiLiteBus, AxiLiteMaster, AxiResp

from mpu9250_ahrs.hdl.contract.axi_regs import AXI_REGS, axi_register_address
from mpu9250_ahrs.hdl.contract.commands import BOARD_REGS, REGMAP_VERSION, SPACES
from mpu9250_ahrs.hdl.contract.pwm_regs import PWM_REGS
from mpu9250_ahrs.hdl.engine.register_map import CONFIG_REGS, HOST_WRITABLE

PLAIN = [CONFIG_REGS[f"{n}{i}"] for n in ("GYRO_OFF", "ACC_OFF", "HARD") for i in range(3)]
READ_ONLY = sorted(set(range(256)) - set(HOST_WRITABLE))


def _address(space, a):
    return axi_register_address(SPACES[space], a)


async def _read(axi, address):
    r = await axi.read(address, 4)
    return int.from_bytes(r.data, "little"), r.resp


async def _write(axi, address, value):
    return (await axi.write(address, (value & 0xFFFFFFFF).to_bytes(4, "little"))).resp


def _pauses(rng, p):
    while True:
        yield rng.random() < p


@cocotb.test()
async def core_registers_through_axi(dut):
    rng = random.Random(7)
    for name, value in (("cfg__valid", 0), ("cfg_read__valid", 0), ("cfg_read_data__ready", 0),
                        ("imu__cipo", 0), ("imu_int", 0), ("uart_rx", 1)):
        getattr(dut, name).value = value
    dut.rst.value = 1
    cocotb.start_soon(Clock(dut.clk, 10, unit="ns").start())
    axi = AxiLiteMaster(AxiLiteBus.from_prefix(dut, "s_axi_"), dut.clk, dut.rst,
                        reset_active_level=True)
    for side in (axi.write_if, axi.read_if):
        side.log.setLevel("WARNING")
    for channel in (axi.write_if.aw_channel, axi.write_if.w_channel, axi.write_if.b_channel,
                    axi.read_if.ar_channel, axi.read_if.r_channel):
        channel.set_pause_generator(_pauses(rng, 0.3))
    await ClockCycles(dut.clk, 5)
    dut.rst.value = 0
    await ClockCycles(dut.clk, 300)             # the engine's reset program
    version = int(os.environ["MPU9250_CORE_VERSION"])
    shadow, raw_mode = {}, 0
    for _ in range(int(os.environ.get("MPU9250_AXI_TRANSACTIONS", "1000"))):
        kind = rng.randrange(8)
        if kind == 0:
            a, v = rng.choice(PLAIN), rng.getrandbits(32)
            assert await _write(axi, _address("engine", a), v) == AxiResp.OKAY
            shadow[a] = v
        elif kind == 1 and shadow:
            a = rng.choice(sorted(shadow))
            assert await _read(axi, _address("engine", a)) == (shadow[a], AxiResp.OKAY)
        elif kind == 2:
            a = rng.choice(READ_ONLY)
            assert await _write(axi, _address("engine", a), 1) == AxiResp.SLVERR
        elif kind == 3:                         # RAW_MODE: the core's pin follows it
            raw_mode = rng.getrandbits(1)
            assert await _write(axi, _address("board", BOARD_REGS["RAW_MODE"]),
                                raw_mode) == AxiResp.OKAY
            assert dut.raw_mode.value == raw_mode
        elif kind == 4:
            assert await _read(axi, _address("board", BOARD_REGS["VERSION"])) == \
                (version, AxiResp.OKAY)
        elif kind == 5:                         # a PWM channel's high time, read back
            a, v = PWM_REGS[f"PWM_HIGH{rng.randrange(4)}"], rng.randrange(1000)
            assert await _write(axi, _address("pwm", a), v) == AxiResp.OKAY
            assert await _read(axi, _address("pwm", a)) == (v, AxiResp.OKAY)
        elif kind == 6:
            value, resp = await _read(axi, AXI_REGS["VERSION"][0])
            assert resp == AxiResp.OKAY and value & 0xFFFF == REGMAP_VERSION
        else:
            assert (await _read(axi, 0x3FC))[1] == AxiResp.DECERR
    # no sample came: nothing started after the reset program, the block's counter is 0
    assert (await _read(axi, AXI_REGS["COUNTER"][0])) == (0, AxiResp.OKAY)
