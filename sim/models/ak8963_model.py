"""Behavioural model of the AK8963 magnetometer at register level.

Two buses reach it: the MPU9250 model's auxiliary I2C master (SPI wiring) and the bit-level I2C
bus model in ``sim.models.i2c_bus`` (I2C wiring, through the MPU9250's bypass multiplexer). Both use the
register-device interface every model here offers: ``read_reg``, ``write_reg``,
``next_address`` (auto-increment with the part's wrap rules) and ``advance(t)``.

Behaviour (``shared/mpu9250-notes.md``, AK8963 datasheet):
- WIA = 0x48; ASAX/Y/Z (fuse ROM, configurable) readable in fuse-ROM mode only.
- CNTL1: MODE (power-down, single, continuous 8/100 Hz, external trigger, self-test, fuse ROM) and
  BIT (16-bit 0.15 µT/LSB, or 14-bit 0.6 µT/LSB). CNTL2.SRST resets every register.
- A mode other than power-down may only be entered from power-down, at least ``power_down_s``
  (100 µs) after entering it: otherwise a ``Violation``.
- Measurements: ST1.DRDY set when new data is ready; reading a data register starts data
  protection (the registers stay frozen) until ST2 is read; a measurement finishing meanwhile, or
  while unread data is pending, is skipped and sets ST1.DOR. Reading ST2 (or a data register)
  clears DRDY and DOR. ST2.HOFL when |X|+|Y|+|Z| ≥ 4912 µT; ST2.BITM mirrors CNTL1.BIT.
- Auto-increment wraps 0x00..0x0C -> 0x00 and 0x10..0x12 -> 0x10.
- Self-test mode with ASTC.SELF: one measurement, as a single one, of ``self_test_field``
  instead of the source's field; then power-down.

The field source gives ``(hx, hy, hz)`` in 16-bit counts (0.15 µT/LSB) in the AK8963's own axes;
14-bit mode divides by 4. Values outside ±32760 are clipped (and raise HOFL by their size).
"""

from dataclasses import dataclass, replace

from ...hdl.contract import ak8963_regs as A
from .mpu9250_model import Violation, ProtocolError


__all__ = ["AK8963Timing", "AK8963Model", "constant_field", "DEFAULT_SELF_TEST_FIELD"]

# the self-test generator's field of a good part, raw 16-bit LSB (with the default ASA about
# 36, -24, -1728 after adjustment: inside the datasheet's limits)
DEFAULT_SELF_TEST_FIELD = (30, -20, -1500)

_EPS = 1e-12
_READ_ONLY = frozenset({A.WIA, A.INFO, A.ST1, *range(A.HXL, A.HZH + 1), A.ST2,
                        *range(A.ASAX, A.ASAZ + 1)})


def constant_field(hx=0, hy=0, hz=0):
    return lambda index, t: (hx, hy, hz)


@dataclass(frozen=True)
class AK8963Timing:
    single_s: float = 7.2e-3        # single measurement time (≤ 9 ms)
    power_down_s: float = 100e-6    # minimum time in power-down before another mode
    odr_scale: float = 1.0          # period multiplier for continuous modes and single time

    def scaled(self, odr=1.0):
        return replace(self, odr_scale=self.odr_scale * odr)


