"""Driver + SPI controller (the sensor front end, SPI wiring) co-simulated with the MPU9250 model
and the AK8963 behind its auxiliary I2C master."""

import dataclasses

import pytest

from mpu9250_ahrs.hdl.contract import ak8963_regs as A
from mpu9250_ahrs.hdl.contract import mpu9250_regs as R
from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
from mpu9250_ahrs.sim.scenarios.setup import SimSetup
from mpu9250_ahrs.sim.scenarios.frontend import expected_mag, run_frontend, sample_matches


NO_MAG_FLAGS = {"mag_valid": 0, "mag_overflow": 0, "mag_new": 0, "mag_dor": 0}


def slv4_write(reg, value):
    return [(0x31, 0x0C), (0x32, reg), (0x33, value), (0x34, 0x80)]


def slv4_read(reg):
    return [(0x31, 0x8C), (0x32, reg), (0x34, 0x80)]


def expected_writes(config, *, mag=True):
    """MPU9250 register writes at bring-up, spelled out independently of the driver's table."""
    int_pin_cfg = (0x20 if config.int_latched else 0) | (0x80 if config.int_active_low else 0)
    writes = [
        (0x6A, 0x10), (0x6B, 0x80), (0x6A, 0x10), (0x6B, 0x01),   # SPI, reset, SPI, clock
    ]
    if config.self_test:
        # 1 kHz, 92 Hz, ±250 °/s, ±2 g; self-test on; off
        writes += [(0x19, 0), (0x1A, 2), (0x1B, 0), (0x1C, 0), (0x1D, 2),
                   (0x1B, 0xE0), (0x1C, 0xE0), (0x1B, 0), (0x1C, 0)]
    writes += [
        (0x6C, 0x00),                                              # all axes on
        (0x1A, config.dlpf_cfg), (0x19, config.smplrt_div),
        (0x1B, R.GYRO_FS_DPS.index(config.gyro_fs_dps) << 3),
        (0x1C, R.ACCEL_FS_G.index(config.accel_fs_g) << 3),
        (0x1D, config.accel_dlpf_cfg),
    ]
    if mag:
        # SLV4 off (I2C_MST_DLY kept); I2C master on; WAIT_FOR_ES, 400 kHz; then a read of
        # I2C_MST_STATUS clears a stale SLV4_DONE
        writes += [(0x34, config.aux_every - 1), (0x6A, 0x30), (0x24, 0x4D)]
        writes += slv4_read(0x00)                             # WIA
        writes += slv4_write(0x0B, 0x01) + slv4_write(0x0A, 0x0F)     # SRST, fuse ROM
        writes += slv4_read(0x10) + slv4_read(0x11) + slv4_read(0x12)  # ASA
        writes += slv4_write(0x0A, 0x00)                              # power-down
        if config.self_test:
            # ASTC self, self-test mode 16 bit, SLV0: 7 bytes from HXL; ASTC 0
            writes += slv4_write(0x0C, 0x40) + slv4_write(0x0A, 0x18)
            writes += [(0x25, 0x8C), (0x26, 0x03), (0x27, 0x87)] + slv4_write(0x0C, 0x00)
        writes += slv4_write(0x0A, 0x16)                              # 100 Hz 16 bit
        writes += [(0x25, 0x8C), (0x26, 0x02), (0x27, 0x88)]          # SLV0: 8 bytes from ST1
    return writes + [(0x37, int_pin_cfg), (0x38, 0x01)]


def ak_writes(config):
    """The AK8963's writes at bring-up: reset, fuse ROM, power-down, (self-test,) 100 Hz."""
    self_test = [(A.ASTC, A.ASTC_SELF), (A.CNTL1, A.CNTL1_BIT_16 | A.MODE_SELF_TEST),
                 (A.ASTC, 0)]
    return [(A.CNTL2, A.CNTL2_SRST), (A.CNTL1, A.MODE_FUSE_ROM), (A.CNTL1, A.MODE_POWER_DOWN),
            *(self_test if config.self_test else []),
            (A.CNTL1, A.CNTL1_BIT_16 | A.MODE_CONT_100HZ)]


def assert_samples_match_model(result, *, mag_ok=True):
    model = result.model
    assert model.violations == [], "\n".join(map(str, model.violations))
    for dev in model.aux_devices.values():
        assert dev.violations == [], "\n".join(map(str, dev.violations))
    reads = model.sample_reads[:len(result.samples)]
    assert len(reads) == len(result.samples)
    # Every sample the model produced after the first read was read, in order, none twice.
    assert reads == list(range(reads[0], reads[0] + len(reads)))
    for i, (got, index) in enumerate(zip(result.samples, reads)):
        assert sample_matches(got, model.samples[index]), \
            f"sample {i}: gateware {got} != model {model.samples[index]}"
        mag, flags = expected_mag(model.ext_reads[i], mag_ok,
                                  model.ext_reads[i - 1] if i else None)
        assert got["mag"] == mag, f"sample {i}: magnetometer"
        assert got["flags"] == {"data_ready": 1, "overrun": 0, "resumed": 0, **flags}, \
            f"sample {i}: flags"
        assert got["counter"] == i


