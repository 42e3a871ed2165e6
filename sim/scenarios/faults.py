"""Fault injection: the catalogue of ``hdl/FAULTS.md``, switched on in the models mid-run.

A ``Fault`` says what goes wrong (``inject``) and, for a fault that can go away, how it ends
(``remove``), in terms of the simulated parts: the MPU9250 model, the AK8963 model, the I2C bus
model and two pin overrides (CIPO and INT) that ``sim.bench.harness.attach_models`` applies. A
``FaultInjector`` switches a fault on once the design has read ``at`` samples (``at`` = 0: at
power-up), and off ``duration`` sample periods later (by default the fault's; a magnetometer
fault's at least twice the driver's magnetometer time-out, whatever the rate).

``run_fault`` co-simulates the sensor front end (both wirings) with one fault and measures what
the catalogue promises:

- ``detected_after_samples``: sample periods from the fault to the first of its flags;
- ``flags``: every status and sample flag that went to 1 after the fault (``restarts`` when
  bring-up was restarted);
- ``recovered``: streaming again once the fault was removed (with the magnetometer up and
  new fields coming where it has one), or, for a fault that stays, streaming on what is left;
- ``stale_valid_samples``: samples passed on as valid that carried stale or garbage data: an
  accel/gyro reading the model did not make or had delivered before, or a field marked
  ``mag_valid`` that the AK8963 did not measure or had delivered before. Must be 0.

``python -m mpu9250_ahrs simulate --fault NAME [--fault-at N]`` prints this as JSON.
"""

import bisect
from dataclasses import dataclass, field
from typing import Callable, Optional, Tuple

from ...hdl.contract import ak8963_regs as A
from ...hdl.contract import mpu9250_regs as R
from ...hdl.sensor.sample_reader import GYRO_JUMP_DPS, gyro_jump_limit


__all__ = ["Fault", "FAULTS", "FaultInjector", "run_fault", "fault_names", "ERROR_FLAGS",
           "catalogue_setup", "catalogue_table"]


# DriverStatus bits that say something is wrong (``restarts`` is reported when it goes up)
ERROR_FLAGS = ("whoami_error", "no_response", "int_timeout", "mag_absent", "mag_wia_error",
               "mag_stale", "bad_burst", "bus_timeout", "bus_stuck", "bus_arbitration",
               "rate_error", "self_test_fail")
SAMPLE_FLAGS = ("overrun", "mag_overflow", "mag_dor", "resumed")


@dataclass
class FaultInjector:
    """Switches ``fault`` on at the ``at``-th sample the design reads (0: at time 0; a fault
    with ``before_next``, that much before the next sample) and off ``duration`` sample
    periods later (None: never). ``cipo`` / ``int_level`` (None or a level)
    override the pins; ``mpu_absent`` hides the MPU9250 (SPI: it sees no pin changes; I2C: it
    does not acknowledge)."""
    fault: "Fault"
    at: int
    duration: Optional[float]
    period_s: float
    mpu: object = None
    bus: object = None
    cipo: Optional[int] = None
    int_level: Optional[int] = None
    mpu_absent: bool = False
    mpu_address: int = R.MPU9250_I2C_ADDRESS
    injected_at: Optional[float] = None
    removed_at: Optional[float] = None
    saved: dict = field(default_factory=dict)
    start_at: Optional[float] = None    # ``Fault.before_next``: when it starts

    @property
    def ak(self):
        return self.saved.get("ak") or (self.mpu.aux_devices.get(A.I2C_ADDRESS)
                                        if self.mpu else None)

    @property
    def next_event(self):
        if self.injected_at is None and self.at == 0:
            return 0.0
        if self.injected_at is None and self.start_at is not None:
            return self.start_at
        if self.injected_at is not None and self.removed_at is None and \
                self.duration is not None:
            return self.injected_at + self.duration * self.period_s
        return None

    def _between_transfers(self):
        if self.bus is not None:
            return self.bus._state == "idle"
        return not self.mpu.selected

    def advance(self, t):
        if self.injected_at is None:
            # mid-run faults start between two transfers: a line that breaks during a burst
            # can pass one partly garbage sample (hdl/FAULTS.md, "Limits")
            due = self.at == 0 or (len(self.mpu.sample_reads) >= self.at and
                                   self._between_transfers())
            if due and self.fault.before_next is not None:
                if self.start_at is None:
                    # (this wake may be the next sample's conversion, which the model has not
                    # run up to yet: it counts as made)
                    upcoming = self.mpu.next_sample_after(t)
                    self.start_at = t if upcoming is None else \
                        upcoming - self.fault.before_next * self.period_s
                due = t + 1e-12 >= self.start_at
            if due:
                self.injected_at = t
                self.saved["ak"] = self.mpu.aux_devices.get(A.I2C_ADDRESS)
                self.fault.inject(self, t)
        elif self.removed_at is None and self.duration is not None and \
                t + 1e-12 >= self.injected_at + self.duration * self.period_s:
            self.removed_at = t
            if self.fault.remove is not None:
                self.fault.remove(self, t)


