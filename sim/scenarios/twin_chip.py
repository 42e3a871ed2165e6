"""The twin's ``chip`` loop (issue #57): the whole core with the balance controller
(``AHRSCore(controller="balance")``) co-simulated, its MPU9250 and AK8963 models reading the
plant (``sim/models/balance_plant.py``), its PWM pins moving the plant.

Time: a 4 MHz clock and the sensor's real 1 kHz (4,000 cycles a sample, the sample period not
scaled), so that the engine's, the controller's and the plant's seconds are one: only the
clock is slower than the board's 48 MHz, which stretches the data-ready to duty latency in
time (about 12 times: a few hundred µs rather than 40) and makes the motor PWM 3.9 kHz; the
start-up delays are scaled by 10⁻³ (bring-up in a few ms). The plant is held upright at its
start tilt (on its stand) until the core streams and its filter has settled (``SETTLE_S``),
then the arming pin goes high and the plant is let go: the twin's t = 0.

The PWM pins drive the plant as an H-bridge does, averaged over each plant step (0.1 ms, 400
cycles): the duty of a step is the fraction of its cycles channel 0 (motor A forward) was high
less the fraction channel 1 (reverse) was (the motor's electrical time constant is far below a
step, ``BalancePlant`` neglects it). Motor B's channels (2, 3) are checked to match A's.
"""

import math

import numpy as np

from ...hdl.contract import ak8963_regs as A
from ...hdl.contract.balance_regs import CONTROL_BITS
from ...reference.balance_control import BalanceFixedConfig
from ...reference.frames import body_to_mag
from ..bench.harness import CosimHarness, PinModels
from ..bench.open_bench import open_bench
from ..models.balance_plant import G
from ..models.sources import SensorSample
from .core import core_key
from .setup import SimSetup


__all__ = ["run_chip_loop", "plant_models", "PwmMeter", "SampleFeed", "CHIP_CLOCK_HZ"]

CHIP_CLOCK_HZ = 4e6
STEP_CYCLES = 400                   # a plant step: 0.1 ms
SETTLE_S = 0.3                      # after the first result, before arming
MOTORS_RUNNING_S = 0.05             # a fault's run: pins high this near its end: running
DEFAULT_TRACE_S = 0.05              # --vcd without --trace-to: 50 ms from the arming
GYRO_LSB_PER_DPS = 16.4             # the default ±2000 °/s
ACCEL_LSB_PER_G = 2048              # the default ±16 g


def controller_registers(gains, sign):
    """The controller's registers at reset for ``gains`` (``BalanceGains``): the build's
    ``controller_regs``. ``sign``: +1 if the attitude's pitch grows as the plant leans forward,
    -1 if it falls (the tilt's gains then turn round, and the rate's: the gyro's rate keeps its
    sign); the arming pin arms it."""
    c = BalanceFixedConfig.from_gains(gains, gyro_lsb_per_dps=GYRO_LSB_PER_DPS)
    control = 1 << CONTROL_BITS["pin_arms"]
    return {"BAL_CONTROL": control, "BAL_KP": sign * c.kp, "BAL_KD": sign * c.kd,
            "BAL_KI": sign * c.ki, "BAL_KV": c.kv, "BAL_SETPOINT": sign * c.setpoint,
            "BAL_CUTOFF": c.cutoff, "BAL_OUT_LIMIT": c.out_limit, "BAL_I_LIMIT": c.i_limit,
            "BAL_STALE": c.stale}


