"""The fault catalogue (``hdl/FAULTS.md``): every fault injected into the models in
co-simulation, on each wiring it applies to. Each must be flagged with one of its flags within
the catalogue's bound, let no stale or garbage sample through marked valid, and end with the
design streaming again (with new magnetometer fields where the fault was the magnetometer's).
"""

import pytest

from mpu9250_ahrs.hdl.mpu9250_driver import BAD_BURST_LIMIT, burst_is_plausible
from mpu9250_ahrs.sim.faults import FAULTS, FaultInjector, catalogue_setup, fault_names, run_fault


AT, AFTER, DURATION = 3, 4, 8


def bound(name, setup):
    """The catalogue's detection bound for ``name`` on ``setup``, in sample periods."""
    period = setup.sample_period_s
    timing = setup.driver_timing()
    power_up, reset, _ = timing.cycles(setup.clk_freq, setup.config)
    attempt = (power_up + reset) / setup.clk_freq / period
    k = timing.mag_timeout_periods(setup.config)
    ak_period = 0.01 * setup.odr_scale * (1 + setup.ak_clock_error) / period
    from mpu9250_ahrs.hdl.i2c_controller import I2CTiming
    i2c_timeout = I2CTiming.for_clock(setup.clk_freq).timeout / setup.clk_freq / period
    spi = setup.config.wiring == "spi"
    return {
        "mpu_absent": attempt + 1, "who_am_i_wrong": attempt + 1,
        "cipo_stuck_high_bringup": attempt + 1, "cipo_stuck_low_bringup": attempt + 1,
        # the magnetometer's set-up: a dozen SLV4 transfers, each at a sample tick (SPI)
        "ak8963_absent": attempt + 20, "wia_wrong": attempt + 20,
        "ak8963_lost": k + 1 if spi else 1, "ak8963_reset": k + 1,
        "mag_overflow": ak_period + 1,
        "cipo_stuck_high": 1, "cipo_stuck_low": 1,
        "int_stuck_low": timing.stream_timeout_periods + 1.5,
        "int_stuck_high": timing.stream_timeout_periods + 1.5,
        "mpu_reset": timing.stream_timeout_periods + 1.5,
        "i2c_bus_stuck": 1, "clock_stretch_timeout": i2c_timeout + 1,
        "nack_mid_transfer": 1,
        "sensor_overrun": FAULTS["sensor_overrun"].duration + 1,
        "host_garbage": 0,
    }[name]


KEEPS_STREAMING = {"ak8963_absent", "wia_wrong", "ak8963_lost", "ak8963_reset", "mag_overflow",
                   "nack_mid_transfer", "sensor_overrun",
                   "host_garbage"}
CASES = [(name, wiring) for wiring in ("spi", "i2c") for name in fault_names(wiring)]


@pytest.mark.parametrize("name,wiring", CASES, ids=[f"{w}-{n}" for n, w in CASES])
def test_fault(name, wiring):
    setup = catalogue_setup(wiring, fault=name)
    fault = FAULTS[name]
    removable = not (fault.stall or fault.duration is None)
    r = run_fault(name, setup, at=AT, after=AFTER, duration=DURATION if removable else None)
    assert r["stale_valid_samples"] == 0, r
    assert set(fault.flags) & set(r["flags"]), r
    assert r["detected_after_samples"] is not None and \
        r["detected_after_samples"] <= bound(name, setup), r
    assert r["recovered"], r
    assert r.get("counter_increasing", True), r
    # what the design keeps running on: a magnetometer fault, a glitch of one read, a slow
    # consumer or a bad host write never restart the sensor's bring-up
    if name in KEEPS_STREAMING:
        assert "restarts" not in r["flags"], r
    # the models saw no protocol violation
    assert r["violations"] == [], r


@pytest.mark.parametrize("burst,ok", [
    (bytes([0x01]) + bytes(range(14)), True),
    (bytes([0x00]) + bytes(range(14)), False),            # no RAW_RDY: no new sample
    (bytes(15), False),                                    # a line stuck low
    (bytes([0xFF] * 15), False),                           # a line stuck high
    (bytes([0x01]) + bytes([0xFF] * 14), False),           # data all ones
    (bytes([0x01]) + bytes([0xFF] * 13) + b"\x00", True),  # one byte not: a real value
])
def test_burst_check(burst, ok):
    assert burst_is_plausible(burst) == ok
    assert BAD_BURST_LIMIT >= 2


def test_injector_timing():
    """A fault starts once ``at`` samples were read and ends ``duration`` periods later."""
    class Mpu:
        sample_reads = []
        selected = False
        aux_devices = {}
    seen = []
    fault = FAULTS["int_stuck_low"]
    inj = FaultInjector(fault, at=2, duration=3, period_s=1.0, mpu=Mpu())
    inj.advance(0.5)
    assert inj.injected_at is None and inj.next_event is None
    Mpu.sample_reads = [0, 1]
    inj.advance(1.5)
    assert inj.injected_at == 1.5 and inj.int_level == 0 and inj.next_event == 4.5
    inj.advance(4.4)
    assert inj.removed_at is None
    inj.advance(4.5)
    assert inj.removed_at == 4.5 and inj.int_level is None