@dataclass(frozen=True)
class Fault:
    """One catalogue entry. ``wirings``: where it applies. ``at_power_up``: injected at time 0
    (else once ``at`` samples were read). ``duration``: sample periods until ``remove`` (None:
    a one-off event or a fault that stays). ``flags``: the flags the design must set (the
    first of them times the detection). ``recovers``: what ``recovered`` needs: "stream"
    (samples again), "mag" (and new fields) or "remains" (streaming on what is left)."""
    name: str
    description: str
    inject: Callable
    remove: Optional[Callable] = None
    wirings: Tuple[str, ...] = ("spi", "i2c")
    at_power_up: bool = False
    duration: Optional[float] = 60
    flags: Tuple[str, ...] = ()
    recovers: str = "stream"
    stall: bool = False             # the consumer stops taking samples (sensor overrun)
    self_test: bool = False         # needs the self-tests at bring-up (``catalogue_setup``)
    # a glitch between two samples starts this many sample periods before the next one is
    # made (with the bus idle), rather than as soon as the fault may start: that moment can
    # be a data-ready edge (the pulse then hides in it), or mid-read (the reads of a slow
    # set-up fill most of a period). None: as soon as it may start
    before_next: Optional[float] = None
    # the fault makes the part sample faster than configured: none is left at 8 kHz
    faster: bool = False
    # the AK8963's fault (besides those whose recovery is "mag"): needs the magnetometer
    mag: bool = False
    # found by the reader's gyro jump check, which is off at ±500 °/s and less
    # (``gyro_jump_limit``)
    gyro_jump: bool = False
    # the part's SDO timing (``MPU9250Timing`` fields, as pairs) and the clock (the read
    # levelling's trained rate is faster than the safe one only near the board's 48 MHz):
    # None, the catalogue's
    part: Optional[Tuple[Tuple[str, float], ...]] = None
    clk_freq: Optional[float] = None

    @property
    def needs_magnetometer(self):
        return self.mag or self.recovers == "mag"

    @property
    def removable(self):
        """A fault that lasts a while and then goes, whose length a test may choose: not a
        one-off event, a stall, or a glitch shorter than a period (those keep their own)."""
        return not (self.stall or self.duration is None or self.duration < 1)


def _set(attr, value):
    def apply(inj, t):
        setattr(inj, attr, value)
    return apply


def _ak_gone(inj, t):
    inj.mpu.aux_devices.pop(A.I2C_ADDRESS, None)


def _ak_back(inj, t):
    inj.mpu.aux_devices[A.I2C_ADDRESS] = inj.saved["ak"]


def _ak_reset(inj, t):
    ak = inj.ak
    ak.advance(t)
    ak.write_reg(A.CNTL2, A.CNTL2_SRST)         # as a supply glitch leaves it: power-down


def _wia(value):
    def apply(inj, t):
        ak = inj.ak
        ak.wia = value
        ak.regs[A.WIA] = value
    return apply


def _who_am_i(value):
    def apply(inj, t):
        inj.mpu.who_am_i = value
        inj.mpu.regs[R.WHO_AM_I] = value
    return apply


def _overflow_on(inj, t):
    ak = inj.ak
    inj.saved["source"] = ak.source
    ak.source = lambda index, t: (30000, 20000, 10000)          # 9000 µT: HOFL


def _overflow_off(inj, t):
    inj.ak.source = inj.saved["source"]


