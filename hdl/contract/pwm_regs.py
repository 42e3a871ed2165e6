"""The PWM block's contract (``hdl/FRAMES.md``, space 0x02): its registers, channels and
limits. Plain data: the gateware's ``link.pwm`` and the host's ``config`` and ``regmap`` read
the same tables."""

__all__ = ["PWM_REGS", "PWM_CHANNELS", "SERVO_PERIOD_US", "MOTOR_MAX_HZ", "PERIOD_BITS",
           "WATCHDOG_MS_AT_RESET"]


PWM_CHANNELS = 4
PERIOD_BITS = 16
SERVO_PERIOD_US = (2_500, 20_000)      # 400 .. 50 Hz frames
MOTOR_MAX_HZ = 20_000
WATCHDOG_MS_AT_RESET = 500

# Register addresses in the PWM block's space (the command channel's 0x02xx).
PWM_REGS = {
    "PWM_ENABLE": 0x00, "PWM_MODE": 0x01, "PWM_WATCHDOG_MS": 0x02, "PWM_STATUS": 0x03,
    "PWM_SERVO_PERIOD": 0x04, "PWM_MOTOR_PERIOD": 0x05,
    **{f"PWM_HIGH{k}": 0x10 + k for k in range(PWM_CHANNELS)},
}
