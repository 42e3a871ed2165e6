"""The front end on an I2C-wired board: MPU9250 at 0x68/0x69 through the FPGA's I2C controller,
the AK8963 at 0x0C through the MPU9250's bypass multiplexer. Real sample rate (1 kHz): I2C at
400 kHz needs about 0.66 ms for one nine-axis read."""

import pytest

from mpu9250_ahrs.hdl.contract import ak8963_regs as A
from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
from mpu9250_ahrs.sim.scenarios.setup import SimSetup
from mpu9250_ahrs.sim.scenarios.frontend import expected_mag, run_frontend, sample_matches


def i2c_setup(setup_kw=None, **config):
    return SimSetup(config=MPU9250Config(wiring="i2c", **config), odr_scale=1.0,
                    **(setup_kw or {}))


def transfers(bus, address):
    """(direction, register, bytes) per transfer to ``address``; NACKed ones have no bytes."""
    return [(rw, reg, bytes(data or b"")) for _, a, rw, reg, data in bus.log if a == address]


def assert_clean(result):
    for who in (result.model, result.bus, *result.model.aux_devices.values()):
        assert who.violations == [], "\n".join(map(str, who.violations))


def assert_samples(result, *, mag_ok=True):
    model, bus = result.model, result.bus
    reads = model.sample_reads[:len(result.samples)]
    assert reads == list(range(reads[0], reads[0] + len(result.samples)))
    mag_reads = [data for rw, reg, data in transfers(bus, A.I2C_ADDRESS)
                 if rw == "r" and reg == A.ST1 and len(data) == A.SAMPLE_BYTES]
    for i, got in enumerate(result.samples):
        assert sample_matches(got, model.samples[reads[i]]), f"sample {i}"
        mag, flags = expected_mag(mag_reads[i] if mag_ok else b"", mag_ok,
                                  mag_reads[i - 1] if i and mag_ok else None)
        assert got["mag"] == mag and \
            got["flags"] == {"data_ready": 1, "overrun": 0, "resumed": 0, **flags}
        assert got["counter"] == i


def test_bring_up_and_nine_axis_samples(vcd):
    setup = i2c_setup()
    result = run_frontend(setup, n_samples=12, vcd=vcd())
    assert_clean(result)
    mpu_writes = [(reg, data[0]) for rw, reg, data in transfers(result.bus, 0x68)
                  if rw == "w" and data]
    assert mpu_writes == [
        (0x6B, 0x80), (0x6B, 0x01),                     # reset, clock (no I2C_IF_DIS on I2C)
        (0x6C, 0x00), (0x1A, 0x01), (0x19, 0x00), (0x1B, 0x18), (0x1C, 0x18), (0x1D, 0x01),
        (0x6A, 0x00), (0x37, 0x22),                     # I2C master off, bypass on, INT
                                                        # set-up kept (a re-initialisation
                                                        # runs this while streaming)
        (0x37, 0x22), (0x38, 0x01)]                     # latched INT (bypass kept), RAW_RDY
    ak = [(rw, reg, data) for rw, reg, data in transfers(result.bus, A.I2C_ADDRESS) if data]
    assert ak[:8] == [("r", A.WIA, b"\x48"), ("w", A.CNTL2, b"\x01"), ("w", A.CNTL1, b"\x0f"),
                      ("r", A.ASAX, b"\xb0"), ("r", A.ASAY, b"\xb2"), ("r", A.ASAZ, b"\xa7"), ("w", A.CNTL1, b"\x00"), ("w", A.CNTL1, b"\x16")]
    assert result.status["mag_ok"] == 1 and result.asa == [0xB0, 0xB2, 0xA7]
    assert_samples(result)
    assert sum(s["flags"]["mag_valid"] for s in result.samples) >= 1


def test_alternate_address_0x69():
    setup = i2c_setup(i2c_address=0x69)
    result = run_frontend(setup, n_samples=2)
    assert_clean(result)
    assert transfers(result.bus, 0x68) == [] and transfers(result.bus, 0x69)
    assert_samples(result)


def test_magnetometer_absent():
    setup = i2c_setup()
    result = run_frontend(setup, n_samples=3, model=setup.model(magnetometer=False))
    assert result.status["mag_absent"] == 1 and result.status["mag_ok"] == 0
    assert_samples(result, mag_ok=False)


def test_nothing_on_the_bus_gives_flags_not_a_hang():
    setup = i2c_setup()
    result = run_frontend(setup, stuck_miso=1, until=lambda st: st["restarts"] >= 2)
    assert result.status["no_response"] == 1 and result.status["streaming"] == 0


def test_clock_stretching_devices():
    setup = i2c_setup(magnetometer=False)
    result = run_frontend(setup, n_samples=2, model=setup.model(magnetometer=False),
                          bus_kw={"stretch_s": 4e-6})
    assert_clean(result)
    assert_samples(result, mag_ok=False)


def test_skipping_the_power_down_wait_is_caught_by_the_model():
    # A driver that does not wait 100 µs in power-down before the next AK8963 mode.
    setup = i2c_setup(setup_kw={"mag_power_down_s": 0})
    result = run_frontend(setup, until=lambda st: st["mag_ok"])
    ak = result.model.aux_devices[A.I2C_ADDRESS]
    assert [v.kind for v in ak.violations] == ["power-down wait"]
