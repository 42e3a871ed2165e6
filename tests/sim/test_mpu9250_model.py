"""The MPU9250 model on its own: register semantics, SPI checks, sample timing, INT pin."""

import pytest

from mpu9250_ahrs.hdl.contract import mpu9250_regs as R
from mpu9250_ahrs.sim.models.mpu9250_model import MPU9250Model, MPU9250Timing, ProtocolError
from mpu9250_ahrs.sim.models.sources import SensorSample, counting_source, table_source


class Host:
    """Drives the model's pins like an SPI mode-3 controller; time in seconds."""

    def __init__(self, model, t=0.0):
        self.model, self.t = model, t

    def wait(self, seconds):
        self.t += seconds
        self.model.advance(self.t)

    def transfer(self, data, *, half=0.5e-6, setup=None, hold=0.5e-6, sclk_idle=1,
                 bits=None):
        m = self.model
        if sclk_idle == 0:
            m.sclk_edge(self.t, 0, 0)
        m.cs_edge(self.t, 0)
        self.t += half if setup is None else setup
        rx = []
        nbits = 8 * len(data) if bits is None else bits
        for i in range(nbits):
            byte, bit = divmod(i, 8)
            mosi = (data[byte] >> (7 - bit)) & 1
            m.sclk_edge(self.t, 0, mosi)
            self.t += half
            if bit == 0:
                rx.append(0)
            # sampled just before the next falling edge: the bit shows 100 ns after its own
            rx[-1] = (rx[-1] << 1) | m.sdo_at(self.t + 0.99 * half)
            m.sclk_edge(self.t, 1, mosi)
            self.t += half
        self.t += hold - half
        m.cs_edge(self.t, 1)
        self.t += 1e-6
        return bytes(rx)

    def read(self, addr, n=1, **kw):
        return self.transfer(bytes([R.SPI_READ | addr]) + bytes(n), **kw)[1:]

    def write(self, addr, *values, **kw):
        self.transfer(bytes([addr, *values]), **kw)


FAST = dict(half=0.0625e-6)      # 8 MHz: a period longer than the 100 ns output delay


def ready_model(**kw):
    """A model past its start-up time, with fast simulated time constants."""
    kw.setdefault("timing", MPU9250Timing(startup_s=1e-3, reset_s=1e-3))
    m = MPU9250Model(**kw)
    host = Host(m)
    host.wait(1.1e-3)
    return m, host


def kinds(model):
    return [v.kind for v in model.violations]


def test_who_am_i_and_reset_values():
    m, host = ready_model()
    assert host.read(R.WHO_AM_I) == bytes([0x71])
    assert host.read(R.PWR_MGMT_1) == bytes([0x01])
    assert host.read(R.CONFIG) == bytes([0x00])
    assert m.violations == []


def test_who_am_i_configurable():
    m, host = ready_model(who_am_i=0x73)
    assert host.read(R.WHO_AM_I) == bytes([0x73])


def test_access_during_start_up_is_ignored_and_reported():
    m = MPU9250Model(timing=MPU9250Timing(startup_s=1e-3))
    host = Host(m)
    assert host.read(R.WHO_AM_I) == bytes([0x00])
    host.write(R.CONFIG, 0x03)
    assert kinds(m) == ["access during start-up"] * 2
    host.wait(1e-3)
    assert host.read(R.CONFIG) == bytes([0x00])      # the write was ignored


def test_write_read_back_and_burst_auto_increment():
    m, host = ready_model()
    host.write(R.SMPLRT_DIV, 0x04, 0x03, 0x08)      # SMPLRT_DIV, CONFIG, GYRO_CONFIG
    assert host.read(R.SMPLRT_DIV, 3) == bytes([0x04, 0x03, 0x08])
    assert [(a, v) for _, a, v in m.writes] == [(0x19, 4), (0x1A, 3), (0x1B, 8)]


def test_user_ctrl_self_clearing_bits():
    m, host = ready_model()
    host.write(R.USER_CTRL, R.USER_CTRL_I2C_IF_DIS | 0x07)
    assert host.read(R.USER_CTRL) == bytes([R.USER_CTRL_I2C_IF_DIS])


def test_write_to_read_only_register_is_a_violation():
    m, host = ready_model()
    host.write(R.WHO_AM_I, 0x00)
    assert kinds(m) == ["write to a read-only register"]
    assert m.violations[0].register == R.WHO_AM_I
    assert host.read(R.WHO_AM_I) == bytes([0x71])


def test_raise_on_violation():
    m, host = ready_model(raise_on_violation=True)
    with pytest.raises(ProtocolError, match="read-only"):
        host.write(R.ACCEL_XOUT_H, 0x00)


