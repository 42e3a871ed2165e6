"""Behavioural model of the MPU9250 as an SPI peripheral.

The model is plain Python driven by pin events with time stamps in seconds, so it can be unit
tested on its own and attached to Amaranth's simulator by ``sim.bench.harness`` (which feeds it the pin
levels the gateware drives, one system clock at a time).

What it does, as the part does (``shared/mpu9250-notes.md``):
- SPI mode 3, MSB first: SDI latched on rising SCLK, SDO changed on falling SCLK. First byte:
  bit 7 = read, bits 6..0 = address; bursts auto-increment (wrapping 0x7F -> 0x00).
- A register file with the documented reset values (WHO_AM_I configurable: 0x71 MPU9250,
  0x73 MPU9255); H_RESET, SLEEP, self-clearing USER_CTRL bits.
- Registers cannot be reached for ``startup_s`` after power-up and ``reset_s`` after H_RESET.
- New samples at the output data rate that CONFIG, GYRO_CONFIG.FCHOICE_B and SMPLRT_DIV select,
  while awake. Sensor registers change atomically: a sample that becomes ready during a
  transaction is committed when chip select rises, so a burst never mixes two samples.
- INT_STATUS.RAW_RDY and the INT pin: latched (LATCH_INT_EN) or a ``int_pulse_s`` pulse,
  active low with ACTL; cleared by reading INT_STATUS, or by any read with INT_ANYRD_2CLEAR.

What it checks, recording a ``Violation`` (or raising ``ProtocolError`` if asked):
SCLK above 1 MHz (or a level under 400 ns) on anything but a read of the sensor and interrupt
registers, SCLK above 20 MHz at all, CS setup < 8 ns, CS hold < 500 ns, chip select raised in
the middle of a byte, SCLK low when CS falls (not mode 3), access while the part is starting up,
writes to read-only registers.

Auxiliary I2C master (USER_CTRL.I2C_MST_EN): at every sample tick the enabled slots SLV0..SLV3
run in order, reads filling EXT_SENS_DATA in slot order (BYTE_SW, GRP, REG_DIS, the
I2C_MST_DELAY_CTRL / I2C_MST_DLY pacing), then SLV4's single-byte transfer, which sets
I2C_MST_STATUS.SLV4_DONE (and SLV4_NACK) and clears its enable. Results appear after the
transfers' duration at the I2C_MST_CLK rate; with WAIT_FOR_ES the sample and its data-ready
interrupt wait for them too. Devices sit in ``aux_devices``; an absent address NACKs.

Self-test: SELF_TEST_X/Y/Z_ACCEL and _GYRO hold factory codes (``self_test_codes``, kept
through a reset); an axis whose self-test bit is set in ACCEL_CONFIG / GYRO_CONFIG [7:5] reads
its factory response ``otp(code)`` (LSB at ±2 g, ±250 °/s; halved per full-scale step) times
``self_test_gain`` (1.0: a good part; 0: a dead axis) on top of the source's counts.

Not modelled: the FIFO, sensor warm-up, the primary I2C interface's own pins (that is
``sim.models.i2c_bus``, which uses ``read_reg``/``write_reg`` here).
"""

import math
import random
from collections import deque
from dataclasses import dataclass, replace
from typing import Optional

from ...hdl.contract import mpu9250_regs as R
from ...hdl.sensor.self_test import otp
from .sources import SensorSample, constant_source


# A good part's factory codes (accel X, Y, Z, gyro X, Y, Z): about 0.39 g and 60 °/s
DEFAULT_SELF_TEST_CODES = (90, 94, 102, 112, 115, 108)

__all__ = ["DEFAULT_SELF_TEST_CODES", "MPU9250Timing", "Violation", "ProtocolError", "MPU9250Model"]