def _mpu_reset(inj, t):
    mpu = inj.mpu
    mpu.advance(t)
    mpu.now = t
    mpu.write_reg(R.PWR_MGMT_1, R.PWR_MGMT_1_H_RESET)   # a brown-out: registers to reset values


def _bus_hold(inj, t):
    inj.bus.hold_sda(1 << 30)


def _bus_release(inj, t):
    inj.bus.release_sda()


def _stretch(inj, t):
    inj.bus.stretch_s = inj.saved["stretch_s"]


def _no_stretch(inj, t):
    inj.bus.stretch_s = 0.0


def _nack(inj, t):
    inj.bus.nack_next, inj.bus.nack_address = 1, inj.mpu_address


def _nothing(inj, t):
    pass


def _rate_glitch(inj, t):
    # SMPLRT_DIV loses its value (a glitch, a brown-out of that register): 0, the fastest rate
    # the DLPF setting allows (200 Hz -> 1 kHz); already 0 (1 kHz), CONFIG's DLPF_CFG loses
    # its instead (0: the 8 kHz internal rate). The part reschedules as for a write.
    mpu = inj.mpu
    mpu.advance(t)
    mpu.now = t
    if mpu.regs[R.SMPLRT_DIV]:
        mpu.regs[R.SMPLRT_DIV] = 0
    else:
        mpu.regs[R.CONFIG] &= ~0x07
    mpu._reschedule(t)


def _gyro_bit_flip(inj, t):
    # the data line inverts the top bit of gyro x in the next burst (a glitch, cross-talk)
    inj.mpu.line_flips[R.GYRO_XOUT_H] = 0x80


def _int_high(inj, t):
    # a spurious pulse on INT between two samples (cross-talk, a glitch): the pin override
    # raises INT now; ``remove`` lets it go a fraction of a period later
    inj.int_level = 1


def _int_free(inj, t):
    inj.int_level = None


def _aux_stall(inj, t):
    inj.mpu.aux_stalled = True


def _aux_free(inj, t):
    inj.mpu.aux_stalled = False


# the drift of ``sdo_drift``: 60 ns over 20 sample periods (the eye moves three cycles of the
# 48 MHz clock, most of a 12 MHz bit), then it stays there
SDO_DRIFT_S, SDO_DRIFT_PERIODS = 60e-9, 20


def _sdo_ramp(inj, t):
    inj.mpu.ramp_sdo_drift(t, SDO_DRIFT_S / (SDO_DRIFT_PERIODS * inj.period_s))


def _sdo_hold(inj, t):
    inj.mpu.ramp_sdo_drift(t, 0.0)


def _gyro_y_dead(inj, t):
    # a damaged gyro axis: its self-test makes no response (the part still reads its rate)
    inj.mpu.self_test_gain[4] = 0.0


def _mag_z_dead(inj, t):
    # the AK8963's Z coil: its self-test field reads 0
    inj.ak.self_test_field[2] = 0