def test_fast_clock_allowed_only_for_sensor_reads():
    m, host = ready_model()
    host.read(R.INT_STATUS, 15, **FAST)                 # 10 MHz sensor burst: fine
    assert m.violations == []
    host.read(R.WHO_AM_I, **FAST)                       # 10 MHz on WHO_AM_I: too fast
    assert kinds(m) and set(kinds(m)) <= {"SCLK too fast", "SCLK level too short"}
    assert all(v.register == R.WHO_AM_I for v in m.violations)
    m.violations.clear()
    host.write(R.CONFIG, 1, **FAST)                     # writes are never fast
    assert "SCLK too fast" in kinds(m)


def test_sclk_above_20_mhz_is_a_violation():
    m, host = ready_model()
    host.read(R.ACCEL_XOUT_H, 6, half=0.02e-6)          # 25 MHz
    assert "SCLK too fast" in kinds(m)


def test_1_mhz_is_allowed_everywhere():
    m, host = ready_model()
    host.write(R.CONFIG, 1, half=0.5e-6)
    host.read(R.WHO_AM_I, half=0.5e-6)
    assert m.violations == []


@pytest.mark.parametrize("kw,kind", [
    (dict(hold=0.3e-6), "CS hold"),
    (dict(setup=5e-9), "CS setup"),
    (dict(sclk_idle=0), "SPI mode"),
    (dict(bits=12), "CS raised mid-byte"),
])
def test_cs_framing_violations(kw, kind):
    m, host = ready_model()
    data = bytes([R.SPI_READ | R.WHO_AM_I, 0])
    host.transfer(data, **kw)
    assert kind in kinds(m)


def test_h_reset_restores_defaults_and_blocks_access():
    m, host = ready_model()
    host.write(R.CONFIG, 0x05)
    host.write(R.PWR_MGMT_1, R.PWR_MGMT_1_H_RESET)
    host.read(R.WHO_AM_I)
    assert kinds(m) == ["access during start-up"]
    host.wait(1e-3)
    assert host.read(R.CONFIG) == bytes([0]) and host.read(R.PWR_MGMT_1) == bytes([0x01])
    assert m.resets == 1


@pytest.mark.parametrize("config,gyro_config,div,rate", [
    (1, 0, 0, 1000), (1, 0, 4, 200), (3, 0, 9, 100), (0, 0, 9, 8000), (7, 0, 0, 8000),
    (1, 1, 9, 32000), (1, 2, 0, 32000),
])
def test_output_data_rate(config, gyro_config, div, rate):
    m, host = ready_model()
    host.write(R.SMPLRT_DIV, div, config, gyro_config)
    n0, t0 = len(m.samples), host.t
    host.wait(0.05)
    produced = len(m.samples) - n0
    assert abs(produced - rate * (host.t - t0)) <= 1
    assert m.sample_period == pytest.approx(1 / rate)


def test_sleep_stops_sampling():
    m, host = ready_model()
    host.write(R.PWR_MGMT_1, R.PWR_MGMT_1_SLEEP | 1)
    n = len(m.samples)
    host.wait(0.01)
    assert len(m.samples) == n


def test_sleep_after_reset_from_otp():
    m, host = ready_model(sleep_after_reset=True)
    assert host.read(R.PWR_MGMT_1) == bytes([0x41])
    assert m.samples == []


def test_sensor_registers_are_big_endian():
    sample = SensorSample(accel=(0x1234, -2, 3), temp=-300, gyro=(-32768, 32767, 0))
    m, host = ready_model(source=table_source([sample]))
    host.wait(1.5e-3)
    assert host.read(R.ACCEL_XOUT_H, R.SENSOR_BYTES, **FAST) == bytes.fromhex(
        "1234" "fffe" "0003" "fed4" "8000" "7fff" "0000")


def test_burst_is_atomic():
    m, host = ready_model(source=counting_source())
    host.wait(2e-3)
    host.t = m.next_event - 50e-6               # the next sample is due mid-burst
    before = m.samples[-1]
    # A 1 MHz burst (~ 120 µs) straddling the sample time must return one sample, whole.
    data = host.read(R.ACCEL_XOUT_H, R.SENSOR_BYTES, half=0.5e-6)
    assert data == before.to_bytes()
    assert m.samples[-1] != before               # the new sample landed after CS rose
    # a burst from ACCEL_XOUT_H is the self-test's (a sample read starts at INT_STATUS)
    assert m.self_test_reads == [m.samples.index(before)] and m.sample_reads == []


