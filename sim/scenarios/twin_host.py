"""The twin's ``host`` loop (issue #57): the same law on a PC. The whole core of the default
build (the PWM block, no controller) co-simulated as in the ``chip`` loop (``twin_chip``: 4 MHz,
the sensor's real 1 kHz, its models reading the plant); the host reads its attitude frames
off ``uart_tx`` as they end, each a stated USB latency later (an FTDI adapter holds what it
received until its latency timer runs out: 16 ms by default, 1 ms at best), runs the
controller's fixed-point model on the frame's pitch, gyro and bias, and writes the duty to the
PWM block's high times (two commands: motor A's forward and reverse channels; motor B is wired
in parallel with A, a DRV8833's parallel mode) into ``uart_rx`` at once.

The link: the core's UART at a quarter of its clock (1 Mbaud here, the board's 921,600 within
9 %), so an attitude frame (99 bytes) takes about 1 ms, nearly a sample period, and the
commands' replies share the line (the frame arbiter sends replies first: frames that find the
line busy are not sent). What the host gets is fewer updates than the samples (the summary's
``updates``), each late by a frame's time on the line plus the latency: the comparison the twin
is for.
"""

import math

from ...hdl.contract.pwm_regs import PWM_REGS
from ...hdl.link.frame_types import ATTITUDE
from ...host.protocol import FrameDecoder, encode_command
from ...reference.balance_control import BalanceFixed, BalanceFixedConfig
from ..bench.harness import CosimHarness, PinModels
from ..bench.open_bench import open_bench
from .board import line_segments
from .core import core_key
from .twin_chip import (GYRO_LSB_PER_DPS, SETTLE_S, STEP_CYCLES, PwmMeter, SampleFeed,
                        plant_models)


__all__ = ["run_host_loop"]

MOTOR_PERIOD_CYCLES = 200           # 20 kHz at 4 MHz: the PWM block's shortest motor period


class _Host:
    """The PC: frames in, the law, commands out; the line's bits it sends, in time."""

    def __init__(self, gains, latency_cycles, divisor, rate_hz):
        self.law = BalanceFixed(BalanceFixedConfig.from_gains(
            gains, gyro_lsb_per_dps=GYRO_LSB_PER_DPS, sample_hz=rate_hz))
        self.latency, self.divisor = latency_cycles, divisor
        self.decoder = FrameDecoder()
        self.seq = 0
        self.due = []                   # (cycle, pitch, gyro, bias): frames the host will see
        self.line = []                  # (level, cycles) runs still to put on uart_rx
        self.pitch = 0.0
        self.updates = 0

    def send(self, *commands):
        data = b""
        for name, space, addr, value in commands:
            data += encode_command(name, self.seq, addr=addr, value=value, space=space)
            self.seq = (self.seq + 1) & 0xFF
        self.line += line_segments(data, self.divisor)

    def received(self, data, cycle):
        for frame_type, _seq, fields in self.decoder.feed(data):
            if frame_type == ATTITUDE:
                att = fields["attitude"]
                self.due.append((cycle + self.latency, att["angles"][1],
                                 fields["sample"]["gyro"][1], att["bias"][1]))

    def run_due(self, cycle):
        """The frames the host has by ``cycle``: the law on each, the last duty sent."""
        while self.due and self.due[0][0] <= cycle:
            _, pitch, gyro, bias = self.due.pop(0)
            self.pitch = pitch * 2 * math.pi / 2 ** 32
            duty = self.law.step(pitch, gyro, bias)
            high = round(MOTOR_PERIOD_CYCLES * abs(duty) / 1024)
            self.send(("write", "pwm", PWM_REGS["PWM_HIGH0"], high if duty > 0 else 0),
                      ("write", "pwm", PWM_REGS["PWM_HIGH1"], high if duty < 0 else 0))
            self.updates += 1