class AK8963Model:
    def __init__(self, *, asa=(176, 178, 167), wia=A.WIA_VALUE, source=None,
                 timing=AK8963Timing(), raise_on_violation=False,
                 self_test_field=DEFAULT_SELF_TEST_FIELD):
        self.asa = tuple(asa)
        self.wia = wia
        self.source = source or constant_field()
        self.timing = timing
        self.raise_on_violation = raise_on_violation
        # what its self-test generator makes (raw 16-bit LSB, before ASA), instead of the field
        self.self_test_field = list(self_test_field)
        self.violations = []
        self.writes = []            # (t, register, value)
        self.measurements = []      # (hx, hy, hz, hofl) as stored, in order
        self.skipped = 0
        self.now = 0.0
        self.pointer = 0            # register pointer, kept by the bus that talks to the part
        self._reset()

    def _reset(self):
        self.regs = bytearray(0x13)
        self.regs[A.WIA] = self.wia
        self.regs[A.INFO] = 0x9A
        self.mode = A.MODE_POWER_DOWN
        self._power_down_at = -1.0
        self._next_measure = None
        self._protected = False

    def _violation(self, kind, register, detail):
        v = Violation(self.now, kind, register, detail)
        self.violations.append(v)
        if self.raise_on_violation:
            raise ProtocolError(str(v))

    # -- time -------------------------------------------------------------------------------------
    @property
    def next_event(self):
        return self._next_measure

    def advance(self, t):
        while self._next_measure is not None and self._next_measure <= t + _EPS:
            ev = self._next_measure
            self._measure(ev)
            if self.mode in (A.MODE_SINGLE, A.MODE_SELF_TEST):
                self.mode = A.MODE_POWER_DOWN
                self._power_down_at = ev
                self.regs[A.CNTL1] &= A.CNTL1_BIT_16
                self._next_measure = None
            else:
                self._next_measure = ev + self._period()
        self.now = t

    def _period(self):
        hz = {A.MODE_CONT_8HZ: 8.0, A.MODE_CONT_100HZ: 100.0}.get(self.mode)
        return self.timing.odr_scale / hz if hz else None

    def _measure(self, t):
        hx, hy, hz = (int(v) for v in self.source(len(self.measurements) + self.skipped, t))
        if self.mode == A.MODE_SELF_TEST and self.regs[A.ASTC] & A.ASTC_SELF:
            hx, hy, hz = (int(v) for v in self.self_test_field)
        if self._protected:
            self.skipped += 1
            self.regs[A.ST1] |= A.ST1_DOR
            return
        if self.regs[A.ST1] & A.ST1_DRDY:
            self.regs[A.ST1] |= A.ST1_DOR           # the previous result was never read
        hofl = (abs(hx) + abs(hy) + abs(hz)) * A.UT_PER_LSB_16 >= A.OVERFLOW_UT
        bit16 = bool(self.regs[A.CNTL1] & A.CNTL1_BIT_16)
        limit = 32760 if bit16 else 8190
        values = [max(-limit, min(limit, v if bit16 else round(v / 4))) for v in (hx, hy, hz)]
        for i, v in enumerate(values):
            self.regs[A.HXL + 2 * i:A.HXL + 2 * i + 2] = (v & 0xFFFF).to_bytes(2, "little")
        self.regs[A.ST2] = (A.ST2_HOFL if hofl else 0) | (A.ST2_BITM if bit16 else 0)
        self.regs[A.ST1] |= A.ST1_DRDY
        self.measurements.append((*values, hofl))

    # -- registers --------------------------------------------------------------------------------
    def begin_read(self):
        pass

    @staticmethod
    def next_address(addr):
        if A.ASAX <= addr <= A.ASAZ:
            return A.ASAX if addr == A.ASAZ else addr + 1
        return 0x00 if addr >= A.ASTC else addr + 1

    def read_reg(self, addr):
        if A.ASAX <= addr <= A.ASAZ:
            if self.mode != A.MODE_FUSE_ROM:
                self._violation("ASA read outside fuse-ROM mode", addr, "reads 0x00")
                return 0
            return self.asa[addr - A.ASAX]
        if addr > A.ASTC and addr != A.I2CDIS:
            return 0
        value = self.regs[addr]
        if A.HXL <= addr <= A.HZH:
            self._protected = True
            self.regs[A.ST1] &= ~(A.ST1_DRDY | A.ST1_DOR) & 0xFF
        elif addr == A.ST2:
            self._protected = False
            self.regs[A.ST1] &= ~(A.ST1_DRDY | A.ST1_DOR) & 0xFF
        return value

    def write_reg(self, addr, value):
        if addr in _READ_ONLY:
            self._violation("write to a read-only register", addr, f"value 0x{value:02X}")
            return
        self.writes.append((self.now, addr, value))
        if addr == A.CNTL2:
            if value & A.CNTL2_SRST:
                self._reset()
            return
        if addr == A.CNTL1:
            self._set_mode(value)
            return
        if addr in (A.ASTC, A.I2CDIS):
            self.regs[addr] = value

    def _set_mode(self, value):
        mode = value & 0x0F
        if mode not in (A.MODE_POWER_DOWN, A.MODE_SINGLE, A.MODE_CONT_8HZ, A.MODE_CONT_100HZ,
                        A.MODE_EXT_TRIG, A.MODE_SELF_TEST, A.MODE_FUSE_ROM):
            self._violation("undefined CNTL1 mode", A.CNTL1, f"MODE = 0x{mode:X}")
            return
        if mode != A.MODE_POWER_DOWN:
            if self.mode != A.MODE_POWER_DOWN:
                self._violation("mode change without power-down", A.CNTL1,
                                f"from mode 0x{self.mode:X} to 0x{mode:X}")
            elif self.now - self._power_down_at + _EPS < self.timing.power_down_s:
                self._violation("power-down wait", A.CNTL1,
                                f"{(self.now - self._power_down_at) * 1e6:.1f} us < "
                                f"{self.timing.power_down_s * 1e6:.0f} us before mode 0x{mode:X}")
        elif self.mode != A.MODE_POWER_DOWN:
            self._power_down_at = self.now
        self.mode = mode
        self.regs[A.CNTL1] = value & 0x1F
        period = self._period()
        if mode in (A.MODE_SINGLE, A.MODE_SELF_TEST):
            self._next_measure = self.now + self.timing.single_s * self.timing.odr_scale
        elif period is not None:
            self._next_measure = self.now + period
        else:
            self._next_measure = None