FAULTS = {f.name: f for f in [
    Fault("mpu_absent", "no MPU9250 at power-up (SPI: CIPO floats high, no INT; I2C: no ACK); "
          "plugged in later", _set("mpu_absent", True), _set("mpu_absent", False),
          at_power_up=True, flags=("no_response",)),
    Fault("who_am_i_wrong", "WHO_AM_I reads 0x68 (a wrong part) at power-up; right later",
          _who_am_i(0x68), _who_am_i(R.WHO_AM_I_MPU9250), at_power_up=True,
          flags=("whoami_error",)),
    Fault("cipo_stuck_high_bringup", "CIPO stuck high from power-up; freed later",
          _set("cipo", 1), _set("cipo", None), wirings=("spi",), at_power_up=True,
          flags=("no_response",)),
    Fault("cipo_stuck_low_bringup", "CIPO stuck low from power-up; freed later",
          _set("cipo", 0), _set("cipo", None), wirings=("spi",), at_power_up=True,
          flags=("no_response",)),
    Fault("ak8963_absent", "no AK8963 at power-up; it appears later", _ak_gone, _ak_back,
          at_power_up=True, flags=("mag_absent",), recovers="mag"),
    Fault("wia_wrong", "the AK8963's WIA reads 0x00 at power-up; right later", _wia(0x00),
          _wia(A.WIA_VALUE), at_power_up=True, flags=("mag_wia_error",), recovers="mag"),
    Fault("ak8963_lost", "the AK8963 stops answering mid-run (NACK); back later", _ak_gone,
          _ak_back, flags=("mag_stale", "mag_absent"), recovers="mag"),
    Fault("ak8963_reset", "the AK8963 resets mid-run (power-down, nothing measured)",
          _ak_reset, duration=None, flags=("mag_stale",), recovers="mag"),
    Fault("mag_overflow", "a field beyond the AK8963's range (HOFL) for a while",
          _overflow_on, _overflow_off, duration=20, flags=("mag_overflow",), recovers="mag"),
    Fault("aux_stall", "the MPU9250's auxiliary I2C master stalls mid-run (no transfer runs, "
          "an enabled SLV4 transfer waits): past the SLV4 poll's time-out of a set-up; "
          "runs again later", _aux_stall, _aux_free, wirings=("spi",),
          flags=("mag_stale",), recovers="mag"),
    Fault("cipo_stuck_high", "CIPO stuck high mid-run while INT keeps coming; freed later",
          _set("cipo", 1), _set("cipo", None), wirings=("spi",), flags=("bad_burst",)),
    Fault("cipo_stuck_low", "CIPO stuck low mid-run while INT keeps coming; freed later",
          _set("cipo", 0), _set("cipo", None), wirings=("spi",), flags=("bad_burst",)),
    Fault("int_stuck_low", "the INT line stuck low mid-run (no data-ready); freed later",
          _set("int_level", 0), _set("int_level", None), flags=("int_timeout",)),
    Fault("int_stuck_high", "the INT line stuck high mid-run (no edges); freed later",
          _set("int_level", 1), _set("int_level", None), flags=("int_timeout",)),
    Fault("mpu_reset", "the MPU9250 resets mid-run (brown-out: registers to reset values)",
          _mpu_reset, duration=None, flags=("int_timeout",)),
    Fault("i2c_bus_stuck", "a device holds SDA low mid-run; let go later", _bus_hold,
          _bus_release, wirings=("i2c",), flags=("bus_stuck",)),
    Fault("clock_stretch_timeout", "a device stretches SCL past the controller's time-out "
          "mid-run; stops later", _stretch, _no_stretch, wirings=("i2c",),
          flags=("bus_timeout",)),
    Fault("nack_mid_transfer", "the MPU9250 NACKs a register byte mid-transfer, once",
          _nack, duration=None, wirings=("i2c",), flags=("bad_burst",)),
    Fault("host_garbage", "writes to the engine's constants and filter state through its "
          "cfg port (the host port)", _nothing, duration=None, flags=("cfg_refused",),
          wirings=("spi",)),
    Fault("sensor_overrun", "the consumer stops taking samples for a while (samples made and "
          "read faster than taken)", _nothing, _nothing, duration=3,
          flags=("overrun",), stall=True),
    Fault("rate_change", "SMPLRT_DIV (at 1 kHz: CONFIG's DLPF_CFG) loses its value under the "
          "driver (a register glitch): the part samples 5 or 8 times faster", _rate_glitch,
          duration=None, flags=("rate_error",), faster=True),
    Fault("data_bit_flip", "the data line flips the top bit of one gyro word in one burst",
          _gyro_bit_flip, duration=None, flags=("bad_burst",), recovers="remains",
          gyro_jump=True),
    Fault("spurious_int", "one spurious INT pulse between two samples (no new sample)",
          _int_high, _int_free, duration=0.02, flags=("bad_burst",), recovers="remains",
          before_next=0.1),
    Fault("sdo_drift", "the SDO delay of a typical part (15 ns, 7 ns board) drifts 60 ns later "
          "over 20 sample periods, then stays (temperature, supply): the trained eye moves "
          "three cycles", _sdo_ramp, _sdo_hold, wirings=("spi",), duration=SDO_DRIFT_PERIODS,
          flags=("fallback",), recovers="remains",
          part=(("sdo_delay_s", 15e-9), ("board_delay_s", 7e-9), ("sdo_jitter_s", 2e-9)),
          clk_freq=48e6),
    Fault("sdo_slow", "a slow, noisy part: SDO 65 ± 35 ns (the datasheet's 100 ns at worst), "
          "14 ns board: no eye at the trained rate wide enough for the margin", _nothing,
          wirings=("spi",), duration=None, at_power_up=True, flags=("untrained",),
          recovers="remains",
          part=(("sdo_delay_s", 65e-9), ("board_delay_s", 14e-9), ("sdo_jitter_s", 35e-9)),
          clk_freq=48e6),
    Fault("self_test_gyro", "the gyro's Y axis makes no self-test response (a damaged axis)",
          _gyro_y_dead, duration=None, at_power_up=True, flags=("self_test_fail",),
          recovers="remains", self_test=True),
    Fault("self_test_mag", "the AK8963's Z axis reads no self-test field (a damaged axis)",
          _mag_z_dead, duration=None, at_power_up=True, flags=("self_test_fail",),
          recovers="remains", self_test=True, mag=True),
]}