def test_bring_up_sequence_and_nine_axis_samples(vcd):
    setup = SimSetup()
    result = run_frontend(setup, n_samples=25, vcd=vcd())
    model = result.model
    ak = model.aux_devices[A.I2C_ADDRESS]
    assert [(a, v) for _, a, v in model.writes] == expected_writes(setup.config)
    assert [(a, v) for _, a, v in ak.writes] == ak_writes(setup.config)
    assert [(reg, rw) for _, slot, _, reg, rw, _ in model.aux_log if slot == 4] == \
        [(0x00, "r"), (0x0B, "w"), (0x0A, "w"), (0x10, "r"), (0x11, "r"), (0x12, "r"),
         (0x0A, "w"), (0x0A, "w")]
    assert model.resets == 1
    assert result.status == {"streaming": 1, "whoami_error": 0, "no_response": 0,
                             "int_timeout": 0, "restarts": 0,
                             # the model's part trains at 48 MHz (issue #58)
                             "spi_trained": 1,
                             "mag_ok": 1, "mag_absent": 0, "mag_wia_error": 0,
                             "mag_stale": 0, "bad_burst": 0, "bus_timeout": 0,
                             "bus_stuck": 0, "bus_arbitration": 0, "rate_error": 0,
                             "self_test_fail": 0}
    # the simulation leaves the self-tests out (``SimSetup.self_test``): nothing judged
    assert result.who_am_i == 0x71
    assert result.self_test == {"done": 0, "mag_done": 0, "fail": 0}
    assert_samples_match_model(result)
    # read levelling (issue #58): the model's part (100 ns) trains, and its guards held
    level = result.level
    assert level["scanned"] and level["trained"] and level["fallbacks"] == 0, level
    assert level["first"] + 1 <= level["sample_delay"] <= level["last"] - 1, level
    # At 1 kHz against the AK8963's 100 Hz, about one sample in ten carries a new field.
    assert 2 <= sum(s["flags"]["mag_new"] for s in result.samples) <= 3


def test_asa_values_exposed():
    setup = SimSetup()
    model = setup.model(aux_devices={A.I2C_ADDRESS: setup.ak8963(asa=(0x80, 0xC3, 0x1F))})
    result = run_frontend(setup, model=model, until=lambda st: st["mag_ok"])
    assert result.asa == [0x80, 0xC3, 0x1F]


@pytest.mark.parametrize("config", [
    MPU9250Config(gyro_fs_dps=250, accel_fs_g=2, dlpf_cfg=3, accel_dlpf_cfg=5, smplrt_div=4),
    MPU9250Config(gyro_fs_dps=500, accel_fs_g=8, int_latched=False),
    MPU9250Config(gyro_fs_dps=1000, accel_fs_g=4, int_active_low=True),
], ids=["div4_dlpf3", "int_pulse", "int_active_low"])
def test_configurations(config):
    # Keep the simulated sample period near 2,400 cycles whatever the output rate.
    setup = SimSetup(config=config, odr_scale=0.2 * config.output_data_rate / 1000)
    result = run_frontend(setup, n_samples=5)
    assert [(a, v) for _, a, v in result.model.writes] == expected_writes(setup.config)
    assert_samples_match_model(result)


def test_without_magnetometer_config():
    setup = SimSetup(config=MPU9250Config(magnetometer=False))
    result = run_frontend(setup, n_samples=4, model=setup.model(magnetometer=False))
    assert [(a, v) for _, a, v in result.model.writes] == \
        expected_writes(setup.config, mag=False)
    assert_samples_match_model(result, mag_ok=False)


def test_magnetometer_absent_keeps_accel_gyro_flowing():
    setup = SimSetup()
    result = run_frontend(setup, n_samples=6, model=setup.model(magnetometer=False))
    st = result.status
    assert st["mag_absent"] == 1 and st["mag_ok"] == 0 and st["streaming"] == 1
    assert st["restarts"] == 0
    assert_samples_match_model(result, mag_ok=False)


def test_wrong_wia_flags_and_skips_magnetometer():
    setup = SimSetup()
    model = setup.model(aux_devices={A.I2C_ADDRESS: setup.ak8963(wia=0x49)})
    result = run_frontend(setup, n_samples=3, model=model)
    st = result.status
    assert st["mag_wia_error"] == 1 and st["mag_ok"] == 0 and st["mag_absent"] == 0
    assert_samples_match_model(result, mag_ok=False)