def _swap_pairs(data, reg, grp):
    """BYTE_SW: swap the two bytes of each word read whole. Words start at even register
    addresses (GRP = 0) or odd ones (GRP = 1)."""
    out = list(data)
    k = 0
    if (reg & 1) != grp:
        k = 1                                   # the first byte is the second half of a word
    while k + 1 < len(out):
        out[k], out[k + 1] = out[k + 1], out[k]
        k += 2
    return out

_EPS = 1e-12        # time comparisons: stamps come from integer cycle counts / clock frequency


# The SDO output delay (a falling SCLK edge to the next bit on SDO) the model's parts have. The
# datasheet (PS-MPU-9250A-01, SPI timing) gives a maximum only, 100 ns at 1 MHz. The flight
# stacks read the sensor registers fast in mode 3, sampling on the rising edge half a period
# after the falling one, without moving that point: PX4 at 10 MHz (50 ns), Betaflight up to
# 20 MHz (25 ns), ArduPilot 8 MHz requested (62 ns). Parts that work there answer, with their
# MCU's input setup (a few ns) and a short board, within about 20 ns: the typical part is
# taken at 15 ns, the fastest at 5 ns (a CMOS output and its pad are not quicker), the slowest
# the datasheet's 100 ns (a part "some drivers find marginal at 20 MHz", mpu9250-notes.md).
SDO_DELAY_MIN_S = 5e-9
SDO_DELAY_TYPICAL_S = 15e-9
SDO_DELAY_MAX_S = 100e-9


@dataclass(frozen=True)
class MPU9250Timing:
    """Real-world times of the part. Defaults are the datasheet's worst case.

    SDO: each bit shows ``sdo_delay_s`` (the part's output delay, ``SDO_DELAY_MIN_S`` ..
    ``SDO_DELAY_MAX_S``) plus ``board_delay_s`` (the round trip outside the part: SCLK's way
    out from the FPGA's register to the part and SDO's way back to the FPGA's input
    register, its I/O included; the cycle model has none of its own) after its falling SCLK
    edge, give or take ``sdo_jitter_s`` (uniform, drawn per bit from the model's seeded
    generator), plus the model's ``sdo_drift_s`` at that time (0 at power-up: a fault or a
    test moves it mid-run, as temperature and supply move a real part's). Transitions in
    flight keep their order (a delay beyond an SCLK period delays the bits, it loses none);
    the previous bit stays until the next one shows."""
    startup_s: float = 0.100    # power-up to register access: 11 ms typical, 100 ms max
    reset_s: float = 0.100      # H_RESET to register access (drivers wait ~100 ms)
    int_pulse_s: float = 50e-6  # INT pulse width with LATCH_INT_EN = 0
    odr_scale: float = 1.0      # sample period (and aux I2C transfer time) multiplier: < 1
                                # speeds simulations up
    sdo_delay_s: float = SDO_DELAY_MAX_S     # the part's SDO output delay (the datasheet's
                                            # maximum by default)
    board_delay_s: float = 0.0  # the round trip outside the part, added to each bit's delay
    sdo_jitter_s: float = 0.0   # each bit's delay within ± this of the rest

    def __post_init__(self):
        if not SDO_DELAY_MIN_S - 1e-15 <= self.sdo_delay_s <= SDO_DELAY_MAX_S + 1e-15:
            raise ValueError(f"sdo_delay_s {self.sdo_delay_s * 1e9:g} ns: a part's SDO delay is "
                             f"{SDO_DELAY_MIN_S * 1e9:g} .. {SDO_DELAY_MAX_S * 1e9:g} ns "
                             f"(the round trip outside it is board_delay_s)")
        if self.board_delay_s < 0 or self.sdo_jitter_s < 0:
            raise ValueError("board_delay_s and sdo_jitter_s cannot be negative")
        if self.sdo_jitter_s > self.sdo_delay_s:
            raise ValueError(f"sdo_jitter_s {self.sdo_jitter_s * 1e9:g} ns is more than the "
                             f"delay it moves ({self.sdo_delay_s * 1e9:g} ns)")

    @property
    def sdo_round_trip_s(self):
        """The delay of a bit without jitter or drift: the part's and the board's."""
        return self.sdo_delay_s + self.board_delay_s

    def scaled(self, delays=1.0, odr=1.0):
        """Start-up and reset delays times ``delays``; sample period and pulse times ``odr``."""
        return replace(self, startup_s=self.startup_s * delays, reset_s=self.reset_s * delays,
                       int_pulse_s=self.int_pulse_s * odr, odr_scale=self.odr_scale * odr)


