"""The balance controller's digital twin (issue #57): the two-wheeled plant
(``sim/models/balance_plant.py``) in a closed loop with a controller, pushed, and summarised.

Loops (``run_twin``'s ``loop``):

- ``off``: no controller (the duty stays 0): the negative control, the plant is unstable.
- ``model``: the controller's fixed-point model (``reference/balance_control.BalanceFixed``),
  one step per 1 kHz sample, on the plant's own tilt and rate quantised as the gateware sees
  them (the tilt in BAM32, the rate in gyro counts at 16.4 LSB/°/s): the law and its numbers,
  with a perfect attitude; the duty applied 40 µs after the sample (the core's data-ready to
  attitude latency, ``report``'s ``latency_us``, rounded up to the plant's step).
- ``float``: the same law in floating point (``BalanceFloat``).
- ``chip``: the gateware, the whole core with the balance controller co-simulated (compiled),
  its sensor models reading the plant, its PWM pins driving it (``twin_chip``).
- ``host``: the same law on a PC reading the co-simulated board's frames through its UART and
  writing the PWM block's registers back, a stated USB latency late (``twin_host``).
"""

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..models.balance_plant import BalancePlant, PlantParams
from ...reference.balance_control import (DUTY_FULL, E_PER_RAD, BalanceFixed,
                                          BalanceFixedConfig, BalanceFloat, BalanceGains)


__all__ = ["Push", "TwinTrace", "run_twin", "parse_push", "LOOPS"]

LOOPS = ("off", "model", "float", "chip", "host")
PUSH_SECONDS = 0.1
GYRO_LSB_PER_DPS = 16.4             # the default build's ±2000 °/s
SAMPLE_HZ = 1000.0
LATENCY_S = 40e-6
# a push is recovered from when the tilt is back within this, within RECOVER_S of its end
RECOVERED_DEG, RECOVER_S = 2.0, 1.5


@dataclass(frozen=True)
class Push:
    """A horizontal force ``newtons`` on the body's centre of mass for 100 ms from ``at_s``."""
    newtons: float
    at_s: float

    def force(self, t):
        return self.newtons if self.at_s <= t < self.at_s + PUSH_SECONDS else 0.0


def parse_push(text):
    """``F@T`` (newtons at seconds) as a ``Push``; a clear error otherwise."""
    try:
        force, at = text.split("@")
        return Push(float(force), float(at))
    except ValueError:
        raise ValueError(f"--push {text!r}: expected F@T, a force in newtons at a time in "
                         f"seconds (e.g. 2@3)") from None


@dataclass
class TwinTrace:
    """Per sample: time, the plant's tilt (°), the controller's tilt (°: what it saw), duty
    (−1 .. 1), push (N)."""
    t: list = field(default_factory=list)
    tilt_deg: list = field(default_factory=list)
    seen_deg: list = field(default_factory=list)
    duty: list = field(default_factory=list)
    push: list = field(default_factory=list)


class _Watch:
    """What a run saw: the worst tilt, when it fell (passed the cut-off), when it was back
    upright after each push, the trace, the gateware's tilt against the plant's."""

    def __init__(self, pushes, cutoff_deg, trace):
        self.pushes, self.trace = pushes, trace
        self.cutoff = math.radians(cutoff_deg)
        self.fell_at, self.worst, self.back_at = None, 0.0, {}
        self.errors = []

    def see(self, t, tilt):
        """The plant's tilt at ``t``; False once it has fallen."""
        self.worst = max(self.worst, abs(tilt))
        for p in self.pushes:
            if p not in self.back_at and t >= p.at_s + PUSH_SECONDS and \
                    abs(tilt) < math.radians(RECOVERED_DEG):
                self.back_at[p] = t
        if abs(tilt) > self.cutoff and self.fell_at is None:
            self.fell_at = t
        return self.fell_at is None

    def sample(self, t, tilt, seen, duty, push, estimate=False):
        if estimate:
            self.errors.append(seen - tilt)
        if self.trace is not None:
            self.trace.t.append(t)
            self.trace.tilt_deg.append(math.degrees(tilt))
            self.trace.seen_deg.append(math.degrees(seen))
            self.trace.duty.append(duty)
            self.trace.push.append(push)

    def summary(self, loop, plant, start):
        recovered = sum(1 for p in self.pushes if p in self.back_at and
                        self.back_at[p] <= p.at_s + PUSH_SECONDS + RECOVER_S and
                        (self.fell_at is None or self.fell_at > self.back_at[p]))
        out = {"loop": loop, "upright": self.fell_at is None,
               "max_abs_pitch_deg": round(math.degrees(self.worst), 3),
               "fell_at_s": None if self.fell_at is None else round(self.fell_at, 4),
               "pushes_recovered": recovered, "pushes": len(self.pushes),
               "travel_m": round(plant.position, 3)}
        if self.errors:
            e = np.asarray(self.errors)
            out["estimate_rms_deg"] = round(math.degrees(float(np.sqrt(np.mean(e * e)))), 3)
        out["wall_s"] = round(time.perf_counter() - start, 2)
        return out