def test_magnetic_overflow_is_flagged():
    setup = SimSetup()
    big = lambda i, t: (20000, 10000, 3000)          # 4950 µT: HOFL
    model = setup.model(aux_devices={A.I2C_ADDRESS: setup.ak8963(source=big)})
    result = run_frontend(setup, n_samples=22, model=model)
    assert_samples_match_model(result)
    new = [s for s in result.samples if s["flags"]["mag_new"]]
    assert new and all(s["flags"]["mag_overflow"] and not s["flags"]["mag_valid"] for s in new)


def test_mpu9255_who_am_i_accepted():
    setup = SimSetup()
    result = run_frontend(setup, n_samples=2, model=setup.model(who_am_i=0x73))
    assert result.who_am_i == 0x73 and result.status["whoami_error"] == 0
    assert_samples_match_model(result)


def test_wrong_who_am_i_sets_flag_and_retries():
    setup = SimSetup()
    model = setup.model(who_am_i=0x68)
    result = run_frontend(setup, model=model, until=lambda st: st["restarts"] >= 2)
    assert result.status["whoami_error"] == 1 and result.status["no_response"] == 0
    assert result.who_am_i == 0x68 and result.status["streaming"] == 0
    assert result.samples == []
    assert model.resets >= 2                     # each retry starts from a fresh H_RESET
    assert model.violations == []


@pytest.mark.parametrize("level,value", [(1, 0xFF), (0, 0x00)])
def test_unplugged_sensor_gives_flags_not_a_hang(level, value):
    setup = SimSetup()
    result = run_frontend(setup, stuck_miso=level, until=lambda st: st["restarts"] >= 2)
    assert result.status["restarts"] >= 2
    assert result.status["no_response"] == 1 and result.status["whoami_error"] == 1
    assert result.who_am_i == value


def test_missing_interrupt_times_out_and_restarts():
    setup = SimSetup(config=MPU9250Config(magnetometer=False))
    # The part answers on SPI but its samples come far slower than the driver's timeout.
    model = setup.model(magnetometer=False)
    model.timing = dataclasses.replace(model.timing, odr_scale=200.0)
    result = run_frontend(setup, model=model,
                          until=lambda st: st["int_timeout"] == 1 and st["restarts"] >= 1)
    assert result.status["int_timeout"] == 1 and result.status["restarts"] >= 1
    assert result.samples == []
    assert model.violations == []


def test_slow_consumer_gets_overrun_flags():
    setup = SimSetup(config=MPU9250Config(magnetometer=False), odr_scale=0.1)
    period = int(setup.sample_period_s * setup.clk_freq)
    # Ready for one cycle in every 2.5 sample periods: some samples must be dropped.
    stride = int(2.5 * period)
    result = run_frontend(setup, n_samples=5, ready=lambda c: c % stride == 0,
                          model=setup.model(magnetometer=False), max_cycles=30 * period + 20_000)
    assert result.model.violations == []
    samples = result.samples
    assert len(samples) == 5
    assert any(s["flags"]["overrun"] for s in samples[1:])
    for prev, cur in zip(samples, samples[1:]):
        gap = (cur["counter"] - prev["counter"]) & 0xFFFFFFFF
        assert gap >= 1
        if cur["flags"]["overrun"]:
            assert gap > 1
    for s in samples:
        index = result.model.sample_reads[s["counter"]]
        assert sample_matches(s, result.model.samples[index])


def test_faster_system_clock():
    # 48 MHz: slow SCLK 1 MHz (24-cycle levels), fast SCLK 12 MHz; the model checks both.
    setup = SimSetup(clk_freq=48e6, delay_scale=2.5e-4, odr_scale=0.1)
    result = run_frontend(setup, n_samples=3)
    assert_samples_match_model(result)


def test_config_validation():
    with pytest.raises(ValueError, match="gyro full scale"):
        MPU9250Config(gyro_fs_dps=300)
    with pytest.raises(ValueError, match="smplrt_div"):
        MPU9250Config(smplrt_div=256)
    with pytest.raises(ValueError, match="wiring"):
        MPU9250Config(wiring="uart")


@pytest.mark.parametrize("ratio,skipped", [(1, 0), (2, 1), (3, 2)])
def test_skipped_counts_data_ready_intervals(ratio, skipped):
    """The driver measures the time between data-ready edges against the sample period: a
    sensor that made ``ratio`` periods' worth of samples between two reads (here: the driver
    told a period ``ratio`` times shorter than the model's) reports ``ratio - 1`` skipped
    samples with the next one. The first two samples after bring-up report none (the first
    comes from an INT already high when streaming began, the second from the first edge, which
    has no edge before it to be measured from)."""
    from dataclasses import replace
    setup = SimSetup(clk_freq=12e6, config=MPU9250Config(magnetometer=False))
    base = setup.driver_timing()
    setup.driver_timing = lambda: replace(base, sample_period_s=setup.sample_period_s / ratio)
    result = run_frontend(setup, n_samples=5)
    assert [s["skipped"] for s in result.samples] == [0, 0] + [skipped] * 3


