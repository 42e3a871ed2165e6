"""Bit-level I2C bus model: the devices' side of SCL and SDA.

``I2CBusModel`` watches the two (wired-AND) line levels with time stamps and plays every device
on the bus: START/STOP detection, address matching with ACK or NACK, a register pointer set by
the first written byte, writes and reads that auto-increment with each device's own rule
(``next_address``), ACK/NACK from the controller on reads. Devices are register devices
(``read_reg``, ``write_reg`` — returning False to NACK the byte —, ``next_address``,
``begin_read``, ``pointer``, ``advance``) and are looked up
when addressed (``devices`` is a dict or a function of the address), so a device can appear
later: the AK8963 once the MPU9250's bypass is on.

What it can do to the controller:
- ``stretch_s``: hold SCL low that long after every acknowledge (clock stretching);
- ``stuck_clocks``: start with SDA held low, as a device interrupted mid-read holds it, until
  that many SCL clocks have gone by.

Faults to inject mid-run (``sim.scenarios.faults``): ``hold_sda(clocks)`` holds SDA low from now on for that
many SCL clocks (a device that lost its place; ``release_sda`` ends it), ``nack_next`` NACKs the
next that-many register-pointer bytes (to ``nack_address``, or any device if None): a NACK in
the middle of a transfer.

What it checks (``violations``), against the I2C-bus specification's fast mode by default
(``standard_mode=True`` for 100 kHz): SCL low ≥ 1.3 µs and high ≥ 0.6 µs, START hold ≥ 0.6 µs,
repeated-START setup ≥ 0.6 µs, STOP setup ≥ 0.6 µs, bus free between STOP and START ≥ 1.3 µs,
and SDA changing while SCL is high in the middle of a byte.
"""

import math

from .mpu9250_model import ProtocolError, Violation


__all__ = ["I2CBusModel"]

_EPS = 1e-12


