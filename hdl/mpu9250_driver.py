"""MPU9250 driver: brings the part up over SPI, then reads one sample per data-ready interrupt.

Interface
    ``spi_o`` (out, ``SPIByte`` stream) and ``spi_i`` (in, byte stream): to an ``SPIController``.
    ``int_pin`` (in): the sensor's INT pin, raw; synchronised here.
    ``samples`` (out, ``Sample`` stream): one per data-ready interrupt. If the consumer has not
        taken the previous sample when the next is read, the new one is dropped and the following
        sample carries ``flags.overrun`` (valid never waits on ready).
    ``status`` (out, ``DriverStatus``): see ``hdl/sample.py``.

Bring-up (the sequence well-known drivers use; values from ``MPU9250Config``)
    wait power-up; USER_CTRL = I2C_IF_DIS; PWR_MGMT_1 = H_RESET; wait reset;
    USER_CTRL = I2C_IF_DIS (H_RESET cleared it); PWR_MGMT_1 = CLKSEL 1; check WHO_AM_I;
    PWR_MGMT_2 = 0; CONFIG; SMPLRT_DIV; GYRO_CONFIG; ACCEL_CONFIG; ACCEL_CONFIG2; INT_PIN_CFG;
    INT_ENABLE = RAW_RDY. Register writes and the WHO_AM_I read use the slow SPI clock.
    A wrong WHO_AM_I, or no interrupt within ``int_timeout_s``, sets a status flag and restarts
    the sequence from the power-up wait (which doubles as the retry delay).

Streaming
    On each rising edge of the (active) INT level, one fast burst from INT_STATUS through
    GYRO_ZOUT_L: 1 + 15 bytes. Reading INT_STATUS clears a latched interrupt.
    Latency from the INT edge to ``samples.valid``: 2 synchroniser cycles + the burst
    (16 bytes of 16·fast_half + capture_delay + 1 cycles, plus CS setup) + 2 cycles.
"""

import math
from dataclasses import dataclass
from typing import Optional, Tuple

from amaranth import *
from amaranth.lib import enum, stream, wiring
from amaranth.lib.cdc import FFSynchronizer
from amaranth.lib.wiring import In, Out

from . import mpu9250_regs as R
from .sample import DriverStatus, Sample
from .spi_controller import SPIByte


__all__ = ["MPU9250Config", "DriverTiming", "MPU9250Driver"]


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

    def __post_init__(self):
        R.gyro_config(self.gyro_fs_dps)
        R.accel_config(self.accel_fs_g)
        for name, top in (("dlpf_cfg", 7), ("accel_dlpf_cfg", 7), ("smplrt_div", 255)):
            if not 0 <= getattr(self, name) <= top:
                raise ValueError(f"MPU9250Config.{name} must be 0..{top}")
        if not self.accepted_who_am_i:
            raise ValueError("MPU9250Config.accepted_who_am_i cannot be empty")

    @property
    def output_data_rate(self):
        return R.output_data_rate(self.dlpf_cfg, R.gyro_config(self.gyro_fs_dps), self.smplrt_div)

    def configuration_writes(self):
        """(register, value) written after the WHO_AM_I check, in order."""
        int_pin_cfg = ((R.INT_PIN_CFG_LATCH_INT_EN if self.int_latched else 0) |
                       (R.INT_PIN_CFG_ACTL if self.int_active_low else 0))
        return [
            (R.PWR_MGMT_2, 0x00),
            (R.CONFIG, self.dlpf_cfg),
            (R.SMPLRT_DIV, self.smplrt_div),
            (R.GYRO_CONFIG, R.gyro_config(self.gyro_fs_dps)),
            (R.ACCEL_CONFIG, R.accel_config(self.accel_fs_g)),
            (R.ACCEL_CONFIG2, self.accel_dlpf_cfg),
            (R.INT_PIN_CFG, int_pin_cfg),
            (R.INT_ENABLE, R.INT_ENABLE_RAW_RDY),
        ]


@dataclass(frozen=True)
class DriverTiming:
    """Real-time waits of the driver, converted to cycles at elaboration.

    ``time_scale`` multiplies the power-up and reset waits (simulations use ≪ 1; the sensor
    model's delays must be scaled alike). ``int_timeout_s`` is used as given; ``None`` means
    four output sample periods plus 50 ms for the gyro to wake.
    """
    power_up_s: float = 0.100
    reset_s: float = 0.100
    int_timeout_s: Optional[float] = None
    time_scale: float = 1.0

    def cycles(self, clk_freq, config):
        def c(seconds):
            return max(1, math.ceil(seconds * clk_freq))
        timeout = self.int_timeout_s
        if timeout is None:
            timeout = 4 / config.output_data_rate + 0.050
        return (c(self.power_up_s * self.time_scale), c(self.reset_s * self.time_scale),
                c(timeout))


