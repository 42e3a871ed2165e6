"""MPU9250 + AK8963 driver: bring-up, then one nine-axis sample per data-ready interrupt.

Interface
    ``port`` (``RegisterPortSignature``, flipped): register commands to an ``SPIRegisterPort``
        or an ``I2CRegisterPort``.
    ``int_pin`` (in): the sensor's INT pin, raw; synchronised here.
    ``samples`` (out, ``Sample`` stream): one per data-ready interrupt. If the consumer has not
        taken the previous sample when the next is read, the new one is dropped and the following
        sample carries ``flags.overrun`` (valid never waits on ready). ``skipped`` counts the
        samples before this one that never came out: dropped so, or made by the sensor and
        never read (data-ready edges more than one sample period apart).
    ``status`` (out, ``DriverStatus``) and ``asa`` (out, 3 × 8 bits: the AK8963's fuse-ROM
        sensitivity adjustment values, valid once ``status.mag_ok``). See ``hdl/sensor/sample.py``
        and ``hdl/sensor/driver_status.py``.

Bring-up is a program (``bring_up_program``) run by a small sequencer: register writes, checked
reads, stored reads, status polls and waits, each with what to do on failure. The sequence is the
one well-known drivers use:

    SPI wiring: wait power-up; USER_CTRL = I2C_IF_DIS; PWR_MGMT_1 = H_RESET; wait reset;
    USER_CTRL = I2C_IF_DIS (H_RESET cleared it); PWR_MGMT_1 = CLKSEL 1; check WHO_AM_I;
    the self-test (``MPU9250Config.self_test``, ``hdl/sensor/self_test.py``): 1 kHz, ±250 °/s, ±2 g,
    92 Hz; wait 20 ms; N bursts of the 14 sensor bytes 1 ms apart, subtracted; self-test on,
    wait, N bursts added; self-test off; the six factory codes, each axis judged; wait;
    PWR_MGMT_2, CONFIG, SMPLRT_DIV, GYRO_CONFIG, ACCEL_CONFIG, ACCEL_CONFIG2;
    magnetometer through the MPU9250's I2C master: SLV4 disabled, USER_CTRL |= I2C_MST_EN,
    I2C_MST_CTRL = WAIT_FOR_ES | 400 kHz, wait the master's longest cycle, read I2C_MST_STATUS
    (a stale SLV4_DONE cleared: ``aux_idle_cycles``); each AK8963 access is a single SLV4 transfer
    (SLV4_ADDR/REG/DO/CTRL, CTRL keeping I2C_MST_DLY, SLV0's pacing above 1 kHz; then poll
    I2C_MST_STATUS for SLV4_DONE, failing on SLV4_NACK or a time-out): check WIA =
    0x48, CNTL2 = SRST, CNTL1 = fuse ROM, read ASAX/Y/Z, CNTL1 = power-down, wait 100 µs,
    with the self-test ASTC = SELF, CNTL1 = 0x18 (self-test, 16-bit), SLV0 reads HXL..ST2,
    wait 9 ms and two sample periods, read them (EXT_SENS_DATA), judge, ASTC = 0, wait 100 µs;
    CNTL1 = 0x16 (continuous 100 Hz, 16-bit); then SLV0 reads 8 bytes from ST1 every sample
    (above 1 kHz every n-th sample, without WAIT_FOR_ES: ``MPU9250Config.aux_every``);
    INT_PIN_CFG; INT_ENABLE = RAW_RDY.

    I2C wiring: the same without I2C_IF_DIS, and with the AK8963 reached directly at 0x0C
    after INT_PIN_CFG.BYPASS_EN (I2C master off; its self-test result read directly).

Failures (the whole catalogue, with detection times: ``hdl/FAULTS.md``): a wrong WHO_AM_I or
an MPU9250 that does not acknowledge (I2C) sets a flag and restarts from the power-up wait (the
retry delay), and each restart doubles the wait after H_RESET, up to four times the datasheet's
(``BACKOFF_MAX_SHIFT``: a part slower than its datasheet is brought up by a later retry instead
of being reset again too early for ever; back to one time once streaming); so do no interrupt
within the time-out and ``BAD_BURST_LIMIT`` sample bursts in a row that fail their checks (a
stuck data line, a read that fails on the bus, a gyro jump no motion makes: a flipped bit). A
sample that came too early (the part runs faster than configured) has the configuration
written again, without a restart. A magnetometer
failure (NACK, wrong WIA, SLV4 time-out) sets its flag and skips the rest of the magnetometer
set-up: accel/gyro samples flow on with ``mag_valid`` = 0. While streaming, a magnetometer that
gives no new field for ``mag_timeout_s`` is flagged stale and set up again between samples
(that set-up leaves the interrupt's alone: an MPU9250 reset meanwhile stays silent, for the INT
time-out to find).

Streaming: on each rising edge of the active INT level, read INT_STATUS through GYRO_ZOUT_L and
the eight AK8963 bytes (ST1..ST2): one fast SPI burst of 23 bytes from INT_STATUS (SPI wiring:
they sit in EXT_SENS_DATA_00..07), or two I2C reads (I2C wiring). Reading INT_STATUS clears a
latched interrupt; reading ST2 releases the AK8963's data registers.

Read levelling (SPI wiring, where the SPI controller has a trained rate: ``SensorFrontEnd``,
issue #58): as streaming begins, a ``ReadLeveller`` scans the trained rate's sample delays and
the reader waits for it (about 0.5 ms at 48 MHz); if it found an eye the bursts go at the
trained rate, and after each the leveller checks the delays a cycle either side. A guard that
reads wrong or a trained burst that fails its checks falls back to the safe rate at once
(``level.fallbacks`` counts), and the scan runs again ``DriverTiming.retrain_s`` later (in bursts
read), as after a scan that found none. ``level`` (``ReadLevelStatus``) is the board register
SPI_TRAINING.

Two blocks share the register port: the bring-up sequencer (``hdl/sensor/bring_up_sequencer.py``:
the program, one step at a time) and the sample reader (``hdl/sensor/sample_reader.py``: a burst per
data-ready edge, its checks, the sample). The reader asks the sequencer for a restart (no
data-ready, bad bursts) or for the magnetometer's part again (no new field); the sequencer runs
that beside the samples, a command at a time, so the accel/gyro samples never stop for it.
"""