def test_sample_during_burst_raises_int_for_the_next_read():
    m, host = ready_model(source=counting_source())
    enable_int(host, R.INT_PIN_CFG_LATCH_INT_EN)
    wait_for_sample(m, host)
    host.t = m.next_event - 50e-6
    first = host.read(R.INT_STATUS, 1 + R.SENSOR_BYTES, half=0.5e-6)   # clears, then a sample
    assert first[0] == 1 and m.int_level == 1
    second = host.read(R.INT_STATUS, 1 + R.SENSOR_BYTES, **FAST)
    assert second[1:] == m.samples[-1].to_bytes() != first[1:]
    assert m.int_level == 0


def enable_int(host, cfg):
    host.write(R.INT_PIN_CFG, cfg)
    host.write(R.INT_ENABLE, R.INT_ENABLE_RAW_RDY)


def wait_for_sample(m, host):
    n = len(m.samples)
    while len(m.samples) == n:
        host.wait(m.next_event - host.t + 1e-9)


def test_int_latched_until_int_status_read():
    m, host = ready_model()
    enable_int(host, R.INT_PIN_CFG_LATCH_INT_EN)
    host.read(R.INT_STATUS)
    wait_for_sample(m, host)
    assert m.int_level == 1
    host.wait(200e-6)
    assert m.int_level == 1
    host.read(R.WHO_AM_I)                    # other reads do not clear it
    assert m.int_level == 1
    assert host.read(R.INT_STATUS) == bytes([1])
    assert m.int_level == 0


def test_int_anyrd_2clear():
    m, host = ready_model()
    enable_int(host, R.INT_PIN_CFG_LATCH_INT_EN | R.INT_PIN_CFG_ANYRD_2CLEAR)
    wait_for_sample(m, host)
    assert m.int_level == 1
    host.read(R.WHO_AM_I)
    assert m.int_level == 0


def test_int_active_low():
    m, host = ready_model()
    enable_int(host, R.INT_PIN_CFG_LATCH_INT_EN | R.INT_PIN_CFG_ACTL)
    host.read(R.INT_STATUS)
    assert m.int_level == 1
    wait_for_sample(m, host)
    assert m.int_level == 0


def test_int_pulse_is_50_us():
    m, host = ready_model()
    enable_int(host, 0)
    wait_for_sample(m, host)
    t_sample = m.sample_times[-1]
    host.t = t_sample + 49e-6
    host.wait(0)
    assert m.int_level == 1
    host.wait(2e-6)
    assert m.int_level == 0
    assert m.regs[R.INT_STATUS] & 1                   # status stays until read


def test_int_disabled_keeps_pin_low():
    m, host = ready_model()
    host.write(R.INT_PIN_CFG, R.INT_PIN_CFG_LATCH_INT_EN)
    wait_for_sample(m, host)
    assert m.int_level == 0


def test_timing_scaled():
    t = MPU9250Timing().scaled(delays=1e-3, odr=0.5)
    assert t.startup_s == pytest.approx(100e-6) and t.reset_s == pytest.approx(100e-6)
    assert t.int_pulse_s == pytest.approx(25e-6) and t.odr_scale == 0.5


def test_sample_out_of_range_rejected():
    with pytest.raises(ValueError, match="signed 16-bit"):
        SensorSample(accel=(40000, 0, 0))


# -- auxiliary I2C master -------------------------------------------------------------------------

from mpu9250_ahrs.hdl.contract import ak8963_regs as A           # noqa: E402
from mpu9250_ahrs.sim.models.ak8963_model import AK8963Model, constant_field   # noqa: E402


def aux_model(**kw):
    ak = AK8963Model(source=constant_field(0x0102, -3, 0x3F00), **kw)
    m, host = ready_model(aux_devices={A.I2C_ADDRESS: ak})
    host.write(R.CONFIG, 1)                              # 1 kHz (reset value DLPF 0: 8 kHz)
    host.write(R.USER_CTRL, R.USER_CTRL_I2C_IF_DIS | R.USER_CTRL_I2C_MST_EN)
    host.write(R.I2C_MST_CTRL, R.I2C_MST_CLK_400KHZ)
    return m, host, ak


def slv4(host, m, addr, reg, do=0):
    host.write(R.I2C_SLV4_ADDR, addr, reg, do, R.I2C_SLV_EN)
    for _ in range(10):
        host.wait(m.sample_period)
        status = host.read(R.I2C_MST_STATUS)[0]
        if status & R.I2C_MST_STATUS_SLV4_DONE:
            return status, host.read(R.I2C_SLV4_DI)[0]
    raise AssertionError("SLV4 never finished")