def fault_names(wiring=None):
    return [n for n, f in FAULTS.items() if wiring is None or wiring in f.wirings]


def _field_key(mag):
    return tuple(int(v) for v in mag)


def host_garbage_writes():
    """(address, value) writes no host may make: the constants of the register map and some
    filter state. ``HOST_WRITABLE`` refuses each."""
    from ...hdl.engine.register_map import CONFIG_REGS, REGS
    return [(CONFIG_REGS["ZERO"], 12345), (CONFIG_REGS["INV_GAIN"], 0),
            (CONFIG_REGS["SHL8"], 1), (REGS["THETA0"], 1 << 29), (REGS["P0_00"], -1),
            (REGS["QOUT0"], 0), (0xFD, 7)]


def run_host_garbage(setup, *, n_results=4, baud=None, compiled=None):
    """The whole core twice, with and without ``host_garbage_writes`` at the start: every
    result must be the same and every write counted in ``cfg_refused`` (port and frames).
    ``baud``: the UART's (default: a quarter of the clock, so that frames come quickly)."""
    from .core import run_core
    from ..bench.bench import simulator_name
    bad = host_garbage_writes()
    baud = baud or round(setup.clk_freq / 4)   # an integer: the build's cache key has it
    clean = run_core(setup, n_results=n_results, n_frames=1, baud=baud, compiled=compiled)
    dirty = run_core(setup, n_results=n_results, n_frames=1, writes=bad, baud=baud,
                     compiled=compiled)
    changed = sum(a != b for a, b in zip(clean.results, dirty.results))
    refused = dirty.frames[-1]["cfg_refused"] if dirty.frames else None
    return {"fault": "host_garbage", "wiring": setup.config.wiring,
            "description": FAULTS["host_garbage"].description,
            "injected_at_sample": 0, "removed": False,
            "detected_after_samples": 0.0 if refused == len(bad) else None,
            "flags": ["cfg_refused"] if refused else [],
            "cfg_refused": refused, "writes": len(bad),
            "recovered": len(dirty.results) >= n_results,
            "stale_valid_samples": changed, "status": dirty.status,
            "cycles": dirty.cycles, "wall_s": round(clean.wall_s + dirty.wall_s, 2),
            "simulator": simulator_name(dirty.compiled),
            "violations": [str(v) for v in dirty.model.violations][:5]}