def run_host_loop(plant, seconds, *, pushes, gains, on_sample, latency_ms=1.0, seed=1,
                  compiled=True, progress=None):
    """Runs the loop as ``twin_chip.run_chip_loop`` does (``on_sample`` per 1 ms with the
    duty and the host's last pitch); the host sees each frame ``latency_ms`` after its last
    byte. Returns what the run saw (cycles, updates, the simulator)."""
    from ...hdl.board.top import AHRSCore
    setup, model = plant_models(plant, seed)
    held_tilt = plant.psi
    core_kwargs = dict(clk_freq=setup.clk_freq, config=setup.config,
                       timing=setup.driver_timing(), baud=setup.clk_freq / 4)
    core = AHRSCore(**core_kwargs)
    harness = CosimHarness(core, spi=core.imu, int_pin=core.imu_int)
    sent = []
    bench = open_bench(harness, {"uart_rx": core.uart_rx},
                       {"pwm": core.pwm, "uart_tx": core.uart_tx, "status": core.status},
                       setup.clk_freq, compiled=compiled, name="twin_host",
                       key=core_key("twin_host", **core_kwargs),
                       models=PinModels(setup.clk_freq, mpu=model),
                       uart=("uart_tx", core.uart.divisor, sent))
    host = _Host(gains, round(latency_ms * 1e-3 * setup.clk_freq), core.uart.divisor,
                 rate_hz=setup.config.output_data_rate / core.telemetry_divider)
    seen = {"simulator": "compiled" if bench.compiled else "python"}
    feed = SampleFeed(round(setup.clk_freq / 1000 / STEP_CYCLES), on_sample, progress,
                      seconds)
    dt = STEP_CYCLES / setup.clk_freq

    async def scenario(bench):
        bench.set("uart_rx", 1)
        # the board up and streaming, the filter settled, the PWM block set up
        while not sent:
            await bench.tick(10_000)
            if bench.cycle > 40_000_000:
                raise RuntimeError("the core never sent a frame (bring-up failed)")
        await bench.tick(round(SETTLE_S * setup.clk_freq))
        host.send(("write", "pwm", PWM_REGS["PWM_MODE"], 0b0011),
                  ("write", "pwm", PWM_REGS["PWM_MOTOR_PERIOD"], MOTOR_PERIOD_CYCLES),
                  ("write", "pwm", PWM_REGS["PWM_ENABLE"], 0b0011))
        await _play(bench, host)
        host.law.arm(by_host=True)
        plant.psi = held_tilt
        sent.clear()
        host.decoder.drop()
        meter = PwmMeter(bench)
        for k in range(round(seconds / dt)):
            t = k * dt
            high = [0, 0]
            await _step(bench, host, bench.cycle + STEP_CYCLES, meter, high)
            host.received(bytes(sent), bench.cycle)
            sent.clear()
            host.run_due(bench.cycle)
            duty = (high[0] - high[1]) / STEP_CYCLES
            plant.step(dt, duty, sum(p.force(t) for p in pushes))
            if not feed.step(k, t, duty, lambda: host.pitch):
                break

    bench.run(scenario)
    seen.update(cycles=bench.cycle, updates=host.updates)
    return seen


async def _play(bench, host):
    """The host's line played out to its end (set-up commands, before the loop runs)."""
    while host.line:
        level, cycles = host.line.pop(0)
        bench.set("uart_rx", level)
        await bench.tick(cycles)
    bench.set("uart_rx", 1)


async def _step(bench, host, end, meter, high):
    """Clocks to ``end``: the host's line put on ``uart_rx`` edge by edge, the PWM pins'
    high cycles (motor A's two channels, ``high``) counted by ``meter`` between them."""
    while bench.cycle < end:
        if host.line:
            level, cycles = host.line[0]
            bench.set("uart_rx", level)
            stop = min(end, bench.cycle + cycles)
        else:
            bench.set("uart_rx", 1)
            stop = end
        start = bench.cycle
        await meter.until(bench, stop, high)
        if host.line:
            level, cycles = host.line[0]
            left = cycles - (bench.cycle - start)
            if left > 0:
                host.line[0] = (level, left)
            else:
                host.line.pop(0)
