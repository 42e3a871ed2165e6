"""The balance controller's contract (issue #57; ``hdl/control/balance_controller.py``): its
registers, their widths and ranges, the trips and the build constants. Plain data: the
gateware, the fixed-point reference (``reference/balance_control.py``) and the tests read the
same tables."""

__all__ = ["BALANCE_REGS", "BALANCE_WIDTHS", "BALANCE_RESET", "TRIPS", "CONTROL_BITS",
           "GAIN_BITS", "GAIN_SHIFT", "INTEGRAL_SHIFT", "INTEGRAL_BITS", "W_FRACTION",
           "DUTY_BITS", "DUTY_FULL", "PWM_STEPS_MAX_HZ"]


# the duty: signed, in 1/1024 of the battery (|duty| <= 1023)
DUTY_BITS = 11
DUTY_FULL = 1 << (DUTY_BITS - 1)
GAIN_BITS = 18                  # the gains: signed, an 18x18 multiplier's operand
GAIN_SHIFT = 8                  # the products' sum >> 8 is the duty
INTEGRAL_SHIFT = 8              # the integral's word in the sum: i >> 8
INTEGRAL_BITS = 24              # the integral: |i| <= BAL_I_LIMIT < 2^23
W_FRACTION = 8                  # the duty's low-pass: the duty's units · 2^8
PWM_STEPS_MAX_HZ = 25_000       # the motor PWM's frequency at most (1024 steps a period)

# BAL_CONTROL's bits
CONTROL_BITS = {"arm": 0, "roll": 1, "pin_arms": 3}       # bit 2 reserved
# why the controller disarmed itself (BAL_STATUS bits 4.., one-hot, the last trip's)
TRIPS = ("fallen", "fault", "stale", "watchdog")

# name: address (in the controller's register space)
BALANCE_REGS = {
    "BAL_CONTROL": 0x00,     # bit 0 arm (1 arms, 0 disarms; reads 1 while armed), bit 1 the
                             # axis (0 pitch, 1 roll), bit 2 reserved (a rate of the other sign:
                             # BAL_KD's sign), bit 3 the
                             # arming pin arms (its rising edge) and disarms (its falling)
    "BAL_STATUS": 0x01,      # read only: bit 0 armed, bit 1 armed by the host (the watchdog
                             # applies), bits 7:4 the last trip (TRIPS, one-hot)
    "BAL_SETPOINT": 0x02,    # the tilt held: signed 16 bits, 2^16 = 360°
    "BAL_KP": 0x03,          # the gains: signed 18 bits (reference/balance_control.py)
    "BAL_KD": 0x04,
    "BAL_KI": 0x05,
    "BAL_KV": 0x06,
    "BAL_OUT_LIMIT": 0x07,   # the largest |duty|: 0 .. 1023
    "BAL_I_LIMIT": 0x08,     # the integral's bound: 0 .. 2^23 - 1 (e units x samples): it
                             # integrates only while it stays within; a write sets it to 0
    "BAL_CUTOFF": 0x09,      # |e| beyond it trips "fallen": 0 .. 32767
    "BAL_STALE": 0x0A,       # sample periods without a result before "stale": 1 .. 255
    "BAL_WATCHDOG": 0x0B,    # host-armed: sample periods without an accepted command before
                             # "watchdog": 0 (off) .. 4095 (4 s at 1 kHz)
    "BAL_DUTY": 0x0C,        # read only: the duty now (signed, 1/1024)
}
# writable registers: (bits, signed, lowest, highest)
BALANCE_WIDTHS = {
    "BAL_CONTROL": (4, False, 0, 15),
    "BAL_SETPOINT": (16, True, -(1 << 15), (1 << 15) - 1),
    **{name: (GAIN_BITS, True, -(1 << (GAIN_BITS - 1)), (1 << (GAIN_BITS - 1)) - 1)
       for name in ("BAL_KP", "BAL_KD", "BAL_KI", "BAL_KV")},
    "BAL_OUT_LIMIT": (10, False, 0, DUTY_FULL - 1),
    "BAL_I_LIMIT": (INTEGRAL_BITS - 1, False, 0, (1 << (INTEGRAL_BITS - 1)) - 1),
    "BAL_CUTOFF": (15, False, 0, (1 << 15) - 1),
    "BAL_STALE": (8, False, 1, 255),
    "BAL_WATCHDOG": (12, False, 0, 4095),
}
# the values at reset (a build may set others: ``BalanceController(config=...)``)
BALANCE_RESET = {"BAL_CONTROL": 0, "BAL_STALE": 5, "BAL_WATCHDOG": 500}