import math
from dataclasses import dataclass
from typing import Optional, Tuple

from amaranth import *
from amaranth.lib import data, stream, wiring
from amaranth.lib.wiring import In, Out, connect, flipped

from ..contract import ak8963_regs as A
from ..contract import mpu9250_regs as R
from .bring_up_sequencer import BringUpSequencer, Fail, Op, SelfTestWaits, Step, bring_up_program
from .self_test import SelfTest
from ..primitives.clocking import cycles
from .register_port import RegisterPortSignature
from .sample_store import SLOTS, SampleStoreWriteSignature
from .register_port_arbiter import RegisterPortArbiter
from .driver_status import DriverStatus, ReadLevelStatus, SelfTestStatus
from .read_leveller import ReadLeveller
from .sample import Sample
from .data_ready_timer import tick_cycles
from .sample_reader import (BAD_BURST_LIMIT, MPU_BYTES, SAMPLE_BYTES, SampleReader,
                            burst_is_plausible, gyro_jump_limit)


__all__ = ["MPU9250Config", "DriverTiming", "Op", "Fail", "Step", "bring_up_program",
           "MPU9250Driver", "driver_members", "BAD_BURST_LIMIT", "burst_is_plausible",
           "SAMPLE_BYTES", "MPU_BYTES"]