class I2CBusModel:
    FAST = dict(low=1.3e-6, high=0.6e-6, hd_sta=0.6e-6, su_sta=0.6e-6, su_sto=0.6e-6, buf=1.3e-6)
    STANDARD = dict(low=4.7e-6, high=4.0e-6, hd_sta=4.0e-6, su_sta=4.7e-6, su_sto=4.0e-6,
                    buf=4.7e-6)

    def __init__(self, devices, *, stretch_s=0.0, stuck_clocks=0, standard_mode=False,
                 raise_on_violation=False):
        # A dict {address: device}, or a callable address -> device or None.
        self._lookup = devices if callable(devices) else devices.get
        self.stretch_s = stretch_s
        self.limits = self.STANDARD if standard_mode else self.FAST
        self.raise_on_violation = raise_on_violation
        self.violations = []
        self.log = []               # (t, address, "r"/"w", register, bytes) per transfer
        self.frames = []            # (t START, t STOP, index of its first ``log`` entry)
        self.starts = 0
        self.now = 0.0
        self.scl = self.sda = 1
        self.scl_low = False        # what the devices drive
        self.sda_low = stuck_clocks > 0
        self._stuck = stuck_clocks
        self.nack_next = 0
        self.nack_address = None
        self._stretch_until = None
        self._state = "idle"
        self._t_scl = {0: -math.inf, 1: -math.inf}   # last time SCL went to that level
        self._t_start = self._t_stop = -math.inf
        self._byte_open = False

    # -- bookkeeping ------------------------------------------------------------------------------
    def _violation(self, kind, detail):
        v = Violation(self.now, kind, None, detail)
        self.violations.append(v)
        if self.raise_on_violation:
            raise ProtocolError(str(v))

    def _check(self, kind, since, limit):
        if self.now - since + _EPS < self.limits[limit]:
            self._violation(kind, f"{(self.now - since) * 1e6:.3f} us < "
                                  f"{self.limits[limit] * 1e6:.1f} us")

    @property
    def next_event(self):
        return self._stretch_until

    def advance(self, t):
        self.now = t
        if self._stretch_until is not None and t + _EPS >= self._stretch_until:
            self._stretch_until = None
            self.scl_low = False

    def hold_sda(self, clocks):
        """From now on, hold SDA low for ``clocks`` SCL clocks (a device out of step)."""
        self._stuck, self.sda_low = clocks, True

    def release_sda(self):
        self._stuck, self.sda_low = 0, False

    # -- lines ------------------------------------------------------------------------------------
    def lines(self, t, scl, sda):
        """The line levels at time ``t`` (after any change)."""
        self.advance(t)
        if scl != self.scl:
            self.scl = scl
            if scl:
                self._check("SCL low time", self._t_scl[0], "low")
            else:
                self._check("SCL high time", self._t_scl[1], "high")
                if self._t_start > self._t_scl[1]:
                    self._check("START hold time", self._t_start, "hd_sta")
            self._t_scl[scl] = t
            self._rise() if scl else self._fall()
        if sda != self.sda:
            self.sda = sda
            if self.scl:
                if not sda:
                    self._on_start()
                else:
                    self._on_stop()

    def _on_start(self):
        if self._byte_open:
            self._violation("SDA changed while SCL high", "inside a byte (read as a START)")
        if self._state == "idle":
            self._check("bus free time", self._t_stop, "buf")
            self._frame = (self.now, len(self.log))
        else:
            self._check("repeated START setup", self._t_scl[1], "su_sta")
        self.starts += 1
        self._byte_open = False
        self._t_start = self.now
        self._state = "addr"
        self._phase = 0
        self._shift = 0
        self._release()

    def _on_stop(self):
        if self._byte_open:
            self._violation("SDA changed while SCL high", "inside a byte (read as a STOP)")
        self._check("STOP setup", self._t_scl[1], "su_sto")
        if self._state != "idle" and hasattr(self, "_frame"):
            self.frames.append((self._frame[0], self.now, self._frame[1]))
        self._t_stop = self.now
        self._byte_open = False
        self._state = "idle"
        self._release()

    def _release(self):
        if not self._stuck:
            self.sda_low = False

    def _rise(self):
        if self._state in ("idle", "ignore"):
            return
        if self._phase < 8:
            # The first clock of a "byte" may turn out to be a STOP or repeated START; from
            # the second on, SDA must not change while SCL is high.
            self._byte_open = self._phase >= 1
            if self._state in ("addr", "write"):
                self._shift = ((self._shift << 1) | self.sda) & 0xFF
            self._phase += 1
        elif self._phase == 8:
            self._byte_open = False
            if self._state == "read":
                self._master_ack = not self.sda
            self._phase = 9

    def _fall(self):
        if self._stuck:
            self._stuck -= 1
            if not self._stuck:
                self.sda_low = False
            return
        if self._state in ("idle", "ignore"):
            return
        if self._phase == 8:                       # the ACK clock begins
            if self._state == "read":
                self.sda_low = False               # the controller answers
            else:
                self.sda_low = self._take_byte(self._shift)
        elif self._phase == 9:                     # the ACK clock ended
            self._phase = 0
            self.sda_low = False
            if self.stretch_s > 0:
                self.scl_low = True
                self._stretch_until = self.now + self.stretch_s
            if self._state == "read":
                if self._first_read or self._master_ack:
                    self._first_read = False
                    self._load_read_byte()
                    self._drive_bit()
                else:
                    self._state = "ignore"         # NACKed: wait for STOP or START
            self._shift = 0
        elif self._state == "read":
            self._drive_bit()

    def _take_byte(self, byte):
        """A whole byte was written to the devices; returns whether to acknowledge."""
        if self._state == "addr":
            self._address, reading = byte >> 1, byte & 1
            self._device = self._lookup(self._address)
            if self._device is None:
                self.log.append((self.now, self._address, "r" if reading else "w", None, None))
                self._state = "ignore"
                self._byte_open = False
                return False
            if reading:
                self._state = "read"
                self._first_read = True
                self._device.begin_read()
                self._read_bytes = bytearray()
                self.log.append((self.now, self._address, "r", self._device.pointer,
                                 self._read_bytes))
            else:
                self._state = "write"
                self._pointer_set = False
            return True
        dev = self._device
        if not self._pointer_set:
            self.log.append((self.now, self._address, "w", byte, bytearray()))
            if self.nack_next and self.nack_address in (None, self._address):
                self.nack_next -= 1
                self._state = "ignore"
                self._byte_open = False
                return False
            dev.pointer = byte
            self._pointer_set = True
        else:
            dev.advance(self.now)
            accepted = dev.write_reg(dev.pointer, byte) is not False    # False: NACK it
            dev.pointer = dev.next_address(dev.pointer)
            self.log[-1][4].append(byte)
            return accepted
        return True

    def _load_read_byte(self):
        dev = self._device
        dev.advance(self.now)
        self._out = dev.read_reg(dev.pointer)
        dev.pointer = dev.next_address(dev.pointer)
        self._read_bytes.append(self._out)

    def _drive_bit(self):
        self.sda_low = not (self._out >> (7 - self._phase)) & 1
