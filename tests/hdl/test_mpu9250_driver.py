"""Driver + SPI controller (the sensor front end) co-simulated with the MPU9250 model."""

import dataclasses

import pytest

from mpu9250_ahrs.hdl import mpu9250_regs as R
from mpu9250_ahrs.hdl.mpu9250_driver import MPU9250Config
from mpu9250_ahrs.sim.cosim import SimSetup, run_frontend, sample_matches


def expected_writes(config):
    """The bring-up writes, spelled out independently of the driver's program table."""
    int_pin_cfg = (0x20 if config.int_latched else 0) | (0x80 if config.int_active_low else 0)
    return [
        (0x6A, 0x10), (0x6B, 0x80), (0x6A, 0x10), (0x6B, 0x01),   # SPI, reset, SPI, clock
        (0x6C, 0x00),                                              # all axes on
        (0x1A, config.dlpf_cfg), (0x19, config.smplrt_div),
        (0x1B, R.GYRO_FS_DPS.index(config.gyro_fs_dps) << 3),
        (0x1C, R.ACCEL_FS_G.index(config.accel_fs_g) << 3),
        (0x1D, config.accel_dlpf_cfg), (0x37, int_pin_cfg), (0x38, 0x01),
    ]


def assert_samples_match_model(result):
    model = result.model
    assert model.violations == [], "\n".join(map(str, model.violations))
    reads = model.sample_reads[:len(result.samples)]
    assert len(reads) == len(result.samples)
    # Every sample the model produced after the first read was read, in order, none twice.
    assert reads == list(range(reads[0], reads[0] + len(reads)))
    for i, (got, index) in enumerate(zip(result.samples, reads)):
        assert sample_matches(got, model.samples[index]), \
            f"sample {i}: gateware {got} != model {model.samples[index]}"
        assert got["counter"] == i
        assert got["flags"] == {"data_ready": 1, "overrun": 0, "mag_valid": 0, "mag_overflow": 0}
        assert got["mag"] == [0, 0, 0]


def test_bring_up_sequence_and_samples(vcd):
    setup = SimSetup()
    result = run_frontend(setup, n_samples=12, vcd=vcd())
    writes = [(a, v) for _, a, v in result.model.writes]
    assert writes == expected_writes(setup.config)
    # The documented order: SPI mode first, reset, SPI mode again (reset cleared it), clock.
    assert writes[:4] == [(R.USER_CTRL, R.USER_CTRL_I2C_IF_DIS), (R.PWR_MGMT_1, 0x80),
                          (R.USER_CTRL, R.USER_CTRL_I2C_IF_DIS), (R.PWR_MGMT_1, 0x01)]
    assert writes[-1] == (R.INT_ENABLE, R.INT_ENABLE_RAW_RDY)
    assert result.model.resets == 1
    assert result.status == {"streaming": 1, "whoami_error": 0, "no_response": 0,
                             "int_timeout": 0, "retries": 0, "who_am_i": 0x71}
    assert_samples_match_model(result)
    # Bring-up takes the two scaled waits plus the register traffic, nothing more.
    power_up, reset, _ = setup.driver_timing().cycles(setup.clk_freq, setup.config)
    assert result.bring_up_cycles < power_up + reset + 4000


@pytest.mark.parametrize("config", [
    MPU9250Config(gyro_fs_dps=250, accel_fs_g=2, dlpf_cfg=3, accel_dlpf_cfg=5, smplrt_div=4),
    MPU9250Config(gyro_fs_dps=500, accel_fs_g=8, int_latched=False),
    MPU9250Config(gyro_fs_dps=1000, accel_fs_g=4, int_active_low=True),
], ids=["div4_dlpf3", "int_pulse", "int_active_low"])
def test_configurations(config):
    # Keep the simulated sample period near 2,400 cycles whatever the output rate.
    setup = SimSetup(config=config, odr_scale=0.2 * config.output_data_rate / 1000)
    result = run_frontend(setup, n_samples=5)
    assert [(a, v) for _, a, v in result.model.writes] == expected_writes(config)
    assert_samples_match_model(result)


def test_mpu9255_who_am_i_accepted():
    setup = SimSetup()
    result = run_frontend(setup, n_samples=2, model=setup.model(who_am_i=0x73))
    assert result.status["who_am_i"] == 0x73 and result.status["whoami_error"] == 0
    assert_samples_match_model(result)


def test_wrong_who_am_i_sets_flag_and_retries():
    setup = SimSetup()
    model = setup.model(who_am_i=0x68)
    result = run_frontend(setup, model=model, until=lambda st: st["retries"] >= 2)
    assert result.status["whoami_error"] == 1 and result.status["no_response"] == 0
    assert result.status["who_am_i"] == 0x68 and result.status["streaming"] == 0
    assert result.samples == []
    assert model.resets >= 2                     # each retry starts from a fresh H_RESET
    assert model.violations == []


@pytest.mark.parametrize("level,value", [(1, 0xFF), (0, 0x00)])
def test_unplugged_sensor_gives_flags_not_a_hang(level, value):
    setup = SimSetup()
    result = run_frontend(setup, stuck_miso=level, until=lambda st: st["retries"] >= 2)
    assert result.status["retries"] >= 2
    assert result.status["no_response"] == 1 and result.status["whoami_error"] == 1
    assert result.status["who_am_i"] == value


def test_missing_interrupt_times_out_and_restarts():
    setup = SimSetup()
    # The part answers on SPI but its samples come far slower than the driver's timeout.
    model = setup.model()
    model.timing = dataclasses.replace(model.timing, odr_scale=200.0)
    result = run_frontend(setup, model=model, until=lambda st: st["int_timeout"] == 1)
    assert result.status["int_timeout"] == 1 and result.status["retries"] >= 1
    assert result.samples == []
    assert model.violations == []


def test_slow_consumer_gets_overrun_flags():
    setup = SimSetup()
    period = int(setup.sample_period_s * setup.clk_freq)
    # Ready for one cycle in every 2.5 sample periods: some samples must be dropped.
    stride = int(2.5 * period)
    result = run_frontend(setup, n_samples=5, ready=lambda c: c % stride == 0,
                          max_cycles=30 * period + 20_000)
    assert result.model.violations == []
    samples = result.samples
    assert len(samples) == 5
    assert any(s["flags"]["overrun"] for s in samples[1:])
    for prev, cur in zip(samples, samples[1:]):
        gap = (cur["counter"] - prev["counter"]) & 0xFFFF
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