@dataclass(frozen=True)
class MPU9250Config:
    """Elaboration-time sensor configuration."""
    gyro_fs_dps: int = 2000
    accel_fs_g: int = 16
    dlpf_cfg: int = 1               # CONFIG.DLPF_CFG: 184 Hz gyro bandwidth, 1 kHz internal
    accel_dlpf_cfg: int = 1         # ACCEL_CONFIG2.A_DLPF_CFG (ACCEL_FCHOICE_B = 0)
    smplrt_div: int = 0             # output rate = 1 kHz / (1 + div) with DLPF_CFG 1..6
    int_latched: bool = True        # INT held until INT_STATUS is read, else a 50 µs pulse
    int_active_low: bool = False
    accepted_who_am_i: Tuple[int, ...] = (R.WHO_AM_I_MPU9250, R.WHO_AM_I_MPU9255)
    magnetometer: bool = True       # bring the AK8963 up and read it every sample
    wiring: str = "spi"             # "spi" or "i2c"
    i2c_address: int = R.MPU9250_I2C_ADDRESS    # 0x68, or 0x69 with AD0 high (I2C wiring)
    self_test: bool = True          # both parts' self-tests at bring-up (hdl/sensor/self_test.py)
    self_test_samples: int = 128    # samples summed with self-test off and on (a power of 2)

    def __post_init__(self):
        R.gyro_config(self.gyro_fs_dps)
        R.accel_config(self.accel_fs_g)
        for name, top in (("dlpf_cfg", 7), ("accel_dlpf_cfg", 7), ("smplrt_div", 255)):
            if not 0 <= getattr(self, name) <= top:
                raise ValueError(f"MPU9250Config.{name} must be 0..{top}")
        if not self.accepted_who_am_i:
            raise ValueError("MPU9250Config.accepted_who_am_i cannot be empty")
        if self.wiring not in ("spi", "i2c"):
            raise ValueError(f"MPU9250Config.wiring must be 'spi' or 'i2c', not {self.wiring!r}")
        if self.i2c_address not in (0x68, 0x69):
            raise ValueError("MPU9250Config.i2c_address must be 0x68 or 0x69")
        n = self.self_test_samples
        if not (1 <= n <= 256 and n & (n - 1) == 0):
            raise ValueError("MPU9250Config.self_test_samples must be a power of 2, 1..256")

    @classmethod
    def for_odr(cls, odr_hz, **kwargs):
        """The configuration for an output rate of ``odr_hz``: 8000 (DLPF_CFG 0: 250 Hz gyro
        bandwidth, no divider; the accelerometer still updates at 1 kHz, its 4 kHz mode needs
        ACCEL_FCHOICE_B, which this driver leaves at 0), or 1000 / n for n = 1..256 (internal
        1 kHz, SMPLRT_DIV = n − 1, gyro and accelerometer DLPF the widest of 184, 92, 41, 20,
        10, 5 Hz below half the rate)."""
        if odr_hz == 8000:
            return cls(dlpf_cfg=0, accel_dlpf_cfg=1, smplrt_div=0, **kwargs)
        div = 1000 / odr_hz - 1 if odr_hz > 0 else -1
        if div < 0 or div > 255 or abs(div - round(div)) > 1e-9:
            raise ValueError(f"the MPU9250 offers 8000 Hz or 1000/n Hz (n = 1..256), not "
                             f"{odr_hz:g} Hz")
        bandwidths = {1: 184, 2: 92, 3: 41, 4: 20, 5: 10, 6: 5}
        dlpf = next((k for k, bw in bandwidths.items() if bw < odr_hz / 2), 6)
        return cls(dlpf_cfg=dlpf, accel_dlpf_cfg=dlpf, smplrt_div=int(round(div)), **kwargs)

    @property
    def output_data_rate(self):
        return R.output_data_rate(self.dlpf_cfg, R.gyro_config(self.gyro_fs_dps), self.smplrt_div)

    @property
    def aux_every(self):
        """Samples per read of the AK8963 by the MPU9250's I2C master (SPI wiring). Reading its
        eight bytes at 400 kHz takes about 0.25 ms: at up to 1 kHz that fits a sample period
        and happens every sample, with WAIT_FOR_ES; faster, the read is paced to every n-th
        sample, n = ODR / 1 kHz (I2C_MST_DLY, still ten times the AK8963's 100 Hz), and
        WAIT_FOR_ES is off so that data-ready is never held back (DELAY_ES_SHADOW keeps the
        bytes whole instead)."""
        return max(1, math.ceil(self.output_data_rate / 1000 - 1e-9))

    @property
    def int_pin_cfg(self):
        return ((R.INT_PIN_CFG_LATCH_INT_EN if self.int_latched else 0) |
                (R.INT_PIN_CFG_ACTL if self.int_active_low else 0) |
                (R.INT_PIN_CFG_BYPASS_EN if self.wiring == "i2c" else 0))

    def sensor_writes(self):
        """(register, value) that set the accel/gyro up, written after the WHO_AM_I check."""
        return [
            (R.PWR_MGMT_2, 0x00),
            (R.CONFIG, self.dlpf_cfg),
            (R.SMPLRT_DIV, self.smplrt_div),
            (R.GYRO_CONFIG, R.gyro_config(self.gyro_fs_dps)),
            (R.ACCEL_CONFIG, R.accel_config(self.accel_fs_g)),
            (R.ACCEL_CONFIG2, self.accel_dlpf_cfg),
        ]