@pytest.mark.parametrize("wiring", ["spi", "i2c"])
@pytest.mark.parametrize("slower", [1.5, 3.0])
def test_a_part_slower_to_reset_than_its_datasheet_comes_up(wiring, slower):
    """Issue #25: an MPU9250 whose reset takes 1.5 or 3 times the driver's wait. Before, every
    retry reset it again and read it too early, for ever (SPI: 93 restarts; I2C: 255); now the
    wait after H_RESET doubles with each restart (up to 4x) and the part streams. Its only
    complaints are the early accesses while it was still in reset."""
    from mpu9250_ahrs.hdl.sensor.bring_up_sequencer import BACKOFF_MAX_SHIFT
    setup = SimSetup(config=MPU9250Config(magnetometer=False, wiring=wiring),
                     odr_scale=1.0 if wiring == "i2c" else SimSetup.odr_scale)
    model = setup.model(magnetometer=False)
    model.timing = dataclasses.replace(model.timing, reset_s=model.timing.reset_s * slower)
    power_up, reset, _ = setup.driver_timing().cycles(setup.clk_freq, setup.config)
    attempts = sum(power_up + (reset << min(k, BACKOFF_MAX_SHIFT)) for k in range(4))
    period = setup.sample_period_s * setup.clk_freq
    result = run_frontend(setup, model=model, n_samples=3,
                          max_cycles=int(attempts + setup.self_test_cycles() + 20 * period +
                                         20_000))
    assert len(result.samples) == 3 and result.status["streaming"] == 1
    assert 1 <= result.status["restarts"] <= BACKOFF_MAX_SHIFT + 1
    assert {v.kind for v in model.violations} <= {"access during start-up"}
    assert all(v.kind == "access during start-up" for v in getattr(result.bus, "violations", []))


def self_test_setup(wiring):
    """The self-tests on a 200 Hz part at a 4 MHz clock, times scaled as the fault tests'."""
    from mpu9250_ahrs.sim.scenarios.faults import catalogue_setup
    return catalogue_setup(wiring, self_test=True)


@pytest.mark.parametrize("wiring", ["spi", "i2c"])
def test_self_test_passes_on_a_good_part(wiring):
    """Issue #25: both parts' self-tests at bring-up, with the writes they take, on the
    models' good parts: all nine axes pass; the samples after it are the configured ones."""
    setup = self_test_setup(wiring)
    result = run_frontend(setup, n_samples=3)
    assert result.self_test == {"done": 1, "mag_done": 1, "fail": 0}
    assert result.status["self_test_fail"] == 0 and result.status["streaming"] == 1
    model = result.model
    assert len(model.self_test_reads) == 2 * setup.config.self_test_samples
    ak = model.aux_devices[A.I2C_ADDRESS]
    assert [(a, v) for _, a, v in ak.writes] == ak_writes(setup.config)
    assert model.violations == [] and ak.violations == []
    if wiring == "spi":     # (the I2C wiring's samples: tests/hdl/test_i2c_wiring.py)
        assert [(a, v) for _, a, v in model.writes] == expected_writes(setup.config)
        assert_samples_match_model(result)


AXES_CASES = [("accel", i) for i in range(3)] + [("gyro", i) for i in range(3)] + \
    [("mag", i) for i in range(3)]


@pytest.mark.parametrize("part,axis", AXES_CASES, ids=[f"{p}{a}" for p, a in AXES_CASES])
def test_self_test_finds_each_failing_axis(part, axis):
    """Each single axis without a self-test response (a damaged axis) is the one flagged,
    and the design streams on (SPI wiring; the fault catalogue runs both)."""
    setup = self_test_setup("spi")
    model = setup.model()
    if part == "mag":
        # X and Y must read within ±200 (a field near 0), Z about -1500: out of the limits
        model.aux_devices[A.I2C_ADDRESS].self_test_field[axis] = 1000 if axis < 2 else 0
        bit = 6 + axis
    else:
        model.self_test_gain[axis + 3 * (part == "gyro")] = 0.0
        bit = axis + 3 * (part == "gyro")
    result = run_frontend(setup, n_samples=2, model=model)
    assert result.self_test == {"done": 1, "mag_done": 1, "fail": 1 << bit}
    assert result.status["self_test_fail"] == 1 << bit and len(result.samples) == 2