class _Sensor:
    """The MPU9250 and AK8963 sources: what they measure on the plant's body now, with noise."""

    def __init__(self, plant, rng, field_ut=50.0, inclination_deg=60.0):
        self.plant, self.rng = plant, rng
        inc = math.radians(inclination_deg)
        self.earth = field_ut / 0.15 * np.array([0.0, math.cos(inc), -math.sin(inc)])
        self.asa_factor = None

    def sample(self, index, t):
        rate, (fx, fz) = self.plant.imu()
        gyro = (self.rng.normal(0, 2.0), math.degrees(rate) * GYRO_LSB_PER_DPS +
                self.rng.normal(0, 2.0), self.rng.normal(0, 2.0))
        accel = (fx / G * ACCEL_LSB_PER_G + self.rng.normal(0, 6.0), self.rng.normal(0, 6.0),
                 fz / G * ACCEL_LSB_PER_G + self.rng.normal(0, 6.0))
        clip = lambda v: tuple(int(np.clip(round(x), -32768, 32767)) for x in v)  # noqa: E731
        return SensorSample(accel=clip(accel), temp=0, gyro=clip(gyro))

    def field(self, index, t):
        psi = self.plant.psi                        # the body turned about its y axis
        c, s = math.cos(psi), math.sin(psi)
        body = np.array([c * self.earth[0] - s * self.earth[2], self.earth[1],
                         s * self.earth[0] + c * self.earth[2]])
        body = body + self.rng.normal(0, 1.5, 3)
        raw = body_to_mag(body) / self.asa_factor
        return tuple(int(round(v)) for v in raw)


class PwmMeter:
    """The PWM pins' high cycles, counted edge by edge as the bench clocks (the chip and host
    loops'): ``levels`` the pins now, ``last`` the cycle they were last looked at,
    ``last_on`` the last cycle any pin was high."""

    def __init__(self, bench):
        self.levels, self.last, self.last_on = bench.get("pwm"), bench.cycle, None

    async def until(self, bench, stop, high):
        """Clocks to ``stop``, adding to ``high[ch]`` the cycles pin ``ch`` was high (the
        first ``len(high)`` pins)."""
        while bench.cycle < stop:
            await bench.changed("pwm", until=stop)
            now = bench.cycle
            for ch in range(len(high)):
                if self.levels >> ch & 1:
                    high[ch] += now - self.last
            if self.levels:
                self.last_on = now
            self.last, self.levels = now, bench.get("pwm")


class SampleFeed:
    """The plant steps' duties averaged over each sample period, handed on with the pitch the
    loop saw (``on_sample(t, duty, pitch)``, False to stop), progress every 1,000 samples."""

    def __init__(self, per_sample, on_sample, progress, seconds):
        self.per_sample, self.on_sample = per_sample, on_sample
        self.progress, self.seconds = progress, seconds
        self.duties = []

    def step(self, k, t, duty, pitch):
        """Plant step ``k`` at ``t`` applied ``duty``; ``pitch()`` the loop's pitch (rad).
        False once ``on_sample`` says stop."""
        self.duties.append(duty)
        if len(self.duties) < self.per_sample:
            return True
        if self.progress and k % (self.per_sample * 1000) == self.per_sample - 1:
            self.progress(t / self.seconds)
        mean = sum(self.duties) / self.per_sample
        self.duties.clear()
        return self.on_sample(t, mean, pitch())


def plant_models(plant, seed):
    """The twin's set-up (4 MHz, the sensor's real 1 kHz) and its MPU9250 model with an
    AK8963 behind it, both reading ``plant`` (``_Sensor``, noise from ``seed``): the chip
    loop's and the host loop's."""
    setup = SimSetup(clk_freq=CHIP_CLOCK_HZ, odr_scale=1.0, ak_clock_error=-0.55)
    sensor = _Sensor(plant, np.random.default_rng(seed))
    ak = setup.ak8963(source=sensor.field)
    sensor.asa_factor = np.array([(a + 128) / 256 for a in ak.asa])
    return setup, setup.model(source=sensor.sample, aux_devices={A.I2C_ADDRESS: ak})


# The catalogue's faults the twin runs (SPI-wired, mid-run, injected into the sensor models): the
# controller stops the motors on the first group and rides through the second
# (``tests/sim/test_balance_plant.py``)
TWIN_FAULTS_STOP = ("cipo_stuck_high", "cipo_stuck_low", "int_stuck_low", "int_stuck_high",
                    "mpu_reset")