def run_fault(name, setup=None, *, at=20, duration=None, after=None, max_cycles=None,
              vcd=None, keep_result=False, progress=None, compiled=None):
    """Co-simulate the front end of ``setup`` (``SimSetup``) with fault ``name``; return the
    summary dict (module docstring). ``at``: samples read before a mid-run fault; ``duration``:
    sample periods until it is removed (default: the fault's); ``after``: samples to see once
    it is removed (default 12). ``keep_result``: return (summary, the ``CosimResult``)."""
    from .setup import SimSetup
    from .frontend import run_frontend
    from ..bench.bench import simulator_name
    setup = setup or SimSetup()
    if name not in FAULTS:
        raise ValueError(f"unknown fault {name!r}; simulate --fault list names them")
    fault = FAULTS[name]
    wiring = setup.config.wiring
    if wiring not in fault.wirings:
        raise ValueError(f"fault {name} applies to {' and '.join(fault.wirings)} wiring, "
                         f"not {wiring}")
    if fault.self_test and not setup.config.self_test:
        raise ValueError(f"fault {name} is found by the self-test at bring-up, which this "
                         f"set-up leaves out")
    if fault.needs_magnetometer and not setup.config.magnetometer:
        raise ValueError(f"fault {name} needs the magnetometer (leave out --no-mag)")
    if fault.gyro_jump and gyro_jump_limit(setup.config.gyro_fs_dps) is None:
        raise ValueError(f"fault {name} is found by the gyro jump check, which is off at "
                         f"±{setup.config.gyro_fs_dps} °/s (a {GYRO_JUMP_DPS} °/s jump is "
                         f"beyond the words' range): choose --gyro-fs 1000 or 2000")
    if name == "host_garbage":
        return run_host_garbage(setup, compiled=compiled)
    if at < 1 and not fault.at_power_up:
        raise ValueError("--fault-at must be at least 1 (samples read before the fault)")
    if fault.faster and setup.config.output_data_rate >= 8000:
        raise ValueError(f"fault {name} makes the part sample faster than configured: at "
                         f"{setup.config.output_data_rate:g} Hz it samples at its fastest "
                         f"already (choose --odr 1000/n)")
    after = 12 if after is None else after
    period = setup.sample_period_s
    clk = setup.clk_freq
    timing = setup.driver_timing()
    mag_limit = timing.mag_timeout_periods(setup.config)
    if duration is None:
        duration = fault.duration
        if fault.recovers == "mag" and not fault.at_power_up and duration is not None:
            # a magnetometer fault lasts twice the driver's magnetometer time-out at least:
            # the catalogue's periods are short beside the AK8963's 10 ms at high rates (60
            # periods at 8 kHz are 7.5 ms: no field was due, nothing to find)
            duration = max(duration, 2 * mag_limit)
    model = setup.model(magnetometer=setup.config.magnetometer, part=dict(fault.part or ()))
    inj = FaultInjector(fault, 0 if fault.at_power_up else at, duration, period, mpu=model,
                        mpu_address=setup.config.i2c_address)
    power_up, reset, _ = timing.cycles(clk, setup.config)
    if fault.at_power_up:
        # three bring-up attempts' worth before the fault goes (a magnetometer fault: one,
        # and its own duration after it), the self-tests included: their waits follow the
        # sample period's scale, so at 8 kHz in real time they are about 170 periods beside
        # the waits' 1.6, and a fault gone before them was found by nothing
        attempts = (power_up + reset + setup.self_test_cycles()) / clk / period
        inj.duration = attempts + duration if fault.recovers == "mag" else 3 * attempts
    if name == "clock_stretch_timeout":
        from ...hdl.sensor.i2c_controller import I2CTiming
        inj.saved["stretch_s"] = 2 * I2CTiming.for_clock(clk).timeout / clk

    def ready(cycle):
        if not fault.stall or inj.injected_at is None:
            return 1
        start = inj.injected_at * clk
        return int(not start <= cycle < start + duration * period * clk)

    def stop(cycle, status, sample_cycles, samples):
        if inj.injected_at is None:
            return False
        end = inj.removed_at if inj.removed_at is not None else (
            inj.injected_at if inj.duration is None else None)
        if end is None:
            return False
        # enough samples after the fault ended, and the magnetometer back where it matters
        first = bisect.bisect_right(sample_cycles, end * clk + 1e-6)
        fresh = samples[first:]
        ok = len(fresh) >= after and status["streaming"]
        if fault.recovers == "mag":
            ok = ok and status["mag_ok"] and any(s["flags"]["mag_valid"] for s in fresh)
        return ok

    if max_cycles is None:
        bring_up = setup.bring_up_budget_cycles()
        span = (at + (duration or 0) + after + 2 * mag_limit + 60) * period * clk
        if fault.at_power_up:
            span += inj.duration * period * clk
        max_cycles = int(2 * bring_up + span + 200_000)
    result = run_frontend(setup, model=model, injector=inj, stop=stop, max_cycles=max_cycles,
                          vcd=vcd, ready=ready if fault.stall else None,
                          until=lambda st: False, progress=progress,
                          compiled=compiled)
    summary = summarise(fault, inj, result, setup, after)
    summary["simulator"] = simulator_name(result.compiled)
    return (summary, result) if keep_result else summary