# The I2C master's read of the AK8963 at each sample (SPI wiring), in bit times: START, the
# address and register bytes, a repeated START, the address again, ST1..ST2, STOP
AK8963_READ_BITS = 1 + 9 + 9 + 1 + 9 + 9 * A.SAMPLE_BYTES + 1
# an SLV4 transfer: start, address, register, (repeated start, address,) the byte, stop
SLV4_BITS = 1 + 9 + 9 + 1 + 9 + 9 + 1


@dataclass(frozen=True)
class DriverTiming:
    """Real-time waits of the driver, converted to cycles at elaboration.

    ``time_scale`` multiplies the power-up and reset waits (simulations use ≪ 1; the sensor
    model's delays must be scaled alike). ``int_timeout_s`` is used as given; ``None`` means
    ``stream_timeout_periods`` sample periods plus 50 ms (times ``time_scale``) for the gyro
    to wake. It also bounds each SLV4 poll.
    ``mag_power_down_s`` is the AK8963's power-down wait (not scaled). ``sample_period_s`` is
    the sensor's sample period the driver measures data-ready intervals against (``None``:
    1/ODR; simulations that compress the sensor's period give it here). Once samples flow, the
    interrupt time-out is ``stream_timeout_periods`` sample periods. ``mag_timeout_s`` is how
    long the magnetometer may go without a new field before it is flagged stale and set up
    again (three periods of the AK8963's 100 Hz; simulations scale it with the period).
    ``retrain_s``: the wait, after a fall from the trained SPI rate or a scan that found no
    eye, before the read levelling scans again (``retrain_periods``; simulations scale it).
    """
    power_up_s: float = 0.100
    reset_s: float = 0.100
    int_timeout_s: Optional[float] = None
    time_scale: float = 1.0
    mag_power_down_s: float = 100e-6
    sample_period_s: Optional[float] = None
    stream_timeout_periods: int = 4
    mag_timeout_s: float = 0.030
    self_test_settle_s: float = 0.020
    mag_self_test_s: float = 0.009
    retrain_s: float = 1.0

    def retrain_periods(self, config):
        """``retrain_s`` in whole sample periods (at least two): how long after a fall from the
        trained rate (or a scan that found no eye) the read levelling scans again (counted in
        the bursts read: one a period while streaming)."""
        return max(2, math.ceil(self.retrain_s / self.period_s(config) - 1e-9))

    def period_s(self, config):
        return self.sample_period_s or 1 / config.output_data_rate

    def period_cycles(self, clk_freq, config):
        return cycles(self.period_s(config), clk_freq, minimum=2)

    def drdy_jitter_cycles(self, clk_freq, config):
        """How much sooner than one period after the last a data-ready edge may come from a
        part that keeps its rate (``SampleReader``'s allowance before ``rate_error``): with
        WAIT_FOR_ES (SPI wiring with the magnetometer, up to 1 kHz) the edge waits for the I2C
        master's read of the AK8963, ``AK8963_READ_BITS`` at 400 kHz (0.26 ms: a quarter of a
        1 kHz period), which ends at once when the AK8963 does not answer. Scaled as the
        period is (a simulation compresses the I2C master's transfers alike). 0 otherwise."""
        if config.wiring != "spi" or not config.magnetometer or config.aux_every != 1:
            return 0
        return self._aux_bits_cycles(AK8963_READ_BITS, clk_freq, config)

    def aux_idle_cycles(self, clk_freq, config):
        """The longest cycle of the MPU9250's I2C master as bring-up sets it (SPI wiring):
        SLV0's read of the AK8963 and an SLV4 transfer (``SLV4_BITS``) at 400 kHz, scaled as
        the period is; at least the AK8963's power-down wait. A magnetometer set-up waits it
        out before it clears I2C_MST_STATUS (``bring_up_program``)."""
        return max(self._aux_bits_cycles(AK8963_READ_BITS + SLV4_BITS, clk_freq, config),
                   cycles(self.mag_power_down_s, clk_freq))

    def _aux_bits_cycles(self, bits, clk_freq, config):
        """``bits`` on the MPU9250's auxiliary I2C bus at the clock bring-up sets
        (I2C_MST_CTRL's I2C_MST_CLK_400KHZ), in cycles, scaled as the period is (a simulation
        compresses the I2C master's transfers alike)."""
        scale = self.period_s(config) * config.output_data_rate
        hz = R.I2C_MST_CLK_KHZ[R.I2C_MST_CLK_400KHZ] * 1e3
        return cycles(bits / hz * scale, clk_freq)

    def int_timeout(self, config):
        """The data-ready time-out before the first sample, in seconds."""
        if self.int_timeout_s is not None:
            return self.int_timeout_s
        return self.stream_timeout_periods * self.period_s(config) + 0.050 * self.time_scale

    def cycles(self, clk_freq, config):
        timeout = self.int_timeout(config)
        return (cycles(self.power_up_s * self.time_scale, clk_freq),
                cycles(self.reset_s * self.time_scale, clk_freq), cycles(timeout, clk_freq))

    def self_test_waits(self, clk_freq, config):
        """The self-test's waits (``SelfTestWaits``), scaled as the sensor's period is: its
        1 kHz reads with the MPU9250's period, the AK8963's 9 ms too (a simulation compresses
        both parts' times alike), its 20 ms settling with ``time_scale`` (at least two 1 kHz
        periods); SPI wiring: two sample periods
        more for the MPU9250's I2C master, which reads the AK8963 at its sample ticks."""
        scale = self.period_s(config) * config.output_data_rate
        mag = self.mag_self_test_s * scale
        if config.wiring == "spi":
            mag += 2 * self.period_s(config)    # SLV0 fetches it at a sample tick
        # the filters' settling is scaled like the other start-up waits (``time_scale``), but
        # never under two samples: the new response must be in the registers
        settle = max(self.self_test_settle_s * self.time_scale, 2 * scale / 1000)
        return SelfTestWaits(settle=cycles(settle, clk_freq),
                             interval=cycles(scale / 1000, clk_freq),
                             mag=cycles(mag, clk_freq))

    def mag_timeout_periods(self, config):
        """``mag_timeout_s`` in whole sample periods (at least two)."""
        return max(2, math.ceil(self.mag_timeout_s / self.period_s(config) - 1e-9))


