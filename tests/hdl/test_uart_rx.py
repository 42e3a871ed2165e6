"""UART receiver: bytes at the baud and a few per cent off it, glitches ignored, framing
errors and overruns counted."""

import pytest
from amaranth.sim import Simulator

from mpu9250_ahrs.hdl.link.uart_rx import UARTReceiver
from mpu9250_ahrs.sim.bench.streams import check_stream_rules


def waveform(data, bit_cycles, *, stop=1):
    """(level, cycles) segments of ``data`` sent 8N1 at ``bit_cycles`` (fractional) per bit,
    with a bit of idle line before and after."""
    levels = [1] * 3
    for byte in data:
        levels += [0] + [(byte >> k) & 1 for k in range(8)] + [stop]
    levels += [1] * 3
    out, t = [], 0.0
    for level in levels:
        start, t = round(t), t + bit_cycles
        out.append((level, round(t) - start))
    return out


def run(segments, *, divisor, ready=True):
    dut = UARTReceiver(divisor=divisor)
    sim = Simulator(dut)
    sim.add_clock(1e-6)
    check_stream_rules(sim, dut.o_stream, "received bytes")
    got = []
    errors = [0, 0]                     # the framing-error and overrun pulses, counted

    async def line(ctx):
        ctx.set(dut.o_stream.ready, ready)

        async def cycle():
            _, _, valid, byte, framing, overrun = await ctx.tick().sample(
                dut.o_stream.valid, dut.o_stream.payload, dut.framing_error, dut.overrun)
            if valid and ready:
                got.append(byte)
            errors[0] += framing
            errors[1] += overrun

        for level, cycles in segments:
            ctx.set(dut.rx, level)
            for _ in range(cycles):
                await cycle()
        for _ in range(4 * divisor):
            await cycle()
        got.append(("errors", *errors))
    sim.add_testbench(line)
    sim.run()
    return got[:-1], got[-1][1:]


DATA = [0x00, 0xFF, 0xA5, 0x5A, 0x01, 0x80, 0x3C]


@pytest.mark.parametrize("divisor, error", [(4, 0.0), (13, -0.03), (13, 0.0), (13, 0.03),
                                            (52, -0.04), (52, 0.04)])
def test_bytes_back_to_back(divisor, error):
    """At four cycles a bit (the simulated board's) the baud must match; at 13 (921,600 baud
    from 12 MHz) and 52 (from 48 MHz) a sender 3-4 % off is still received."""
    got, errors = run(waveform(DATA, divisor * (1 + error)), divisor=divisor)
    assert got == DATA and errors == (0, 0)


def test_a_glitch_is_not_a_start_bit():
    segments = [(1, 20), (0, 1), (1, 40), *waveform([0x42], 8)]
    got, errors = run(segments, divisor=8)
    assert got == [0x42] and errors == (0, 0)


def test_a_one_cycle_spike_inside_a_bit_is_voted_out():
    segments = []
    for level, cycles in waveform([0x00], 8):
        if level == 0 and cycles == 8 and len(segments) > 5:
            segments += [(0, 3), (1, 1), (0, 4)]       # a spike in the middle of a 0 bit
        else:
            segments.append((level, cycles))
    got, _ = run(segments, divisor=8)
    assert got == [0x00]


def test_framing_error_counted_and_byte_dropped():
    # the low stop bit runs on into a break: one error, not one per bit time
    segments = waveform([0x55], 8, stop=0)[:-3] + [(0, 40), (1, 30)] + waveform([0x66], 8)
    got, errors = run(segments, divisor=8)
    assert got == [0x66] and errors == (1, 0)


def test_overrun_counted():
    got, errors = run(waveform([1, 2, 3], 8), divisor=8, ready=False)
    assert errors == (0, 2)


def test_divisor_checked():
    with pytest.raises(ValueError, match="at least 4"):
        UARTReceiver(divisor=3)