@dataclass(frozen=True)
class Violation:
    time: float
    kind: str
    register: Optional[int]
    detail: str

    def __str__(self):
        reg = "" if self.register is None else f" at register 0x{self.register:02X}"
        return f"t = {self.time * 1e6:.3f} us: {self.kind}{reg}: {self.detail}"


class ProtocolError(AssertionError):
    pass


class MPU9250Model:
    SLOW_MAX_HZ = 1e6
    FAST_MAX_HZ = 20e6
    SLOW_MIN_LEVEL_S = 400e-9
    FAST_MIN_LEVEL_S = 25e-9
    CS_SETUP_S = 8e-9
    CS_HOLD_S = 500e-9

    def __init__(self, *, who_am_i=R.WHO_AM_I_MPU9250, timing=MPU9250Timing(), source=None,
                 sleep_after_reset=False, raise_on_violation=False, aux_devices=None,
                 self_test_codes=DEFAULT_SELF_TEST_CODES, self_test_gain=(1.0,) * 6,
                 sdo_seed=1):
        self.who_am_i = who_am_i
        # factory codes and response gains, accel X, Y, Z then gyro X, Y, Z
        self.self_test_codes = tuple(self_test_codes)
        self.self_test_gain = list(self_test_gain)
        self.timing = timing
        self.source = source or constant_source(SensorSample())
        # The reset value of SLEEP comes from factory OTP; drivers must not rely on it.
        self.sleep_after_reset = sleep_after_reset
        self.raise_on_violation = raise_on_violation
        # Devices on the auxiliary I2C bus, by 7-bit address (e.g. {0x0C: AK8963Model()}).
        # With BYPASS_EN (and the I2C master off) they also appear on the primary I2C bus.
        self.aux_devices = dict(aux_devices or {})
        self.aux_log = []           # (t, slot, address, register, "r"/"w", data or None=NACK)
        self.pointer = 0            # register pointer of the primary I2C interface

        self.violations = []
        self.writes = []            # (t, address, value): every write the part accepted
        self.samples = []           # SensorSample written to the registers, in order
        self.sample_times = []
        self.sample_reads = []      # index into ``samples`` of each sample read (a burst
                                    # through ACCEL_XOUT_H from INT_STATUS on)
        self.self_test_reads = []   # the same for bursts that start at ACCEL_XOUT_H
        self._burst_start = None
        self.ext_reads = []         # EXT_SENS_DATA_00..07 as that same read saw them
        self.transactions = []      # SPI: (t CS fell, t CS rose, first register, bytes, read)
        self.resets = 0
        self.line_flips = {}
        # the auxiliary I2C master stalls (a device holding the auxiliary bus, a hung
        # transfer): no slot runs at the sample ticks while it is set, and a transfer that
        # was enabled (SLV4 too) waits, enabled, for the first tick after it clears
        self.aux_stalled = False

        self.now = 0.0
        self.regs = bytearray(128)
        self._reset_registers()
        self._busy_until = timing.startup_s
        self._next_sample = None
        self._pulse_end = None
        self._aux_done = None       # (time, apply) of an auxiliary I2C master cycle in flight
        self._aux_cycles = 0
        self._next_event = self._busy_until

        self.sclk = 1
        self._sdo_level = 0
        self._sdo_pending = deque()     # (time, level): SDO's transitions in flight, in order
        self.sdo_drift_s = 0.0          # added to every bit's delay from now on (a drift)
        self._drift_ramp = None         # (start time, rate s/s, until): ``ramp_sdo_drift``
        self._sdo_rng = random.Random(sdo_seed)
        self.selected = False

    # -- time -------------------------------------------------------------------------------------
    @property
    def busy(self):
        return self._busy_until is not None

    @property
    def sample_period(self):
        rate = R.output_data_rate(self.regs[R.CONFIG], self.regs[R.GYRO_CONFIG],
                                  self.regs[R.SMPLRT_DIV])
        return self.timing.odr_scale / rate

    @property
    def sampling(self):
        return not self.busy and not (self.regs[R.PWR_MGMT_1] & R.PWR_MGMT_1_SLEEP)

    @property
    def next_event(self):
        """Time of the next thing the model does on its own (None: nothing scheduled)."""
        return self._next_event

    def advance(self, t):
        """Let time run up to ``t``: end start-up, convert samples, end INT pulses."""
        while self._next_event is not None and self._next_event <= t + _EPS:
            ev = self._next_event
            if self._busy_until is not None and self._busy_until <= ev + _EPS:
                self._busy_until = None
                self._reschedule(ev)
            elif self._pulse_end is not None and self._pulse_end <= ev + _EPS:
                self._pulse_end = None
            elif self._aux_done is not None and self._aux_done[0] <= ev + _EPS:
                _, apply = self._aux_done
                self._aux_done = None
                apply(ev)
            else:
                self._next_sample = ev + self.sample_period
                self._convert(ev)
            self._update_next_event()
        self.now = t

    def next_sample_after(self, t):
        """When the part makes its next sample after ``t`` (None: it is not sampling). ``t``
        may be ahead of the model's own time: a sample due by then is counted as made."""
        upcoming = self._next_sample
        while upcoming is not None and upcoming <= t + _EPS:
            upcoming += self.sample_period
        return upcoming

    def _update_next_event(self):
        aux = self._aux_done[0] if self._aux_done else None
        events = [e for e in (self._busy_until, self._pulse_end, self._next_sample, aux)
                  if e is not None]
        self._next_event = min(events) if events else None

    def _reschedule(self, t):
        # Sampling starts one period after the part wakes or its rate changes.
        self._next_sample = t + self.sample_period if self.sampling else None
        self._update_next_event()

    def _self_test_response(self, sample):
        """``sample`` with the self-test responses of the axes whose self-test is on."""
        out = []
        for group, (reg, values) in enumerate(((R.ACCEL_CONFIG, sample.accel),
                                               (R.GYRO_CONFIG, sample.gyro))):
            config = self.regs[reg]
            axes = []
            for i, v in enumerate(values):
                code = self.self_test_codes[3 * group + i]
                if config & (0x80 >> i) and code:
                    v += round(otp(code) * self.self_test_gain[3 * group + i]) >> \
                        ((config >> 3) & 3)
                axes.append(max(-32768, min(32767, v)))
            out.append(tuple(axes))
        return replace(sample, accel=out[0], gyro=out[1])

    def _convert(self, t):
        sample = self._self_test_response(self.source(len(self.samples), t))
        aux = None
        if self.regs[R.USER_CTRL] & R.USER_CTRL_I2C_MST_EN and self._aux_done is None and \
                not self.aux_stalled:
            aux = self._aux_cycle(t)
        if aux is None:
            self._commit(t, sample)
        elif self.regs[R.I2C_MST_CTRL] & R.I2C_MST_CTRL_WAIT_FOR_ES:
            # Data ready (and the sensor registers) wait until the external data is in.
            duration, apply = aux
            self._aux_done = (t + duration, lambda te: (apply(te), self._commit(te, sample)))
        else:
            self._commit(t, sample)
            duration, apply = aux
            self._aux_done = (t + duration, apply)
        self._update_next_event()

    def _commit(self, t, sample):
        self.regs[R.ACCEL_XOUT_H:R.ACCEL_XOUT_H + R.SENSOR_BYTES] = sample.to_bytes()
        self.samples.append(sample)
        self.sample_times.append(t)
        self.regs[R.INT_STATUS] |= R.INT_STATUS_RAW_RDY
        if self.regs[R.INT_ENABLE] & R.INT_ENABLE_RAW_RDY and \
                not self.regs[R.INT_PIN_CFG] & R.INT_PIN_CFG_LATCH_INT_EN:
            self._pulse_end = t + self.timing.int_pulse_s
            self._update_next_event()

    # -- auxiliary I2C master ---------------------------------------------------------------------
    def _aux_transfer(self, t, slot, address, reg, read, n, data=0, reg_dis=False):
        """One transaction on the auxiliary bus: (bits on the wire, bytes read or None=NACK)."""
        dev = self.aux_devices.get(address)
        if dev is None:
            self.aux_log.append((t, slot, address, reg, "r" if read else "w", None))
            return 11, None                       # start, address byte NACKed, stop
        dev.advance(t)
        if read:
            if not reg_dis:
                dev.pointer = reg
            dev.begin_read()
            out = []
            for _ in range(n):
                out.append(dev.read_reg(dev.pointer))
                dev.pointer = dev.next_address(dev.pointer)
            self.aux_log.append((t, slot, address, reg, "r", bytes(out)))
            return (11 + 9 * n if reg_dis else 30 + 9 * n), out
        dev.pointer = reg
        dev.write_reg(reg, data)
        dev.pointer = dev.next_address(reg)
        self.aux_log.append((t, slot, address, reg, "w", bytes([data])))
        return 29, []

    def _aux_cycle(self, t):
        """Run the enabled slots once (at a sample tick); results show after the transfers."""
        regs = self.regs
        delayed_ok = self._aux_cycles % (1 + (regs[R.I2C_SLV4_CTRL] & R.I2C_SLV4_MST_DLY)) == 0
        self._aux_cycles += 1
        ext = {}
        status = 0
        bits = 0
        index = 0
        ran = False
        for slot, base in enumerate(R.I2C_SLV_ADDR):
            addr_reg, reg, ctrl = regs[base], regs[base + 1], regs[base + 2]
            if not ctrl & R.I2C_SLV_EN:
                continue
            read, n = bool(addr_reg & R.I2C_SLV_RNW), ctrl & R.I2C_SLV_LENG
            first = index
            if read:
                index += n                      # EXT_SENS_DATA is allocated in slot order
            if regs[R.I2C_MST_DELAY_CTRL] & (1 << slot) and not delayed_ok:
                continue
            ran = True
            used, data = self._aux_transfer(t, slot, addr_reg & 0x7F, reg, read, n,
                                            regs[R.I2C_SLV_DO[slot]],
                                            bool(ctrl & R.I2C_SLV_REG_DIS))
            bits += used
            if data is None:
                status |= 1 << slot
            elif read:
                if ctrl & R.I2C_SLV_BYTE_SW:
                    data = _swap_pairs(data, reg, bool(ctrl & R.I2C_SLV_GRP))
                for k, byte in enumerate(data):
                    if first + k < 24:
                        ext[first + k] = byte
        slv4 = None
        if regs[R.I2C_SLV4_CTRL] & R.I2C_SLV_EN:
            ran = True
            addr_reg = regs[R.I2C_SLV4_ADDR]
            read = bool(addr_reg & R.I2C_SLV_RNW)
            used, data = self._aux_transfer(t, 4, addr_reg & 0x7F, regs[R.I2C_SLV4_REG], read, 1,
                                            regs[R.I2C_SLV4_DO],
                                            bool(regs[R.I2C_SLV4_CTRL] & R.I2C_SLV_REG_DIS))
            bits += used
            slv4 = (data[0] if read and data else None,
                    R.I2C_MST_STATUS_SLV4_DONE | (R.I2C_MST_STATUS_SLV4_NACK if data is None else 0))
            regs[R.I2C_SLV4_CTRL] &= ~R.I2C_SLV_EN & 0xFF     # a single transfer per enable
        if not ran:
            return None
        khz = R.I2C_MST_CLK_KHZ[regs[R.I2C_MST_CTRL] & 0x0F]

        def apply(te):
            for k, byte in ext.items():
                self.regs[R.EXT_SENS_DATA_00 + k] = byte
            self.regs[R.I2C_MST_STATUS] |= status
            if slv4 is not None:
                di, flags = slv4
                if di is not None:
                    self.regs[R.I2C_SLV4_DI] = di
                self.regs[R.I2C_MST_STATUS] |= flags
        # Scaled with the sample period, so a scaled simulation keeps the real proportions.
        return bits / (khz * 1e3) * self.timing.odr_scale, apply

    def primary_bus_device(self, address, own_address=R.MPU9250_I2C_ADDRESS):
        """Who answers ``address`` on the primary I2C bus (I2C wiring): this part, unless it is
        still starting up (then it does not acknowledge, and being addressed is a violation),
        or an auxiliary device while the bypass is on."""
        if address == own_address:
            if self.busy:
                self._violation("access during start-up", None, "addressed on I2C while busy")
                return None
            return self
        return self.aux_devices.get(address) if self.bypass_active else None

    @property
    def bypass_active(self):
        """The auxiliary bus is joined to the primary I2C pins (I2C wiring only)."""
        return bool(self.regs[R.INT_PIN_CFG] & R.INT_PIN_CFG_BYPASS_EN) and \
            not self.regs[R.USER_CTRL] & R.USER_CTRL_I2C_MST_EN

    # -- INT pin ----------------------------------------------------------------------------------
    @property
    def int_active(self):
        if self.regs[R.INT_PIN_CFG] & R.INT_PIN_CFG_LATCH_INT_EN:
            return bool(self.regs[R.INT_STATUS] & self.regs[R.INT_ENABLE] & R.INT_ENABLE_RAW_RDY)
        return self._pulse_end is not None

    @property
    def int_level(self):
        """Logic level of the INT pin (push-pull; ACTL = 1 makes it active low)."""
        active_low = bool(self.regs[R.INT_PIN_CFG] & R.INT_PIN_CFG_ACTL)
        return int(self.int_active != active_low)

    # -- registers --------------------------------------------------------------------------------
    def _reset_registers(self):
        self.regs[:] = bytes(128)
        self.regs[R.PWR_MGMT_1] = R.PWR_MGMT_1_CLKSEL_AUTO | \
            (R.PWR_MGMT_1_SLEEP if self.sleep_after_reset else 0)
        self.regs[R.WHO_AM_I] = self.who_am_i
        codes = self.self_test_codes
        self.regs[R.SELF_TEST_X_ACCEL:R.SELF_TEST_X_ACCEL + 3] = bytes(codes[:3])
        self.regs[R.SELF_TEST_X_GYRO:R.SELF_TEST_X_GYRO + 3] = bytes(codes[3:])

    def _violation(self, kind, register, detail):
        v = Violation(self.now, kind, register, detail)
        self.violations.append(v)
        if self.raise_on_violation:
            raise ProtocolError(str(v))

    def begin_read(self):
        """Start of a read burst: the part's shadow registers hold still until it ends."""
        self._snapshot = bytes(self.regs)
        self._snapshot_sample = len(self.samples) - 1
        self._burst_start = None

    @staticmethod
    def next_address(addr):
        return (addr + 1) & 0x7F

    def read_reg(self, addr):
        # ``line_flips`` {register: mask}: bits the data line inverts on the next read of that
        # register (a glitch in transit: the register itself keeps its value)
        value = self._snapshot[addr] ^ self.line_flips.pop(addr, 0)
        if self._burst_start is None:
            self._burst_start = addr
        if addr == R.ACCEL_XOUT_H and self._burst_start == R.ACCEL_XOUT_H:
            self.self_test_reads.append(self._snapshot_sample)     # the self-test's bursts
        elif addr == R.ACCEL_XOUT_H:
            self.sample_reads.append(self._snapshot_sample)
            self.ext_reads.append(self._snapshot[R.EXT_SENS_DATA_00:R.EXT_SENS_DATA_00 + 8])
        if addr == R.INT_STATUS or self.regs[R.INT_PIN_CFG] & R.INT_PIN_CFG_ANYRD_2CLEAR:
            self.regs[R.INT_STATUS] = 0
        if addr == R.I2C_MST_STATUS:
            # clears on read: the bits the read returned (the burst's snapshot); a bit set since
            # the burst began (an SLV4 transfer ending) stays for the next read
            self.regs[R.I2C_MST_STATUS] &= ~value & 0xFF
        return value

    def write_reg(self, addr, value):
        if addr in R.READ_ONLY:
            self._violation("write to a read-only register", addr, f"value 0x{value:02X}")
            return
        self.writes.append((self.now, addr, value))
        if addr == R.PWR_MGMT_1 and value & R.PWR_MGMT_1_H_RESET:
            self.resets += 1
            self._reset_registers()
            self._busy_until = self.now + self.timing.reset_s
            self._next_sample = self._pulse_end = self._aux_done = None
            self._update_next_event()
            return
        if addr == R.USER_CTRL:
            value &= ~R.USER_CTRL_SELF_CLEARING
        self.regs[addr] = value
        if addr in (R.PWR_MGMT_1, R.CONFIG, R.GYRO_CONFIG, R.SMPLRT_DIV):
            self._reschedule(self.now)

    # -- SPI pins ---------------------------------------------------------------------------------
    @property
    def sdo_change_at(self):
        """When SDO next changes (None: nothing in flight)."""
        return self._sdo_pending[0][0] if self._sdo_pending else None

    def sdo_at(self, t):
        """The level of SDO at time ``t`` (a new bit only once its delay has passed, strictly:
        a bit arriving exactly on a clock edge counts as too late for it)."""
        pending = self._sdo_pending
        while pending and t - pending[0][0] > _EPS:
            self._sdo_level = pending.popleft()[1]
        return self._sdo_level

    def ramp_sdo_drift(self, t, rate, until=None):
        """From time ``t`` the drift moves by ``rate`` (seconds of delay per second) until
        ``until`` (None: for ever), from where it is (as temperature moves a part)."""
        self.sdo_drift_s = self.drift_at(t)
        self._drift_ramp = (t, rate, until)

    def drift_at(self, t):
        """The drift at time ``t`` (``sdo_drift_s`` and a ramp's part)."""
        if self._drift_ramp is None:
            return self.sdo_drift_s
        start, rate, until = self._drift_ramp
        end = t if until is None else min(t, until)
        return self.sdo_drift_s + rate * max(0.0, end - start)

    def _bit_delay(self, t):
        """A bit's delay at ``t``: the part's and the board's, the drift, the jitter."""
        timing = self.timing
        jitter = timing.sdo_jitter_s
        return timing.sdo_round_trip_s + self.drift_at(t) + \
            (self._sdo_rng.uniform(-jitter, jitter) if jitter else 0.0)

    def _drive_sdo(self, t, bit, delay):
        """SDO shows ``bit`` ``delay`` after ``t`` (0: at once, what was in flight dropped),
        after the transitions already in flight."""
        self.sdo_at(t)
        if delay == 0:
            self._sdo_level = bit
            self._sdo_pending.clear()
            return
        pending = self._sdo_pending
        if bit == (pending[-1][1] if pending else self._sdo_level):
            return                      # no transition (and no wake for one)
        when = t + delay
        if pending:
            when = max(when, pending[-1][0])
        pending.append((when, bit))

    def cs_edge(self, t, cs_n):
        """Chip select changed to ``cs_n`` at time ``t``."""
        self.advance(t)
        if not cs_n and not self.selected:
            self.selected = True
            self._t_cs = t
            self._bits = 0
            self._shift_in = 0
            self._out = 0
            self._reading = False
            self._addr = None
            self._last_rise = self._last_edge = self._first_fall = None
            self._byte_timing = [math.inf, math.inf, math.inf]  # period, high, low
            self._ignored = self.busy
            if self.sclk == 0:
                self._violation("SPI mode", None, "SCLK was low when CS fell; mode 3 idles high")
            if self._ignored:
                self._violation("access during start-up", None,
                                f"part is busy for another {(self._busy_until - t) * 1e6:.3f} us")
        elif cs_n and self.selected:
            self.selected = False
            first = None if self._bits < 8 else (self._addr - self._bits // 8 + 1) & 0x7F
            self.transactions.append((self._t_cs, t, first, self._bits // 8, self._reading))
            if self._bits % 8:
                self._violation("CS raised mid-byte", self._addr,
                                f"{self._bits % 8} bits of a byte were sent")
            if self._last_rise is not None and t - self._last_rise + _EPS < self.CS_HOLD_S:
                self._violation("CS hold", self._addr,
                                f"{(t - self._last_rise) * 1e9:.1f} ns < 500 ns")
            self._drive_sdo(t, 0, 0)

    def sclk_edge(self, t, level, mosi):
        """SCLK changed to ``level`` at time ``t``; ``mosi`` is the level of SDI then."""
        self.advance(t)
        previous, self.sclk = self.sclk, level
        if not self.selected or previous == level:
            return
        timing = self._byte_timing
        if self._last_edge is not None:
            timing[2 if level else 1] = min(timing[2 if level else 1], t - self._last_edge)
        self._last_edge = t
        if not level:
            if self._first_fall is None:
                self._first_fall = t
                if t - self._t_cs + _EPS < self.CS_SETUP_S:
                    self._violation("CS setup", None, f"{(t - self._t_cs) * 1e9:.1f} ns < 8 ns")
            if self._reading and self._bits % 8 == 0:
                self._out = 0 if self._ignored else self.read_reg(self._addr)
                self._addr = (self._addr + 1) & 0x7F
            self._drive_sdo(t, (self._out >> (7 - self._bits % 8)) & 1 if self._reading else 0,
                            self._bit_delay(t))
        else:
            if self._last_rise is not None:
                timing[0] = min(timing[0], t - self._last_rise)
            self._last_rise = t
            self._shift_in = ((self._shift_in << 1) | (mosi & 1)) & 0xFF
            self._bits += 1
            if self._bits % 8 == 0:
                self._byte_done(self._shift_in)

    def _byte_done(self, byte):
        first = self._bits == 8
        if first:
            self._reading = bool(byte & R.SPI_READ)
            self._addr = byte & 0x7F
            if self._reading:
                self.begin_read()
            register = self._addr
        else:
            register = (self._addr - 1) & 0x7F if self._reading else self._addr
        self._check_rate(register)
        if not first and not self._reading:
            if not self._ignored:
                self.write_reg(self._addr, byte)
            self._addr = (self._addr + 1) & 0x7F

    def _check_rate(self, register):
        period, high, low = self._byte_timing
        self._byte_timing = [math.inf, math.inf, math.inf]
        fast_ok = self._reading and R.FAST_READ_FIRST <= register <= R.FAST_READ_LAST
        max_hz, min_level = ((self.FAST_MAX_HZ, self.FAST_MIN_LEVEL_S) if fast_ok else
                             (self.SLOW_MAX_HZ, self.SLOW_MIN_LEVEL_S))
        if period + _EPS < 1 / max_hz:
            what = "sensor read" if fast_ok else "non-sensor register access"
            self._violation("SCLK too fast", register,
                            f"{1e-6 / period:.3f} MHz > {max_hz / 1e6:g} MHz for a {what}")
        if min(high, low) + _EPS < min_level:
            self._violation("SCLK level too short", register,
                            f"high {high * 1e9:.1f} ns, low {low * 1e9:.1f} ns, "
                            f"need {min_level * 1e9:.0f} ns")