def driver_members():
    """The driver's ports towards the sensor's INT pin and downstream, which the sensor front
    end passes on unchanged: ``int_pin``, ``samples``, ``status``, ``asa``, ``early_sample``
    (a pulse per sample that came early, ``DriverStatus.rate_error``: the board counts them in
    RATE_ERRORS), ``who_am_i`` (8: the last WHO_AM_I value read), ``self_test``
    (``SelfTestStatus``), and the sample store's write port and the offered sample's slot
    (``store``, ``sample_slot``: ``SampleReader``, ``hdl/sensor/sample_store.py``), the early
    start's ``imu_ready`` (``SampleReader``: the next sample's gyro and accelerometer are in its
    slot, its field still coming), the reader's free-running ``tick`` (``tick_cycles``), and
    the read levelling's status (``level``, ``ReadLevelStatus``)."""
    return {"int_pin": In(1), "samples": Out(stream.Signature(Sample)),
            "status": Out(DriverStatus), "asa": Out(data.ArrayLayout(8, 3)),
            "early_sample": Out(1), "who_am_i": Out(8), "self_test": Out(SelfTestStatus),
            "store": Out(SampleStoreWriteSignature()), "sample_slot": Out(range(SLOTS)),
            "imu_ready": Out(1), "tick": Out(1), "level": Out(ReadLevelStatus)}


