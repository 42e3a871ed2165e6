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
        sensitivity adjustment values, valid once ``status.mag_ok``). See ``hdl/sample.py``.

Bring-up is a program (``bring_up_program``) run by a small sequencer: register writes, checked
reads, stored reads, status polls and waits, each with what to do on failure. The sequence is the
one well-known drivers use:

    SPI wiring: wait power-up; USER_CTRL = I2C_IF_DIS; PWR_MGMT_1 = H_RESET; wait reset;
    USER_CTRL = I2C_IF_DIS (H_RESET cleared it); PWR_MGMT_1 = CLKSEL 1; check WHO_AM_I;
    PWR_MGMT_2, CONFIG, SMPLRT_DIV, GYRO_CONFIG, ACCEL_CONFIG, ACCEL_CONFIG2;
    magnetometer through the MPU9250's I2C master: USER_CTRL |= I2C_MST_EN, I2C_MST_CTRL =
    WAIT_FOR_ES | 400 kHz; each AK8963 access is a single SLV4 transfer (SLV4_ADDR/REG/DO/CTRL,
    then poll I2C_MST_STATUS for SLV4_DONE, failing on SLV4_NACK or a time-out): check WIA =
    0x48, CNTL2 = SRST, CNTL1 = fuse ROM, read ASAX/Y/Z, CNTL1 = power-down, wait 100 µs,
    CNTL1 = 0x16 (continuous 100 Hz, 16-bit); then SLV0 reads 8 bytes from ST1 every sample
    (above 1 kHz every n-th sample, without WAIT_FOR_ES: ``MPU9250Config.aux_every``);
    INT_PIN_CFG; INT_ENABLE = RAW_RDY.

    I2C wiring: the same without I2C_IF_DIS, and with the AK8963 reached directly at 0x0C
    after INT_PIN_CFG.BYPASS_EN (I2C master off).

Failures: a wrong WHO_AM_I or an MPU9250 that does not acknowledge (I2C) sets a flag and
restarts from the power-up wait (the retry delay); no interrupt within ``int_timeout_s`` does
the same. A magnetometer failure (NACK, wrong WIA, SLV4 time-out) sets its flag and skips the
rest of the magnetometer set-up: accel/gyro samples flow on with ``mag_valid`` = 0.

