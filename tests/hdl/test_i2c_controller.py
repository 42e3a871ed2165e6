"""I2C controller against the bit-level bus model: transfers at 100 and 400 kHz, NACKs, clock
stretching, time-out, stuck-bus recovery."""

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.sensor.i2c_controller import I2CController, I2COp, I2CTiming
from mpu9250_ahrs.sim.bench.harness import CosimHarness, attach_models
from mpu9250_ahrs.sim.models.i2c_bus import I2CBusModel
from mpu9250_ahrs.sim.bench.streams import check_stream_rules, stream_get, stream_put


CLK = 12e6


class RegisterFile:
    """A plain I2C register device: 256 bytes, pointer wraps, writes to 0xFF are refused."""
    def __init__(self):
        self.regs = bytearray(range(256))
        self.pointer = 0

    def advance(self, t):
        pass

    def begin_read(self):
        pass

    @staticmethod
    def next_address(addr):
        return (addr + 1) & 0xFF

    def read_reg(self, addr):
        return self.regs[addr]

    def write_reg(self, addr, value):
        if addr == 0xFF:
            return False
        self.regs[addr] = value


def run(ops, *, timing=None, bus_kw=None, before=None):
    """Run ``ops`` ((op, data, ack) tuples); return results, the bus model and the status.
    ``before``: {op index: function(bus)} called before that op is offered (returning a number
    of cycles to wait first, or None)."""
    timing = timing or I2CTiming.for_clock(CLK)
    dut = I2CController(timing)
    harness = CosimHarness(dut, i2c=dut.pins)
    dev = RegisterFile()
    bus = I2CBusModel({0x50: dev}, standard_mode=timing.scl_hz(CLK) <= 100e3,
                      **(bus_kw or {}))
    sim = Simulator(harness)
    sim.add_clock(1 / CLK)
    check_stream_rules(sim, dut.o_stream, "results")
    attach_models(sim, harness, CLK, mpu=None, bus=bus)
    results = []
    status = {}

    async def tb(ctx):
        await ctx.tick().repeat(10)          # let the lines settle through the synchronisers
        for index, (op, data, ack) in enumerate(ops):
            if before and index in before:
                pause = before[index](bus)
                if pause:
                    await ctx.tick().repeat(pause)
            await stream_put(ctx, dut.i_stream, {"op": op, "data": data, "ack": ack})
            payload = await stream_get(ctx, dut.o_stream, timeout=200_000)
            results.append({"data": payload.data, "ack": payload.ack, "error": payload.error})
        await ctx.tick().repeat(50)
        st = ctx.get(dut.status)
        status.update(timeout=st.timeout, bus_stuck=st.bus_stuck,
                      arbitration=st.arbitration, recoveries=st.recoveries)
        status["lines"] = (ctx.get(harness.scl), ctx.get(harness.sda))
    sim.add_testbench(tb)
    sim.run()
    return results, bus, dev, status


S, P, W, R = I2COp.START, I2COp.STOP, I2COp.WRITE, I2COp.READ


def write_then_read(addr7, reg, values, n):
    ops = [(S, 0, 0), (W, addr7 << 1, 0), (W, reg, 0)] + [(W, v, 0) for v in values]
    ops += [(P, 0, 0), (S, 0, 0), (W, addr7 << 1, 0), (W, reg, 0), (S, 0, 0),
            (W, addr7 << 1 | 1, 0)]
    ops += [(R, 0, int(i < n - 1)) for i in range(n)] + [(P, 0, 0)]
    return ops


@pytest.mark.parametrize("scl_hz", [100e3, 400e3])
def test_write_then_read_with_repeated_start(scl_hz):
    ops = write_then_read(0x50, 0x10, [0xDE, 0xAD, 0xBE], 4)
    results, bus, dev, status = run(ops, timing=I2CTiming.for_clock(CLK, scl_hz=scl_hz))
    assert bus.violations == [], "\n".join(map(str, bus.violations))
    assert not any(r["error"] for r in results)
    assert all(r["ack"] for r, (op, _, _) in zip(results, ops) if op == W)
    assert dev.regs[0x10:0x13] == bytes([0xDE, 0xAD, 0xBE])
    reads = [r["data"] for r, (op, _, _) in zip(results, ops) if op == R]
    assert reads == [0xDE, 0xAD, 0xBE, 0x13]
    assert status["lines"] == (1, 1) and bus.starts == 3