def _controller(loop, gains):
    if loop == "off":
        return lambda tilt, rate: (0.0, tilt)
    if loop == "float":
        law = BalanceFloat(gains, dt=1 / SAMPLE_HZ)
        return lambda tilt, rate: (law.step(tilt, rate), tilt)
    config = BalanceFixedConfig.from_gains(gains, gyro_lsb_per_dps=GYRO_LSB_PER_DPS,
                                           sample_hz=SAMPLE_HZ)
    law = BalanceFixed(config)
    law.arm()

    def step(tilt, rate):
        angle = round(tilt * E_PER_RAD) << 16               # BAM32 of the tilt
        gyro = max(-32768, min(32767, round(math.degrees(rate) * GYRO_LSB_PER_DPS)))
        return law.step(angle, gyro, 0) / DUTY_FULL, (angle >> 16) / E_PER_RAD
    return step


def run_twin(seconds, *, loop="model", pushes=(), gains=BalanceGains(), params=PlantParams(),
             tilt_deg=1.0, dt=1e-4, trace=None, progress=None, compiled=True, sign=1,
             host_latency_ms=1.0, fault=None, fault_at_s=1.0, vcd=None):
    """The plant from ``tilt_deg`` for ``seconds`` under ``loop``, ``pushes`` (``Push``)
    applied; returns the summary (a dict: upright, max_abs_pitch_deg, fell_at_s,
    pushes_recovered, pushes, loop, travel_m, wall_s; the chip loop's
    estimate_rms_deg, the gateware's pitch against the plant's, and its simulator and cycles).
    It falls when its tilt passes the controller's cut-off (``gains.cutoff_deg``): the run
    stops there. ``trace``: a ``TwinTrace`` filled per sample; ``progress(fraction)``: called
    now and then. ``compiled``, ``sign``: the chip loop's (``twin_chip.run_chip_loop``);
    ``host_latency_ms``: the host loop's (``twin_host.run_host_loop``); ``fault``,
    ``fault_at_s``: the chip loop's, a fault of the catalogue injected with the controller
    armed; ``vcd``: the chip loop's waveform (a ``Waveform``: ``twin_chip.run_chip_loop``)."""
    if vcd is not None and loop != "chip":
        raise ValueError("a waveform is the gateware's: --loop chip")
    if fault is not None and loop != "chip":
        raise ValueError("a fault is injected into the co-simulated board: --loop chip")
    if loop not in LOOPS:
        raise ValueError(f"--loop {loop}: one of {', '.join(LOOPS)}")
    start = time.perf_counter()
    plant = BalancePlant(params, tilt=math.radians(tilt_deg))
    watch = _Watch(pushes, gains.cutoff_deg, trace)
    if loop in ("chip", "host"):
        def on_sample(t, duty, pitch):
            watch.sample(t, plant.psi, pitch, duty, sum(p.force(t) for p in pushes),
                         estimate=True)
            return watch.see(t, plant.psi)
        if loop == "chip":
            from .twin_chip import run_chip_loop
            seen = run_chip_loop(plant, seconds, pushes=pushes, gains=gains,
                                 on_sample=on_sample, compiled=compiled, sign=sign,
                                 progress=progress, fault=fault, fault_at_s=fault_at_s,
                                 vcd=vcd)
        else:
            from .twin_host import run_host_loop
            seen = run_host_loop(plant, seconds, pushes=pushes, gains=gains,
                                 on_sample=on_sample, latency_ms=host_latency_ms,
                                 compiled=compiled, progress=progress)
        return {**watch.summary(loop, plant, start), **seen}
    controller = _controller(loop, gains)
    steps_per_sample = round(1 / (SAMPLE_HZ * dt))
    delay = math.ceil(LATENCY_S / dt - 1e-9)
    duty = pending = seen = 0.0
    for k in range(round(seconds / dt)):
        t = k * dt
        if k % steps_per_sample == 0:
            pending, seen = controller(plant.psi, plant.dpsi)
            watch.sample(t, plant.psi, seen, duty, sum(p.force(t) for p in pushes))
            if progress and k % (steps_per_sample * 1000) == 0:
                progress(t / seconds)
        if k % steps_per_sample == delay:
            duty = pending
        plant.step(dt, duty, sum(p.force(t) for p in pushes))
        if not watch.see(t + dt, plant.psi):
            break
    return watch.summary(loop, plant, start)