Streaming: on each rising edge of the active INT level, read INT_STATUS through GYRO_ZOUT_L and
the eight AK8963 bytes (ST1..ST2): one fast SPI burst of 23 bytes from INT_STATUS (SPI wiring:
they sit in EXT_SENS_DATA_00..07), or two I2C reads (I2C wiring). Reading INT_STATUS clears a
latched interrupt; reading ST2 releases the AK8963's data registers.
"""

import math
from dataclasses import dataclass
from typing import Optional, Tuple

from amaranth import *
from amaranth.lib import data, enum, stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from . import ak8963_regs as A
from .clocking import cycles
from . import mpu9250_regs as R
from .register_port import RegisterPortSignature
from .sample import DriverStatus, Sample


__all__ = ["MPU9250Config", "DriverTiming", "Op", "Fail", "Step", "bring_up_program",
           "MPU9250Driver"]


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


@dataclass(frozen=True)
class DriverTiming:
    """Real-time waits of the driver, converted to cycles at elaboration.

    ``time_scale`` multiplies the power-up and reset waits (simulations use ≪ 1; the sensor
    model's delays must be scaled alike). ``int_timeout_s`` is used as given; ``None`` means
    four output sample periods plus 50 ms for the gyro to wake. It also bounds each SLV4 poll.
    ``mag_power_down_s`` is the AK8963's power-down wait (not scaled). ``sample_period_s`` is
    the sensor's sample period the driver measures data-ready intervals against (``None``:
    1/ODR; simulations that compress the sensor's period give it here).
    """
    power_up_s: float = 0.100
    reset_s: float = 0.100
    int_timeout_s: Optional[float] = None
    time_scale: float = 1.0
    mag_power_down_s: float = 100e-6
    sample_period_s: Optional[float] = None

    def period_cycles(self, clk_freq, config):
        period = self.sample_period_s or 1 / config.output_data_rate
        return cycles(period, clk_freq, minimum=2)

    def cycles(self, clk_freq, config):
        timeout = self.int_timeout_s
        if timeout is None:
            timeout = 4 / config.output_data_rate + 0.050
        return (cycles(self.power_up_s * self.time_scale, clk_freq),
                cycles(self.reset_s * self.time_scale, clk_freq), cycles(timeout, clk_freq))


class Op(enum.Enum, shape=3):
    WAIT   = 0      # arg cycles
    WRITE  = 1      # reg <- value
    CHECK  = 2      # read reg; must be one of the check's values
    STORE  = 3      # read reg into asa[value]
    POLL   = 4      # read reg until (byte & value) != 0; fails on (byte & mask) or time-out
    MARK   = 5      # status.mag_ok <- 1
    STREAM = 6


class Fail(enum.Enum, shape=1):
    RESTART = 0     # MPU9250 problem: flag it and run the program again from the start
    MAG     = 1     # magnetometer problem: flag it and jump to the end of the magnetometer part


@dataclass(frozen=True)
class Step:
    op: Op
    device: int = 0             # 0 = MPU9250, 1 = AK8963 directly (I2C wiring)
    reg: int = 0
    value: int = 0
    mask: int = 0
    wait: int = 0
    fail: Fail = Fail.RESTART
    check: str = ""             # "who_am_i" or "wia"


def bring_up_program(config, power_up_cycles, reset_cycles, mag_wait_cycles):
    """The bring-up sequence for ``config.wiring``, as a list of ``Step`` (the driver's ROM)."""
    spi = config.wiring == "spi"
    steps = [Step(Op.WAIT, wait=power_up_cycles)]
    if spi:
        steps.append(Step(Op.WRITE, reg=R.USER_CTRL, value=R.USER_CTRL_I2C_IF_DIS))
    steps += [Step(Op.WRITE, reg=R.PWR_MGMT_1, value=R.PWR_MGMT_1_H_RESET),
              Step(Op.WAIT, wait=reset_cycles)]
    if spi:
        steps.append(Step(Op.WRITE, reg=R.USER_CTRL, value=R.USER_CTRL_I2C_IF_DIS))
    steps += [Step(Op.WRITE, reg=R.PWR_MGMT_1, value=R.PWR_MGMT_1_CLKSEL_AUTO),
              Step(Op.CHECK, reg=R.WHO_AM_I, check="who_am_i")]
    steps += [Step(Op.WRITE, reg=reg, value=value) for reg, value in config.sensor_writes()]

    if config.magnetometer:
        mag = []

        def mag_write(reg, value):
            if spi:
                mag.extend([Step(Op.WRITE, reg=R.I2C_SLV4_ADDR, value=A.I2C_ADDRESS),
                            Step(Op.WRITE, reg=R.I2C_SLV4_REG, value=reg),
                            Step(Op.WRITE, reg=R.I2C_SLV4_DO, value=value),
                            Step(Op.WRITE, reg=R.I2C_SLV4_CTRL, value=R.I2C_SLV_EN),
                            Step(Op.POLL, reg=R.I2C_MST_STATUS, value=R.I2C_MST_STATUS_SLV4_DONE,
                                 mask=R.I2C_MST_STATUS_SLV4_NACK, fail=Fail.MAG)])
            else:
                mag.append(Step(Op.WRITE, device=1, reg=reg, value=value, fail=Fail.MAG))

        def mag_read(op, reg, **kw):
            if spi:
                mag.extend([Step(Op.WRITE, reg=R.I2C_SLV4_ADDR,
                                 value=R.I2C_SLV_RNW | A.I2C_ADDRESS),
                            Step(Op.WRITE, reg=R.I2C_SLV4_REG, value=reg),
                            Step(Op.WRITE, reg=R.I2C_SLV4_CTRL, value=R.I2C_SLV_EN),
                            Step(Op.POLL, reg=R.I2C_MST_STATUS, value=R.I2C_MST_STATUS_SLV4_DONE,
                                 mask=R.I2C_MST_STATUS_SLV4_NACK, fail=Fail.MAG),
                            Step(op, reg=R.I2C_SLV4_DI, fail=Fail.MAG, **kw)])
            else:
                mag.append(Step(op, device=1, reg=reg, fail=Fail.MAG, **kw))

        if spi:
            wait_es = R.I2C_MST_CTRL_WAIT_FOR_ES if config.aux_every == 1 else 0
            mag += [Step(Op.WRITE, reg=R.USER_CTRL,
                         value=R.USER_CTRL_I2C_IF_DIS | R.USER_CTRL_I2C_MST_EN),
                    Step(Op.WRITE, reg=R.I2C_MST_CTRL, value=wait_es | R.I2C_MST_CLK_400KHZ)]
        else:
            mag += [Step(Op.WRITE, reg=R.USER_CTRL, value=0x00),
                    Step(Op.WRITE, reg=R.INT_PIN_CFG, value=R.INT_PIN_CFG_BYPASS_EN)]
        mag_read(Op.CHECK, A.WIA, check="wia")
        mag_write(A.CNTL2, A.CNTL2_SRST)
        mag_write(A.CNTL1, A.MODE_FUSE_ROM)
        for axis in range(3):
            mag_read(Op.STORE, A.ASAX + axis, value=axis)
        mag_write(A.CNTL1, A.MODE_POWER_DOWN)
        mag.append(Step(Op.WAIT, wait=mag_wait_cycles))
        mag_write(A.CNTL1, A.CNTL1_BIT_16 | A.MODE_CONT_100HZ)
        if spi:
            mag += [Step(Op.WRITE, reg=R.I2C_SLV_ADDR[0], value=R.I2C_SLV_RNW | A.I2C_ADDRESS),
                    Step(Op.WRITE, reg=R.I2C_SLV_ADDR[0] + 1, value=A.ST1),
                    Step(Op.WRITE, reg=R.I2C_SLV_ADDR[0] + 2,
                         value=R.I2C_SLV_EN | A.SAMPLE_BYTES)]
            if config.aux_every > 1:
                mag += [Step(Op.WRITE, reg=R.I2C_SLV4_CTRL, value=config.aux_every - 1),
                        Step(Op.WRITE, reg=R.I2C_MST_DELAY_CTRL,
                             value=R.I2C_MST_DELAY_CTRL_DELAY_ES_SHADOW |
                             R.I2C_MST_DELAY_CTRL_SLV0_DLY_EN)]
        mag.append(Step(Op.MARK))
        steps += mag

    steps += [Step(Op.WRITE, reg=R.INT_PIN_CFG, value=config.int_pin_cfg),
              Step(Op.WRITE, reg=R.INT_ENABLE, value=R.INT_ENABLE_RAW_RDY),
              Step(Op.STREAM)]
    return steps


SAMPLE_BYTES = 1 + R.SENSOR_BYTES + A.SAMPLE_BYTES   # INT_STATUS, accel/temp/gyro, ST1..ST2
_MPU_BYTES = 1 + R.SENSOR_BYTES


class MPU9250Driver(wiring.Component):
    def __init__(self, *, clk_freq, config=MPU9250Config(), timing=DriverTiming()):
        self.clk_freq = clk_freq
        self.config = config
        self.timing = timing
        self.power_up_cycles, self.reset_cycles, self.timeout_cycles = \
            timing.cycles(clk_freq, config)
        self.mag_wait_cycles = cycles(timing.mag_power_down_s, clk_freq)
        self.period_cycles = timing.period_cycles(clk_freq, config)
        self.program = bring_up_program(config, self.power_up_cycles, self.reset_cycles,
                                        self.mag_wait_cycles)
        super().__init__({
            "port": Out(RegisterPortSignature().flip()),
            "int_pin": In(1),
            "samples": Out(stream.Signature(Sample)),
            "status": Out(DriverStatus),
            "asa": Out(data.ArrayLayout(8, 3)),
        })

    def elaborate(self, platform):
        m = Module()
        cfg = self.config
        program = self.program
        skip_mag = next((i for i, s in enumerate(program) if s.op == Op.MARK), 0) + 1

        # -- program ROM --------------------------------------------------------------------------
        pc = Signal(range(len(program)))
        step_layout = data.StructLayout({
            "op": Op, "device": 1, "reg": 8, "value": 8, "mask": 8, "fail": Fail,
            "check_wia": 1, "wait": range(max(s.wait for s in program) + 1)})
        step = Signal(step_layout)
        with m.Switch(pc):
            for index, s in enumerate(program):
                with m.Case(index):
                    m.d.comb += step.eq(step_layout.const({
                        "op": s.op, "device": s.device, "reg": s.reg, "value": s.value,
                        "mask": s.mask, "fail": s.fail, "check_wia": s.check == "wia",
                        "wait": s.wait}))

        # -- register commands --------------------------------------------------------------------
        port = self.port
        # reset-less: a sample is only read once all its bytes are in
        buf = Array(Signal(8, name=f"rx{i}", reset_less=True) for i in range(SAMPLE_BYTES))
        rx_index = Signal(range(SAMPLE_BYTES + 1))
        m.d.comb += [port.rx.ready.eq(1), port.rsp.ready.eq(1)]
        with m.If(port.rx.valid & (rx_index < SAMPLE_BYTES)):
            m.d.sync += [buf[rx_index].eq(port.rx.payload), rx_index.eq(rx_index + 1)]

        def command(device, reg, *, write=0, value=0, length=1, fast=0):
            p = port.cmd.payload
            m.d.comb += [port.cmd.valid.eq(1), p.device.eq(device), p.reg.eq(reg),
                         p.write.eq(write), p.data.eq(value), p.length.eq(length),
                         p.fast.eq(fast)]

        # -- interrupt ----------------------------------------------------------------------------
        int_sync = Signal()
        m.submodules.int_sync = FFSynchronizer(self.int_pin, int_sync)
        int_active = Signal()
        int_prev = Signal()
        int_edge = Signal()
        m.d.comb += int_active.eq(int_sync ^ int(cfg.int_active_low))
        m.d.sync += int_prev.eq(int_active)
        m.d.comb += int_edge.eq(int_active & ~int_prev)
        int_pending = Signal()
        with m.If(int_edge):
            m.d.sync += int_pending.eq(1)

        # Sensor samples missed: data-ready edges are one sample period apart; an interval of
        # n periods (rounded: the phase starts half a period in) means n - 1 samples the sensor
        # made and the driver never read (e.g. a latched INT still high from the sample before).
        period = self.period_cycles
        phase = Signal(range(period))
        periods = Signal(4)                     # whole periods since the last edge, saturating
        skipped = Signal(4)                     # for the sample this edge announces
        seen_edge = Signal()                    # an edge since streaming began
        dropped = Signal(4)                     # read but not taken (the consumer was busy)
        with m.If(int_edge):
            m.d.sync += [phase.eq(period // 2), periods.eq(0), seen_edge.eq(1),
                         skipped.eq(Mux(seen_edge & (periods > 1), periods - 1, 0))]
        with m.Elif(phase == period - 1):
            m.d.sync += [phase.eq(0), periods.eq(Mux(periods == 15, 15, periods + 1))]
        with m.Else():
            m.d.sync += phase.eq(phase + 1)

        timer = Signal(range(max(self.power_up_cycles, self.reset_cycles, self.mag_wait_cycles,
                                 self.timeout_cycles) + 1))
        status = self.status
        counter = Signal(16)
        overrun = Signal()
        last = buf[0]

        with m.If(self.samples.valid & self.samples.ready):
            m.d.sync += self.samples.valid.eq(0)

        def restart():
            m.d.sync += [pc.eq(0), status.streaming.eq(0), status.mag_ok.eq(0),
                         int_pending.eq(0)]
            with m.If(status.retries != 15):
                m.d.sync += status.retries.eq(status.retries + 1)
            m.next = "FETCH"

        def fail(absent):
            """The current step failed: ``absent`` = no acknowledge / time-out, else a bad value."""
            with m.If(step.fail == Fail.MAG):
                m.d.sync += [pc.eq(skip_mag), status.mag_absent.eq(absent),
                             status.mag_wia_error.eq(~absent)]
                m.next = "FETCH"
            with m.Else():
                with m.If(absent):
                    m.d.sync += [status.no_response.eq(1), status.whoami_error.eq(0)]
                restart()

        def next_step():
            m.d.sync += pc.eq(pc + 1)
            m.next = "FETCH"

        def be16(k):
            return Cat(buf[k + 1], buf[k]).as_signed()

        def le16(k):
            return Cat(buf[k], buf[k + 1]).as_signed()

        with m.FSM():
            with m.State("FETCH"):
                m.d.sync += rx_index.eq(0)
                with m.Switch(step.op):
                    with m.Case(Op.WAIT):
                        m.d.sync += timer.eq(step.wait - 1)
                        m.next = "WAIT"
                    with m.Case(Op.WRITE):
                        command(step.device, step.reg, write=1, value=step.value)
                        with m.If(port.cmd.ready):
                            m.next = "ACCESS"
                    with m.Case(Op.CHECK, Op.STORE):
                        command(step.device, step.reg)
                        with m.If(port.cmd.ready):
                            m.next = "ACCESS"
                    with m.Case(Op.POLL):
                        m.d.sync += timer.eq(self.timeout_cycles - 1)
                        m.next = "POLL"
                    with m.Case(Op.MARK):
                        m.d.sync += status.mag_ok.eq(1)
                        next_step()
                    with m.Case(Op.STREAM):
                        # A latched INT already high would give no edge: treat it as pending.
                        m.d.sync += [status.streaming.eq(1), timer.eq(self.timeout_cycles - 1),
                                     counter.eq(0), int_pending.eq(int_active),
                                     seen_edge.eq(0), skipped.eq(0)]
                        m.next = "STREAM"
            with m.State("WAIT"):
                m.d.sync += timer.eq(timer - 1)
                with m.If(timer == 0):
                    next_step()
            with m.State("ACCESS"):
                with m.If(port.rsp.valid):
                    with m.If(port.rsp.payload.error):
                        fail(absent=1)
                    with m.Elif(step.op == Op.CHECK):
                        with m.If(step.check_wia):
                            with m.If(last == A.WIA_VALUE):
                                next_step()
                            with m.Else():
                                fail(absent=0)
                        with m.Else():
                            good = Cat(last == v for v in cfg.accepted_who_am_i).any()
                            m.d.sync += [status.who_am_i.eq(last),
                                         status.whoami_error.eq(~good),
                                         status.no_response.eq((last == 0x00) | (last == 0xFF))]
                            with m.If(good):
                                next_step()
                            with m.Else():
                                restart()
                    with m.Elif(step.op == Op.STORE):
                        m.d.sync += self.asa[step.value[:2]].eq(last)
                        next_step()
                    with m.Else():
                        next_step()
            with m.State("POLL"):
                m.d.sync += rx_index.eq(0)
                with m.If(timer != 0):
                    m.d.sync += timer.eq(timer - 1)
                command(step.device, step.reg)
                with m.If(port.cmd.ready):
                    m.next = "POLL_WAIT"
            with m.State("POLL_WAIT"):
                with m.If(timer != 0):
                    m.d.sync += timer.eq(timer - 1)
                with m.If(port.rsp.valid):
                    with m.If(port.rsp.payload.error | (last & step.mask).any()):
                        fail(absent=1)
                    with m.Elif((last & step.value).any()):
                        next_step()
                    with m.Elif(timer == 0):
                        fail(absent=1)
                    with m.Else():
                        m.next = "POLL"
            with m.State("STREAM"):
                m.d.sync += [timer.eq(timer - 1), rx_index.eq(0)]
                with m.If(int_pending):
                    command(0, R.INT_STATUS, fast=1,
                            length=SAMPLE_BYTES if cfg.wiring == "spi" else _MPU_BYTES)
                    with m.If(port.cmd.ready):
                        m.d.sync += int_pending.eq(int_edge)
                        m.next = "READ_MPU"
                with m.Elif(timer == 0):
                    m.d.sync += status.int_timeout.eq(1)
                    restart()
            with m.State("READ_MPU"):
                with m.If(port.rsp.valid):
                    with m.If(port.rsp.payload.error):
                        m.d.sync += status.no_response.eq(1)
                        restart()
                    with m.Else():
                        m.next = "EMIT"
                        if cfg.wiring == "i2c":     # the AK8963 is a second read on this bus
                            with m.If(status.mag_ok):
                                m.next = "MAG_CMD"
            with m.State("MAG_CMD"):
                command(1, A.ST1, length=A.SAMPLE_BYTES)
                with m.If(port.cmd.ready):
                    m.next = "READ_MAG"
            with m.State("READ_MAG"):
                with m.If(port.rsp.valid):
                    # A lost magnetometer read leaves its bytes stale: flag, don't stop.
                    m.next = "EMIT"
                    with m.If(port.rsp.payload.error):
                        m.d.sync += status.mag_absent.eq(1)
            with m.State("EMIT"):
                m.d.sync += [counter.eq(counter + 1), timer.eq(self.timeout_cycles - 1),
                             status.int_timeout.eq(0)]
                with m.If(self.samples.valid):
                    m.d.sync += [overrun.eq(1),
                                 dropped.eq(Mux(dropped == 15, 15, dropped + 1))]
                with m.Else():
                    p = self.samples.payload
                    st1, st2 = buf[_MPU_BYTES], buf[_MPU_BYTES + 7]
                    mag_new = status.mag_ok & st1[0]
                    hofl = st2[3]
                    m.d.sync += [self.samples.valid.eq(1), overrun.eq(0),
                                 p.counter.eq(counter), dropped.eq(0),
                                 p.skipped.eq(Mux(skipped + dropped > 15, 15,
                                                  skipped + dropped)),
                                 p.flags.data_ready.eq(buf[0][0]),
                                 p.flags.overrun.eq(overrun),
                                 p.flags.mag_new.eq(mag_new),
                                 p.flags.mag_dor.eq(status.mag_ok & st1[1]),
                                 p.flags.mag_overflow.eq(status.mag_ok & hofl),
                                 p.flags.mag_valid.eq(mag_new & ~hofl),
                                 p.temp.eq(be16(1 + 6))]
                    for axis in range(3):
                        m.d.sync += [p.accel[axis].eq(be16(1 + 2 * axis)),
                                     p.gyro[axis].eq(be16(1 + 8 + 2 * axis)),
                                     p.mag[axis].eq(Mux(status.mag_ok,
                                                        le16(_MPU_BYTES + 1 + 2 * axis), 0))]
                m.next = "STREAM"

        return m