def test_slv4_single_transfers():
    m, host, ak = aux_model()
    status, di = slv4(host, m, R.I2C_SLV_RNW | A.I2C_ADDRESS, A.WIA)
    assert status == R.I2C_MST_STATUS_SLV4_DONE and di == 0x48
    status, _ = slv4(host, m, A.I2C_ADDRESS, A.CNTL1, A.MODE_FUSE_ROM)
    assert ak.mode == A.MODE_FUSE_ROM
    assert host.read(R.I2C_SLV4_CTRL)[0] & R.I2C_SLV_EN == 0       # one transfer per enable
    assert m.violations == [] and ak.violations == []


def test_slv4_nack_when_absent():
    m, host, ak = aux_model()
    status, _ = slv4(host, m, R.I2C_SLV_RNW | 0x0D, A.WIA)
    assert status == R.I2C_MST_STATUS_SLV4_DONE | R.I2C_MST_STATUS_SLV4_NACK
    assert host.read(R.I2C_MST_STATUS) == bytes([0])                 # cleared on read


def slv0_read(host, reg, n, ctrl_extra=0, slot=0):
    base = R.I2C_SLV_ADDR[slot]
    host.write(base, R.I2C_SLV_RNW | A.I2C_ADDRESS, reg, R.I2C_SLV_EN | ctrl_extra | n)


def test_slv0_fills_ext_sens_data_each_sample():
    m, host, ak = aux_model()
    ak.write_reg(A.CNTL1, A.CNTL1_BIT_16 | A.MODE_CONT_100HZ)
    slv0_read(host, A.ST1, A.SAMPLE_BYTES)
    host.wait(0.0125)
    data = host.read(R.EXT_SENS_DATA_00, 8, **FAST)
    assert data[1:7] == bytes([0x02, 0x01, 0xFD, 0xFF, 0x00, 0x3F])
    assert data[7] == A.ST2_BITM
    assert len(m.aux_log) >= 12                               # one read per 1 kHz sample


def test_ext_sens_data_allocated_in_slot_order_with_byte_swap():
    m, host, ak = aux_model()
    ak.write_reg(A.CNTL1, A.CNTL1_BIT_16 | A.MODE_CONT_100HZ)
    slv0_read(host, A.WIA, 2, slot=0)                                   # 48 9A
    # HXL..ST2 (ST2 releases the data registers); words start at odd addresses (GRP).
    slv0_read(host, A.HXL, 7, ctrl_extra=R.I2C_SLV_BYTE_SW | R.I2C_SLV_GRP, slot=1)
    host.wait(0.0125)
    assert host.read(R.EXT_SENS_DATA_00, 4, **FAST) == bytes([0x48, 0x9A, 0x01, 0x02])


def test_slot_delay_pacing():
    m, host, ak = aux_model()
    slv0_read(host, A.WIA, 1)
    host.write(R.I2C_SLV4_CTRL, 4)                       # I2C_MST_DLY = 4: every 5th sample
    host.write(R.I2C_MST_DELAY_CTRL, 0x01)
    n = len(m.aux_log)
    host.wait(0.0200)
    assert len(m.aux_log) - n in (4, 5)


def test_wait_for_es_delays_data_ready_by_the_transfer():
    m, host, ak = aux_model()
    host.write(R.I2C_MST_CTRL, R.I2C_MST_CTRL_WAIT_FOR_ES | R.I2C_MST_CLK_400KHZ)
    slv0_read(host, A.ST1, A.SAMPLE_BYTES)
    host.wait(0.005)
    tick = m._next_sample
    host.t = tick + 1e-6
    host.wait(0)
    n = len(m.samples)
    host.wait((30 + 9 * 8) / 400e3 - 5e-6)               # just before the 8-byte read ends
    assert len(m.samples) == n
    host.wait(10e-6)
    assert len(m.samples) == n + 1


def test_self_test_response_and_factory_codes():
    """SELF_TEST_* hold the factory codes (through a reset); an axis with its self-test bit
    reads its factory response, halved per full-scale step, times its gain (0: a dead axis)."""
    from mpu9250_ahrs.hdl.sensor.self_test import otp
    codes = (90, 94, 102, 112, 115, 108)
    m = MPU9250Model(self_test_codes=codes, self_test_gain=(1, 1, 1, 1, 0, 1))
    base = SensorSample(accel=(10, 20, 30), gyro=(-5, 0, 5))
    m.regs[R.GYRO_CONFIG], m.regs[R.ACCEL_CONFIG] = 0xE0, 0xE0 | 0x08     # accel at ±4 g
    got = m._self_test_response(base)
    assert got.accel == tuple(v + (otp(c) >> 1) for v, c in zip(base.accel, codes[:3]))
    assert got.gyro == (-5 + otp(112), 0, 5 + otp(108))
    m.regs[R.GYRO_CONFIG] = 0x40                                          # Y only
    assert m._self_test_response(base).gyro == base.gyro               # Y's gain is 0
    assert bytes(m.regs[R.SELF_TEST_X_ACCEL:R.SELF_TEST_X_ACCEL + 3]) == bytes(codes[:3])
    assert bytes(m.regs[R.SELF_TEST_X_GYRO:R.SELF_TEST_X_GYRO + 3]) == bytes(codes[3:])