def summarise(fault, inj, result, setup, after):
    clk, period = setup.clk_freq, setup.sample_period_s
    t0 = inj.injected_at
    summary = {"fault": fault.name, "wiring": setup.config.wiring,
               "description": fault.description,
               "injected_at_sample": None if t0 is None else len(
                   [c for c in result.sample_cycles if c / clk <= t0 + 1e-12]),
               "removed": inj.removed_at is not None}
    if t0 is None:
        summary.update({"detected_after_samples": None, "flags": [], "recovered": False,
                        "stale_valid_samples": None, "error": "the fault was never injected"})
        return summary
    # flags after the fault: status bits rising to 1, restarts going up, sample flags
    first = {}
    prev = None
    for cycle, st in result.status_log:
        if cycle / clk >= t0 - 1e-12:
            for name in ERROR_FLAGS:
                if st[name] and not (prev and prev[name]):
                    first.setdefault(name, cycle)
            if st["restarts"] > (prev["restarts"] if prev else 0):
                first.setdefault("restarts", cycle)
        prev = st
    # the read levelling's status (``ReadLevelStatus``, the driver's ``level``): ``fallback``,
    # its count went up; ``untrained``, a scan ended without a wide enough eye (the status
    # changed to scanned and not trained with no fall back)
    prev = None
    for cycle, level in result.level_log:
        if cycle / clk >= t0 - 1e-12:
            fell = prev is not None and level["fallbacks"] > prev["fallbacks"]
            if fell:
                first.setdefault("fallback", cycle)
            elif level["scanned"] and not level["trained"] and level != prev:
                first.setdefault("untrained", cycle)        # a scan's end without an eye
        prev = level
    for cycle, s in zip(result.sample_cycles, result.samples):
        if cycle / clk < t0:
            continue
        for name in SAMPLE_FLAGS:
            if s["flags"][name] and name not in first:
                first[name] = cycle
    flags = sorted(first)
    wanted = [first[f] for f in fault.flags if f in first]
    detected = None if not wanted else round((min(wanted) / clk - t0) / period, 1)

    # stale or garbage samples passed on as valid
    model = result.model
    ak = inj.saved.get("ak")
    index_of = {}
    for k, s in enumerate(model.samples):
        index_of.setdefault((s.accel, s.temp, s.gyro), []).append(k)
    fields = {}
    if ak is not None:
        for k, (hx, hy, hz, hofl) in enumerate(ak.measurements):
            fields.setdefault((hx, hy, hz), []).append(k)
    stale, last_sample, last_field = 0, -1, -1
    for cycle, s in zip(result.sample_cycles, result.samples):
        key = (tuple(s["accel"]), s["temp"], tuple(s["gyro"]))
        later = [k for k in index_of.get(key, []) if k > last_sample]
        bad = not later
        if later:
            last_sample = later[0]
        if s["flags"]["mag_valid"]:
            newer = [k for k in fields.get(_field_key(s["mag"]), []) if k > last_field]
            if not newer:
                bad = True
            else:
                last_field = newer[0]
        stale += bad and cycle / clk >= t0 - period

    end = inj.removed_at if inj.removed_at is not None else t0
    fresh = [s for c, s in zip(result.sample_cycles, result.samples) if c / clk > end + 1e-12]
    status = result.status or {}
    recovered = bool(status.get("streaming")) and len(fresh) >= after
    if fault.recovers == "mag":
        recovered = recovered and bool(status.get("mag_ok")) and \
            any(s["flags"]["mag_valid"] for s in fresh)
    violations = [str(v) for who in (model, result.bus, *model.aux_devices.values(), ak)
                  if who is not None for v in who.violations]
    counters = [s["counter"] for s in result.samples]
    # the sensitivity the driver holds (SPI: from SLV4 transfers) is the part's fuse ROM's
    # whenever the magnetometer is up: a wrong one is garbage passed on as valid
    asa_right = None
    if ak is not None and status.get("mag_ok"):
        asa_right = list(result.asa) == list(ak.asa)
        recovered = recovered and asa_right
    summary.update({
        "detected_after_samples": detected, "flags": flags, "recovered": recovered,
        "asa_right": asa_right,
        "stale_valid_samples": stale,
        # the sample counter goes on across a restart: it only ever increases
        "counter_increasing": all(b > a for a, b in zip(counters, counters[1:])),
        "samples_after": len(fresh), "status": status, "cycles": result.cycles,
        "wall_s": round(result.wall_s, 2), "violations": sorted(set(violations))[:5]})
    return summary