TWIN_FAULTS_RIDE = ("ak8963_lost", "ak8963_reset", "mag_overflow", "aux_stall", "rate_change",
                    "data_bit_flip", "spurious_int")
TWIN_FAULTS = TWIN_FAULTS_STOP + TWIN_FAULTS_RIDE
_NOT_IN_TWIN = ("the twin is SPI-wired and arms after bring-up (no I2C or power-up fault), "
                "and runs no host writer or stalled consumer (host_garbage, sensor_overrun)")


def twin_trace(wave, core, clk_freq, wiring):
    """The chip loop's ``RunTrace`` for ``wave`` (a ``Waveform`` whose time bounds count from
    the arming, ``trace_window_at_arming``): the core's groups and the controller's."""
    from ..bench.waveforms import RunTrace
    from .frontend import status_fields
    trace = RunTrace(wave, clk_freq, "core", wiring, status_fields(core.status))
    trace.window.place(None, None)                      # until armed: nothing traced
    trace.groups.append(("controller", [("dut.arm", 1, "arm"), ("dut.pwm", 4, "pwm"),
                                        ("dut.balance.armed", 1, "armed"),
                                        ("dut.balance.duty", 11, "duty")]))
    return trace


def trace_window_at_arming(trace, armed_cycle, clk_freq):
    """The window, ``trace.wave``'s bounds counted from ``armed_cycle``: from the arming (or
    ``start``) for ``DEFAULT_TRACE_S`` (or to ``stop``): a whole 10 s run would be gigabytes."""
    wave = trace.wave
    start_s = wave.start[1] if wave.start else 0.0
    stop_s = wave.stop[1] if wave.stop else start_s + DEFAULT_TRACE_S
    trace.window.place(armed_cycle + round(start_s * clk_freq),
                       armed_cycle + round(stop_s * clk_freq))