def _read_sampled_late(model, t, addr, half, sample_after):
    """A one-byte read in mode 3 at a period of 2·``half``, each SDO bit sampled
    ``sample_after`` after its own falling edge (later than the next edges when it exceeds a
    period, as a trained sample point does): the edges and the samples in time order."""
    frame = [R.SPI_READ | addr, 0]
    events = [(t, 0, "cs", 0)]
    t += half
    for i in range(16):
        mosi = (frame[i // 8] >> (7 - i % 8)) & 1
        events += [(t, 1, "fall", mosi), (t + half, 1, "rise", mosi)]
        if i >= 8:
            events.append((t + sample_after, 2, "sample", None))
        t += 2 * half
    events.append((t + sample_after + 0.5e-6, 3, "cs", 1))
    bits = []
    for when, _, kind, value in sorted(events, key=lambda e: (e[0], e[1])):
        if kind == "cs":
            model.cs_edge(when, value)
        elif kind == "sample":
            bits.append(model.sdo_at(when))
        else:
            model.sclk_edge(when, 0 if kind == "fall" else 1, value)
    return int("".join(map(str, bits)), 2), t + sample_after + 2e-6


def test_the_sdo_delay_is_the_parts_and_the_boards_and_keeps_the_bits_in_order():
    """Issue #58's model: a bit shows the part's SDO delay plus the board's round trip after
    its falling edge; at 20 MHz a 110 ns round trip spans two periods and the bits come out
    late but in order (a sample point trained past a period reads the byte)."""
    timing = MPU9250Timing(startup_s=1e-3, reset_s=1e-3, sdo_delay_s=100e-9,
                           board_delay_s=10e-9)
    assert timing.sdo_round_trip_s == pytest.approx(110e-9)
    m = MPU9250Model(timing=timing)
    t = 1.1e-3
    m.advance(t)
    value, t = _read_sampled_late(m, t, R.WHO_AM_I, 25e-9, 111e-9)
    assert value == 0x71
    value, t = _read_sampled_late(m, t, R.WHO_AM_I, 25e-9, 109e-9)
    assert value == 0x71 >> 1          # each bit sampled before it arrived: the one before
    m.sdo_drift_s = 20e-9              # the eye moves: the trained point now reads early
    value, t = _read_sampled_late(m, t, R.WHO_AM_I, 25e-9, 111e-9)
    assert value == 0x71 >> 1
    value, t = _read_sampled_late(m, t, R.WHO_AM_I, 25e-9, 131e-9)
    assert value == 0x71


def test_the_sdo_jitter_moves_each_bit_within_its_bound():
    timing = MPU9250Timing(startup_s=1e-3, sdo_delay_s=15e-9, sdo_jitter_s=4e-9)
    for seed in (1, 2):
        m = MPU9250Model(timing=timing, sdo_seed=seed)
        delays = [m._bit_delay(0.0) for _ in range(2000)]
        assert 11e-9 <= min(delays) < 11.1e-9 and 18.9e-9 < max(delays) <= 19e-9
    again = MPU9250Model(timing=timing, sdo_seed=2)
    assert [again._bit_delay(0.0) for _ in range(2000)] == delays       # seeded: repeatable
    m, host = ready_model(timing=MPU9250Timing(startup_s=1e-3, reset_s=1e-3,
                                               sdo_delay_s=15e-9, sdo_jitter_s=4e-9))
    assert host.read(R.WHO_AM_I, **FAST) == bytes([0x71])


@pytest.mark.parametrize("kw, message", [
    (dict(sdo_delay_s=2e-9), "a part's SDO delay is 5 .. 100 ns"),
    (dict(sdo_delay_s=120e-9), "the round trip outside it is board_delay_s"),
    (dict(board_delay_s=-1e-9), "cannot be negative"),
    (dict(sdo_delay_s=10e-9, sdo_jitter_s=20e-9), "more than the delay it moves")])
def test_an_sdo_timing_out_of_its_range_is_refused(kw, message):
    with pytest.raises(ValueError, match=message):
        MPU9250Timing(**kw)