class MPU9250Driver(wiring.Component):
    """See the module docstring. Parameters: ``clk_freq``, ``config`` (``MPU9250Config``),
    ``timing`` (``DriverTiming``). Members: ``port``, ``int_pin``, ``samples``, ``status``,
    ``asa``; and at elaboration time ``program`` (the bring-up steps), ``power_up_cycles``,
    ``reset_cycles``, ``timeout_cycles``, ``stream_timeout_cycles``, ``period_cycles``,
    ``mag_timeout_periods``.

    Inside: a ``BringUpSequencer`` and a ``SampleReader`` share the register port through a
    ``RegisterPortArbiter`` (the reader first, a command at a time); with ``max_sample_delay``
    (the SPI controller's trained rate: ``SPITiming.with_trained``) a ``ReadLeveller`` too,
    between the two (a second arbiter), and the member ``sample_delay`` (out) for the SPI
    controller: the leveller's own delay for its reads, the chosen one for everyone else's.

    Latency: a sample leaves the driver a few cycles after its burst ends
    (``sensor_frontend.sample_read_cycles`` bounds data-ready to sample); while the magnetometer
    is set up again, one sequencer command (at most a slow two-byte transaction) may come first.
    Throughput: one sample per data-ready interrupt; the stream never waits on ``ready``.
    """
    def __init__(self, *, clk_freq, config=MPU9250Config(), timing=DriverTiming(),
                 max_sample_delay=None):
        self.clk_freq = clk_freq
        # read levelling (issue #58): the SPI controller has a trained rate with these delays
        self.max_sample_delay = max_sample_delay if config.wiring == "spi" else None
        self.config = config
        self.timing = timing
        self.power_up_cycles, self.reset_cycles, self.timeout_cycles = \
            timing.cycles(clk_freq, config)
        self.mag_wait_cycles = cycles(timing.mag_power_down_s, clk_freq)
        self.period_cycles = timing.period_cycles(clk_freq, config)
        self.stream_timeout_cycles = timing.stream_timeout_periods * self.period_cycles
        self.mag_timeout_periods = timing.mag_timeout_periods(config)
        self.program = bring_up_program(config, self.power_up_cycles, self.reset_cycles,
                                        self.mag_wait_cycles,
                                        timing.self_test_waits(clk_freq, config),
                                        aux_idle_cycles=timing.aux_idle_cycles(clk_freq, config))
        self.self_test_block = (SelfTest(samples_log2=config.self_test_samples.bit_length() - 1)
                                if config.self_test else None)
        # made here, not in ``elaborate``, so that ``report`` finds its program ROM
        # its timer counts the sample reader's ticks (its prescaler, free-running)
        self.sequencer = BringUpSequencer(
            self.program, accepted_who_am_i=config.accepted_who_am_i,
            poll_cycles=self.timeout_cycles, tick_cycles=tick_cycles(self.period_cycles))
        levelling = ({"sample_delay": Out(range(max_sample_delay + 1))}
                     if self.max_sample_delay is not None else {})
        super().__init__({"port": Out(RegisterPortSignature().flip()), **driver_members(),
                          **levelling})

    def elaborate(self, platform):
        m = Module()
        cfg = self.config
        m.submodules.sequencer = seq = self.sequencer
        m.submodules.reader = reader = SampleReader(
            wiring=cfg.wiring, int_active_low=cfg.int_active_low, int_latched=cfg.int_latched,
            gyro_jump=gyro_jump_limit(cfg.gyro_fs_dps),
            magnetometer=cfg.magnetometer, period_cycles=self.period_cycles,
            drdy_jitter_cycles=self.timing.drdy_jitter_cycles(self.clk_freq, cfg),
            first_timeout_cycles=self.timeout_cycles, timeout_cycles=self.stream_timeout_cycles,
            mag_timeout_periods=self.mag_timeout_periods)
        m.submodules.arbiter = arbiter = RegisterPortArbiter()
        connect(m, reader.port, arbiter.first)
        connect(m, arbiter.port, flipped(self.port))
        enable = seq.streaming
        start = seq.started
        if self.max_sample_delay is not None:
            enable, start = self._levelling(m, seq, reader, arbiter)
        else:
            connect(m, seq.port, arbiter.second)
        connect(m, reader.samples, flipped(self.samples))
        connect(m, reader.store, flipped(self.store))
        m.d.comb += [seq.tick.eq(reader.tick), self.tick.eq(reader.tick)]
        m.d.comb += [self.sample_slot.eq(reader.sample_slot),
                     self.imu_ready.eq(reader.imu_ready)]
        status = self.status
        if cfg.self_test:
            m.submodules.self_test = st = self.self_test_block
            m.d.comb += [st.i.eq(seq.test), st.asa.eq(seq.asa), seq.test_busy.eq(st.busy),
                         self.self_test.eq(st.status), status.self_test_fail.eq(st.status.fail)]
        m.d.comb += [
            reader.int_pin.eq(self.int_pin),
            reader.enable.eq(enable), reader.start.eq(start),
            reader.restarted.eq(seq.restarted), reader.mag_ok.eq(seq.mag_ok),
            reader.mag_setup.eq(seq.mag_setup),
            seq.restart.eq(reader.restart), seq.mag_lost.eq(reader.mag_lost),
            seq.reconfigure.eq(reader.reconfigure), self.early_sample.eq(reader.reconfigure),
            status.rate_error.eq(reader.rate_error),
            seq.mag_nack.eq(reader.mag_nack),
            self.asa.eq(seq.asa),
            status.streaming.eq(seq.streaming), status.whoami_error.eq(seq.whoami_error),
            status.no_response.eq(seq.no_response | reader.read_error),
            status.int_timeout.eq(reader.int_timeout), status.restarts.eq(seq.restarts),
            status.spi_trained.eq(self.level.trained),
            self.who_am_i.eq(seq.who_am_i), status.mag_ok.eq(seq.mag_ok),
            status.mag_absent.eq(seq.mag_absent), status.mag_wia_error.eq(seq.mag_wia_error),
            status.mag_stale.eq(reader.mag_stale), status.bad_burst.eq(reader.bad_burst),
        ]
        return m

    def _levelling(self, m, seq, reader, arbiter):
        """The read levelling (issue #58): a ``ReadLeveller`` beside the sequencer (behind the
        reader), the sample delay the SPI controller uses, the fall back to the safe rate and
        the scans again. Returns the reader's ``enable`` and ``start``: held until the first
        scan after streaming began has ended (so that every sample is read at the rate
        chosen)."""
        m.submodules.leveller = lev = ReadLeveller(max_sample_delay=self.max_sample_delay)
        m.submodules.inner = inner = RegisterPortArbiter()
        connect(m, lev.port, inner.first)
        connect(m, seq.port, inner.second)
        connect(m, inner.port, arbiter.second)
        # the leveller's own trained reads at its tap; everyone else's at the delay chosen
        own = arbiter.second_owns & ~inner.second_owns
        m.d.comb += self.sample_delay.eq(Mux(own, lev.sample_delay, lev.centre))

        status = self.level
        trained = status.trained
        scanned = Signal()                  # the first scan since streaming began has ended
        scanning = Signal()                 # the leveller's task is a scan (not a check)
        started = Signal()                  # the reader starts now
        check_due = Signal()                # a burst was read trained: check the guards
        # the wait before a scan again, in bursts read (one a sample period while streaming;
        # none, no need)
        wait = self.timing.retrain_periods(self.config)
        retrain = Signal(range(wait + 1))
        fallback = Signal()
        m.d.comb += [reader.trained.eq(trained),
                     status.sample_delay.eq(lev.centre), status.first.eq(lev.first),
                     status.last.eq(lev.last), status.scanned.eq(scanned)]
        with m.If((retrain != 0) & reader.burst_done):
            m.d.sync += retrain.eq(retrain - 1)
        idle = ~lev.busy & ~lev.done
        with m.If(seq.started | (idle & seq.streaming & scanned & ~trained & (retrain == 0))):
            # at the start of streaming; again a while after a fall back or a scan that found
            # no eye (the bursts go on at the safe rate meanwhile)
            m.d.comb += lev.start.eq(1)
            m.d.sync += [scanning.eq(1), trained.eq(0), check_due.eq(0)]
        with m.Elif(idle & check_due & trained):
            m.d.comb += lev.check.eq(1)
            m.d.sync += [scanning.eq(0), check_due.eq(0)]
        with m.If(lev.done & scanning):
            m.d.sync += [trained.eq(lev.trained), scanned.eq(1), scanning.eq(0)]
            m.d.comb += started.eq(~scanned & seq.streaming)
            with m.If(~lev.trained):
                m.d.sync += retrain.eq(wait)
        # a burst read at the trained rate: its guards are checked after it; one that failed
        # its checks, or a guard that read wrong, falls back to the safe rate at once
        with m.If(reader.burst_done & trained):
            m.d.sync += check_due.eq(1)
        m.d.comb += fallback.eq(trained & (reader.trained_failed |
                                           (lev.done & ~scanning & lev.check_failed)))
        with m.If(fallback):
            m.d.sync += [trained.eq(0), check_due.eq(0), retrain.eq(wait),
                         status.fallbacks.eq(status.fallbacks + (status.fallbacks != 255))]
        with m.If(~seq.streaming):
            m.d.sync += [scanned.eq(0), trained.eq(0), check_due.eq(0)]
        return seq.streaming & scanned, started