class Op(enum.Enum, shape=2):
    WAIT   = 0
    WRITE  = 1
    WHOAMI = 2
    STREAM = 3


BURST_FIRST = R.INT_STATUS
BURST_BYTES = 1 + 1 + R.SENSOR_BYTES     # address, INT_STATUS, accel/temp/gyro


class MPU9250Driver(wiring.Component):
    def __init__(self, *, clk_freq, config=MPU9250Config(), timing=DriverTiming()):
        self.clk_freq = clk_freq
        self.config = config
        self.timing = timing
        self.power_up_cycles, self.reset_cycles, self.timeout_cycles = \
            timing.cycles(clk_freq, config)
        super().__init__({
            "spi_o": Out(stream.Signature(SPIByte)),
            "spi_i": In(stream.Signature(8)),
            "int_pin": In(1),
            "samples": Out(stream.Signature(Sample)),
            "status": Out(DriverStatus),
        })

    def program(self):
        """The bring-up sequence as (op, register, value, wait cycles) rows."""
        ops = [
            (Op.WAIT, 0, 0, self.power_up_cycles),
            (Op.WRITE, R.USER_CTRL, R.USER_CTRL_I2C_IF_DIS, 0),
            (Op.WRITE, R.PWR_MGMT_1, R.PWR_MGMT_1_H_RESET, 0),
            (Op.WAIT, 0, 0, self.reset_cycles),
            (Op.WRITE, R.USER_CTRL, R.USER_CTRL_I2C_IF_DIS, 0),
            (Op.WRITE, R.PWR_MGMT_1, R.PWR_MGMT_1_CLKSEL_AUTO, 0),
            (Op.WHOAMI, R.WHO_AM_I, 0, 0),
        ]
        ops += [(Op.WRITE, reg, value, 0) for reg, value in self.config.configuration_writes()]
        ops.append((Op.STREAM, 0, 0, 0))
        return ops

    def elaborate(self, platform):
        m = Module()
        program = self.program()

        # -- program ROM --------------------------------------------------------------------------
        pc = Signal(range(len(program)))
        op = Signal(Op)
        op_reg = Signal(8)
        op_value = Signal(8)
        op_wait = Signal(range(max(self.power_up_cycles, self.reset_cycles) + 1))
        with m.Switch(pc):
            for index, (kind, reg, value, wait) in enumerate(program):
                with m.Case(index):
                    m.d.comb += [op.eq(kind), op_reg.eq(reg), op_value.eq(value),
                                 op_wait.eq(wait)]

        # -- SPI transaction engine: send xfer_len bytes, collect as many ---------------------------
        xfer_len = Signal(range(BURST_BYTES + 1))
        xfer_hdr = Signal(8)
        xfer_data = Signal(8)            # second byte; later bytes are 0x00
        xfer_fast = Signal()
        tx_index = Signal(range(BURST_BYTES + 1))
        rx_count = Signal(range(BURST_BYTES + 1))
        rx_buf = Signal(8 * BURST_BYTES)  # last received byte in the low bits
        xfer_start = Signal()

        m.d.comb += [
            self.spi_o.valid.eq((tx_index < xfer_len) & ~xfer_start),
            self.spi_o.payload.data.eq(Mux(tx_index == 0, xfer_hdr,
                                           Mux(tx_index == 1, xfer_data, 0))),
            self.spi_o.payload.fast.eq(xfer_fast),
            self.spi_o.payload.last.eq(tx_index == xfer_len - 1),
            self.spi_i.ready.eq(1),
        ]
        with m.If(self.spi_o.valid & self.spi_o.ready):
            m.d.sync += tx_index.eq(tx_index + 1)
        with m.If(self.spi_i.valid):
            m.d.sync += [rx_buf.eq(Cat(self.spi_i.payload, rx_buf[:-8])),
                         rx_count.eq(rx_count + 1)]
        with m.If(xfer_start):
            m.d.sync += [tx_index.eq(0), rx_count.eq(0)]
        xfer_done = Signal()
        m.d.comb += xfer_done.eq(~xfer_start & (rx_count == xfer_len))

        def start_xfer(hdr, data, length, fast):
            m.d.sync += [xfer_hdr.eq(hdr), xfer_data.eq(data), xfer_len.eq(length),
                         xfer_fast.eq(fast), xfer_start.eq(1)]
        m.d.sync += xfer_start.eq(0)

        # -- interrupt ----------------------------------------------------------------------------
        int_sync = Signal()
        m.submodules.int_sync = FFSynchronizer(self.int_pin, int_sync)
        int_active = Signal()
        int_prev = Signal()
        int_edge = Signal()
        m.d.comb += int_active.eq(int_sync ^ int(self.config.int_active_low))
        m.d.sync += int_prev.eq(int_active)
        m.d.comb += int_edge.eq(int_active & ~int_prev)
        int_pending = Signal()
        with m.If(int_edge):
            m.d.sync += int_pending.eq(1)

        timer = Signal(range(max(self.power_up_cycles, self.reset_cycles,
                                 self.timeout_cycles) + 1))
        status = self.status
        counter = Signal(16)
        overrun = Signal()

        with m.If(self.samples.valid & self.samples.ready):
            m.d.sync += self.samples.valid.eq(0)

        def restart():
            m.d.sync += [pc.eq(0), status.streaming.eq(0), int_pending.eq(0)]
            with m.If(status.retries != 15):
                m.d.sync += status.retries.eq(status.retries + 1)
            m.next = "FETCH"

        def byte_at(k):        # k-th byte of a burst, counted from the address byte
            return rx_buf.word_select(BURST_BYTES - 1 - k, 8)

        def be16(k):
            return Cat(byte_at(k + 1), byte_at(k)).as_signed()

        with m.FSM():
            with m.State("FETCH"):
                with m.Switch(op):
                    with m.Case(Op.WAIT):
                        m.d.sync += timer.eq(op_wait - 1)
                        m.next = "WAIT"
                    with m.Case(Op.WRITE):
                        start_xfer(op_reg, op_value, 2, 0)
                        m.next = "XFER"
                    with m.Case(Op.WHOAMI):
                        start_xfer(R.SPI_READ | op_reg, 0, 2, 0)
                        m.next = "XFER"
                    with m.Case(Op.STREAM):
                        # A latched INT already high would give no edge: treat it as pending.
                        m.d.sync += [status.streaming.eq(1), timer.eq(self.timeout_cycles - 1),
                                     counter.eq(0), int_pending.eq(int_active)]
                        m.next = "STREAM"
            with m.State("WAIT"):
                m.d.sync += timer.eq(timer - 1)
                with m.If(timer == 0):
                    m.d.sync += pc.eq(pc + 1)
                    m.next = "FETCH"
            with m.State("XFER"):
                with m.If(xfer_done):
                    m.d.sync += pc.eq(pc + 1)
                    m.next = "FETCH"
                    with m.If(op == Op.WHOAMI):
                        who = rx_buf[:8]
                        good = Cat(who == v for v in self.config.accepted_who_am_i).any()
                        m.d.sync += [status.who_am_i.eq(who),
                                     status.whoami_error.eq(~good),
                                     status.no_response.eq((who == 0x00) | (who == 0xFF))]
                        with m.If(~good):
                            restart()
            with m.State("STREAM"):
                m.d.sync += timer.eq(timer - 1)
                with m.If(int_pending):
                    m.d.sync += int_pending.eq(int_edge)
                    start_xfer(R.SPI_READ | BURST_FIRST, 0, BURST_BYTES, 1)
                    m.next = "BURST"
                with m.Elif(timer == 0):
                    m.d.sync += status.int_timeout.eq(1)
                    restart()
            with m.State("BURST"):
                with m.If(xfer_done):
                    m.d.sync += [counter.eq(counter + 1), timer.eq(self.timeout_cycles - 1),
                                 status.int_timeout.eq(0)]
                    with m.If(self.samples.valid):
                        m.d.sync += overrun.eq(1)
                    with m.Else():
                        p = self.samples.payload
                        m.d.sync += [self.samples.valid.eq(1), overrun.eq(0),
                                     p.counter.eq(counter),
                                     p.flags.data_ready.eq(byte_at(1)[0]),
                                     p.flags.overrun.eq(overrun),
                                     p.temp.eq(be16(2 + 6))]
                        for axis in range(3):
                            m.d.sync += [p.accel[axis].eq(be16(2 + 2 * axis)),
                                         p.gyro[axis].eq(be16(2 + 8 + 2 * axis)),
                                         p.mag[axis].eq(0)]
                    m.next = "STREAM"

        return m