def catalogue_setup(wiring, *, odr=200, clk_freq=4e6, fault=None, self_test=None):
    """The set-up the fault tests and the catalogue table use: 200 Hz, a 4 MHz clock (the
    front end only: SPI at 2 MHz, I2C at about 300 kHz) and scaled time (SPI: periods × 0.05;
    I2C: × 0.25, whose 1.25 ms still fits its read), so that a fault runs in seconds; the
    AK8963's clock 10 % slow (``SimSetup.ak_clock_error``); the self-tests at bring-up only
    for the faults they are to find (``Fault.self_test``), or as ``self_test`` says.
    ``host_garbage`` runs the whole core, on ``setup.quick_core_setup`` (1 kHz, 12 MHz)
    whatever ``odr`` and ``clk_freq`` say: the core tests' set-up, whose compiled build it
    shares."""
    from ...hdl.sensor.mpu9250_driver import MPU9250Config
    from .setup import SimSetup, quick_core_setup
    if fault == "host_garbage":
        return quick_core_setup()
    config = MPU9250Config.for_odr(odr, wiring=wiring)
    if fault in FAULTS and FAULTS[fault].clk_freq:
        clk_freq = FAULTS[fault].clk_freq
    return SimSetup(clk_freq=clk_freq, config=config,
                    odr_scale=0.05 if wiring == "spi" else 0.25, ak_clock_error=0.1,
                    self_test=bool(fault and FAULTS[fault].self_test) if self_test is None
                    else self_test)


def catalogue_table(wirings=("spi", "i2c"), *, at=3, after=4, duration=8, out=None):
    """Run every fault of the catalogue on ``catalogue_setup`` and print a Markdown table of
    what was measured (``python -m mpu9250_ahrs.sim.scenarios.faults``). Returns the summaries."""
    import sys
    out = out or sys.stdout
    rows = []
    print("| fault | wiring | detected after (sample periods) | flags | recovered | "
          "stale valid samples |", file=out)
    print("|---|---|---|---|---|---|", file=out)
    from tqdm import tqdm
    todo = [(wiring, name) for wiring in wirings for name in fault_names(wiring)]
    # progress on stderr, on a terminal only (the table goes to ``out``)
    shown = tqdm(todo, desc="fault catalogue", unit="fault", file=sys.stderr, leave=False,
                 disable=not sys.stderr.isatty())
    for wiring, name in shown:
        shown.set_postfix_str(f"{name} ({wiring})")
        d = duration if FAULTS[name].removable else None
        r = run_fault(name, catalogue_setup(wiring, fault=name), at=at, after=after,
                      duration=d)
        rows.append(r)
        print(f"| {name} | {wiring} | {r['detected_after_samples']} | "
              f"{', '.join(r['flags'])} | {'yes' if r['recovered'] else 'NO'} | "
              f"{r['stale_valid_samples']} |", file=out, flush=True)
    return rows


def main(argv=None):
    """``python -m mpu9250_ahrs.sim.scenarios.faults``: the catalogue as a table."""
    import argparse
    parser = argparse.ArgumentParser(prog="python -m mpu9250_ahrs.sim.scenarios.faults",
                                     description="Run the fault catalogue (hdl/FAULTS.md) in "
                                     "co-simulation and print what was measured as a table.")
    parser.add_argument("--wiring", choices=("spi", "i2c"), action="append",
                        help="only this wiring's faults (repeatable; default both)")
    args = parser.parse_args(argv)
    catalogue_table(tuple(args.wiring or ("spi", "i2c")))
    return 0


if __name__ == "__main__":
    import sys
    from ...reference.entry_point import run_main
    sys.exit(run_main("python -m mpu9250_ahrs.sim.scenarios.faults", main))