def run_chip_loop(plant, seconds, *, pushes, gains, on_sample, sign=1, seed=1,
                  compiled=True, progress=None, fault=None, fault_at_s=1.0, vcd=None):
    """Runs the loop; ``on_sample(t, duty, pitch_rad)`` is called once a sample period (1 ms)
    with the duty applied over it (the mean of its plant steps: a PWM period, 1,024 cycles,
    is longer than a step) and the gateware's last pitch; it returns False to stop (the plant
    fell). ``fault``: a name of the fault catalogue (``sim/scenarios/faults.py``) switched on
    ``fault_at_s`` after arming, for the catalogue's duration (``disarmed_after_ms``: from
    the fault to the PWM pins low for the rest of the run; None with ``motors_ran_on``, pins
    high in the run's last 50 ms: a fault the controller rides through, the magnetometer's).
    ``vcd``: a ``Waveform`` (time bounds from the arming; ``trace_window_at_arming``): the
    compiled design traces it (a build of its own), a GTKWave save file beside it.
    Returns the dict of what the run saw (cycles, when it was armed, the simulator)."""
    from ...hdl.board.top import AHRSCore
    setup, model = plant_models(plant, seed)
    held_tilt = plant.psi
    injector = None
    if fault is not None:
        from .faults import FAULTS, FaultInjector
        if fault not in FAULTS:
            raise ValueError(f"no fault {fault!r} in the catalogue")
        if fault not in TWIN_FAULTS:
            raise ValueError(f"the twin does not run the fault {fault!r}: {_NOT_IN_TWIN}; "
                             f"it runs {', '.join(TWIN_FAULTS)}")
        # armed after the settling; the fault that many samples later (``at`` counts the
        # samples the design read: set when the loop starts), for the catalogue's duration (a
        # pulse stays a pulse, a line freed later is freed)
        injector = FaultInjector(FAULTS[fault], at=1 << 40, duration=FAULTS[fault].duration,
                                 period_s=1 / setup.config.output_data_rate, mpu=model)
    core_kwargs = dict(clk_freq=setup.clk_freq, config=setup.config,
                       timing=setup.driver_timing(), baud=setup.clk_freq / 4,
                       controller="balance", attitude_port=True,
                       controller_regs=controller_registers(gains, sign))
    core = AHRSCore(**core_kwargs)
    harness = CosimHarness(core, spi=core.imu, int_pin=core.imu_int)
    inputs = {"uart_rx": core.uart_rx, "arm": core.arm, "attitude_ready": core.attitude.ready}
    outputs = {"pwm": core.pwm, "attitude_valid": core.attitude.valid,
               "attitude_payload": core.attitude.payload, "status": core.status}
    trace = None
    if vcd is not None:
        if any(bound and bound[0] != "s" for bound in (vcd.start, vcd.stop)):
            raise ValueError("the twin's waveform window is in time from the arming (10ms, "
                             "0.5s), not in samples")
        if not compiled:
            raise ValueError("the twin's waveform is traced by the compiled design")
        trace = twin_trace(vcd, core, setup.clk_freq, setup.config.wiring)
    bench = open_bench(harness, inputs, outputs, setup.clk_freq, compiled=compiled,
                       name="twin", key=core_key("twin", **core_kwargs),
                       models=PinModels(setup.clk_freq, mpu=model, injector=injector),
                       trace=trace)
    seen = {"armed_at_cycle": None, "simulator": "compiled" if bench.compiled else "python",
            "motor_b_mismatch_steps": 0}
    feed = SampleFeed(round(setup.clk_freq / 1000 / STEP_CYCLES), on_sample, progress,
                      seconds)
    meter = []
    dt = STEP_CYCLES / setup.clk_freq

    async def scenario(bench):
        bench.set("uart_rx", 1)
        bench.set("arm", 0)
        bench.set("attitude_ready", 1)
        # on the stand: results flowing, the filter settled
        while not bench.get("attitude_valid"):
            await bench.changed("attitude_valid", until=bench.cycle + 100_000)
            if bench.cycle > 40_000_000:
                raise RuntimeError("the core never gave a result (bring-up failed)")
        await bench.tick(round(SETTLE_S * setup.clk_freq))
        plant.psi = held_tilt
        bench.set("arm", 1)
        seen["armed_at_cycle"] = bench.cycle
        if trace is not None:
            trace_window_at_arming(trace, bench.cycle, setup.clk_freq)
        if injector is not None:
            injector.at = len(model.sample_reads) + round(fault_at_s * 1000)
        meter.append(PwmMeter(bench))

        def pitch():
            return sign * bench.get("attitude_payload")["angles"][1] * 2 * math.pi / 2 ** 32
        for k in range(round(seconds / dt)):
            t = k * dt
            high = [0, 0, 0, 0]
            await meter[0].until(bench, bench.cycle + STEP_CYCLES, high)
            if high[:2] != high[2:]:
                seen["motor_b_mismatch_steps"] += 1
            duty = (high[0] - high[1]) / STEP_CYCLES
            plant.step(dt, duty, sum(p.force(t) for p in pushes))
            if not feed.step(k, t, duty, pitch):
                break

    bench.run(scenario, trace=trace)
    seen["cycles"] = bench.cycle
    if trace is not None:
        trace.finish(model, None, bench.cycle, len(model.sample_reads))
        seen["vcd"] = vcd.path
    if injector is not None:
        seen["fault"] = fault
        seen["fault_injected"] = injector.injected_at is not None
        if injector.injected_at is not None:
            at_cycle = injector.injected_at * setup.clk_freq
            last_on = (meter[0].last_on if meter else None) or 0
            # pins high in the run's last MOTORS_RUNNING_S: the motors ran on (a fault the
            # controller rides through), not disarmed
            running = bench.cycle - last_on < MOTORS_RUNNING_S * setup.clk_freq
            seen["motors_ran_on"] = running
            seen["disarmed_after_ms"] = None if running else \
                round((max(at_cycle, last_on) - at_cycle) / setup.clk_freq * 1e3, 3)
    return seen