def test_address_nack():
    results, bus, dev, status = run([(S, 0, 0), (W, 0x51 << 1, 0), (P, 0, 0)])
    # nobody at 0x51: the address byte is not acknowledged, which is no bus error (the data
    # field of a WRITE's result carries nothing)
    assert (results[1]["ack"], results[1]["error"]) == (0, 0)
    assert not results[2]["error"] and status["lines"] == (1, 1)
    assert status["timeout"] == 0 and status["bus_stuck"] == 0
    assert bus.violations == []


def test_data_nack():
    results, bus, dev, status = run([(S, 0, 0), (W, 0x50 << 1, 0), (W, 0xFF, 0), (W, 1, 0),
                                     (P, 0, 0)])
    assert [r["ack"] for r in results[1:4]] == [1, 1, 0]


def test_clock_stretching_tolerated():
    ops = write_then_read(0x50, 0x20, [0x42], 2)
    results, bus, dev, status = run(ops, bus_kw={"stretch_s": 20e-6})
    assert not any(r["error"] for r in results)
    assert [r["data"] for r, (op, _, _) in zip(results, ops) if op == R] == [0x42, 0x21]
    assert status["timeout"] == 0 and bus.violations == []


def test_stretching_past_the_timeout_is_an_error():
    timing = I2CTiming.for_clock(CLK, timeout_s=100e-6)
    results, bus, dev, status = run([(S, 0, 0), (W, 0x50 << 1, 0), (W, 0x01, 0)],
                                    timing=timing, bus_kw={"stretch_s": 400e-6})
    assert results[1]["error"] == 0 and results[2]["error"] == 1
    assert status["timeout"] == 1


def test_after_a_time_out_the_devices_are_reset_before_the_next_start():
    """A device stretches past the time-out in the middle of a write, then stops: the aborted
    transfer left it mid-byte, so the next START goes out as a START and a STOP first (and
    waits for SCL to be released); the next write lands, the flag clears, no violation."""
    timing = I2CTiming.for_clock(CLK, timeout_s=100e-6)
    ops = [(S, 0, 0), (W, 0x50 << 1, 0), (W, 0x01, 0), (P, 0, 0)] + \
        [(S, 0, 0), (W, 0x50 << 1, 0), (W, 0x40, 0), (W, 0x99, 0), (P, 0, 0)]
    results, bus, dev, status = run(ops, timing=timing, bus_kw={"stretch_s": 400e-6},
                                    before={4: lambda bus: setattr(bus, "stretch_s", 0.0) or
                                            int(450e-6 * CLK)})
    assert results[2]["error"] == 1
    assert not any(r["error"] for r in results[4:]) and results[7]["ack"] == 1
    assert dev.regs[0x40] == 0x99 and dev.regs[0x01] == 0x01     # the aborted write: none
    assert status["timeout"] == 0 and bus.violations == []
    assert bus.starts == 3                  # the first, the reset START-STOP, the new one


def test_stuck_bus_is_recovered():
    ops = write_then_read(0x50, 0x30, [0x77], 1)
    results, bus, dev, status = run(ops, bus_kw={"stuck_clocks": 5})
    assert not any(r["error"] for r in results)
    assert status["recoveries"] == 1 and status["bus_stuck"] == 0
    assert dev.regs[0x30] == 0x77


def test_bus_stuck_for_good_is_reported():
    results, bus, dev, status = run([(S, 0, 0)], bus_kw={"stuck_clocks": 1000})
    assert results[0]["error"] == 1 and status["bus_stuck"] == 1
    assert status["lines"][0] == 1          # SCL released


def test_timing_for_clock():
    fast = I2CTiming.for_clock(12e6)
    assert fast.scl_hz(12e6) <= 400e3 and fast.low / 12e6 >= 1.3e-6 and fast.high / 12e6 >= 0.6e-6
    std = I2CTiming.for_clock(50e6, scl_hz=100e3)
    assert std.scl_hz(50e6) <= 100e3 and std.low / 50e6 >= 4.7e-6 and std.high / 50e6 >= 4e-6
    with pytest.raises(ValueError, match="400 kHz"):
        I2CTiming.for_clock(12e6, scl_hz=1e6)
