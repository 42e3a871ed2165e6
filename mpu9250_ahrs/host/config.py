"""``config``: read and write the board's registers by name, in physical units."""

from ..hdl.contract.filter_registry import FILTER_CODES
from ..hdl.contract.pwm_regs import MOTOR_MAX_HZ, PERIOD_BITS, PWM_CHANNELS, SERVO_PERIOD_US
from .link import BoardError
from .regmap import from_word, lookup, to_word


__all__ = ["get", "set_register", "select_filter", "reset_filter", "set_rate", "sample_rate"]


def get(link, name):
    reg = lookup(name)
    reply = link.check(link.command("read", addr=reg.addr, space=reg.space), f"read {reg.name}")
    word = reply["value"]
    if reg.space == "engine" and word >= 2 ** 31:
        word -= 2 ** 32                       # engine words are signed
    return {"name": reg.name, "value": from_word(reg, word), "unit": reg.unit,
            "word": reply["value"], "format": reg.format}


def set_register(link, name, value):
    """Write ``value`` (physical units) and read it back; returns the read-back."""
    reg = lookup(name)
    if not reg.writable:
        raise BoardError(f"{reg.name} is read-only")
    try:
        word = to_word(reg, value)
    except ValueError as e:
        raise BoardError(str(e)) from None
    reply = link.command("write", addr=reg.addr, value=word, space=reg.space)
    if reply["result_name"] == "refused" and reg.space == "pwm":
        raise BoardError(f"write {reg.name} = {value}: the board refused it: "
                         f"{_pwm_refusal(link, reg.name, word)}")
    link.check(reply, f"write {reg.name} = {value}")
    back = get(link, reg.name)
    if back["word"] != word & 0xFFFFFFFF and reg.name != "CONTROL":
        raise BoardError(f"{reg.name}: wrote 0x{word & 0xFFFFFFFF:08X}, read back "
                         f"0x{back['word']:08X}")
    return back


def _pwm_refusal(link, name, word):
    """Why the PWM block refuses a write of ``word`` to ``name`` (its rules: ``PWMOutputs``),
    with the registers the rule reads, read now."""
    def value(reg):
        return get(link, reg)["value"]
    channels = f"bits {PWM_CHANNELS - 1}:0, one per channel"
    most = f"{(1 << PERIOD_BITS) - 1:,}"               # the 16-bit registers' largest
    if name == "PWM_ENABLE":
        return f"{word} is not {channels}"
    if name == "PWM_MODE":
        if word >> PWM_CHANNELS:
            return f"{word} is not {channels}"
        return (f"an enabled channel's mode stays (PWM_ENABLE = {value('PWM_ENABLE')}, "
                f"PWM_MODE = {value('PWM_MODE')}): disable the channel first")
    if name == "PWM_WATCHDOG_MS":
        return f"the watchdog is 0 (off) .. {most} ms"
    if name == "PWM_SERVO_PERIOD":
        return f"the servo period is {SERVO_PERIOD_US[0]:,} .. {SERVO_PERIOD_US[1]:,} µs"
    if name == "PWM_MOTOR_PERIOD":
        return (f"the motor period is at least the clock's cycles in 1/{MOTOR_MAX_HZ:,} s, "
                f"at most {most} cycles")
    if name.startswith("PWM_HIGH"):
        k = int(name[len("PWM_HIGH"):])
        motor = value("PWM_MODE") >> k & 1
        period = "PWM_MOTOR_PERIOD" if motor else "PWM_SERVO_PERIOD"
        return (f"more than channel {k}'s period ({'motor' if motor else 'servo'} mode: "
                f"{period} = {value(period):,} {'cycles' if motor else 'µs'})")
    return "out of its range (PWMOutputs)"


def select_filter(link, name):
    if name not in FILTER_CODES:
        raise BoardError(f"no filter {name!r}; known: {', '.join(FILTER_CODES)}")
    link.check(link.command("filter", value=FILTER_CODES[name]), f"filter {name}")
    return {"filter": name}


def reset_filter(link):
    link.check(link.command("reset"), "reset")
    return {"reset": True}


def sample_rate(link):
    """The board's sample rate (Hz), from its sample period register T (Q0.24 s)."""
    t = get(link, "T")["value"]
    if t <= 0:
        raise BoardError(f"the board's sample period T reads {t}")
    return 1 / t


def set_rate(link, hz):
    """Telemetry at about ``hz`` frames/s: the divider round(sample rate / hz)."""
    if not hz > 0:
        raise BoardError(f"rate must be above 0, not {hz}")
    odr = sample_rate(link)
    wanted = round(odr / hz)
    divider = max(1, min(65535, wanted))
    link.check(link.command("rate", value=divider), f"rate {hz}")
    result = {"rate_hz": odr / divider, "divider": divider, "sample_rate_hz": odr}
    if divider != wanted:
        # the divider's range: a frame per sample at the most, per 65,535 at the least
        result["note"] = (f"{hz:g} Hz is beyond the telemetry's range at {odr:g} samples/s "
                          f"({odr:g} .. {odr / 65535:.3g} Hz): {odr / divider:.6g} Hz set")
    return result
