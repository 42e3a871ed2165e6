"""``config``: read and write the board's registers by name, in physical units."""

from ..hdl.filter_registry import FILTER_CODES
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
    link.check(link.command("write", addr=reg.addr, value=word, space=reg.space),
               f"write {reg.name} = {value}")
    back = get(link, reg.name)
    if back["word"] != word & 0xFFFFFFFF and reg.name != "CONTROL":
        raise BoardError(f"{reg.name}: wrote 0x{word & 0xFFFFFFFF:08X}, read back "
                         f"0x{back['word']:08X}")
    return back


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
    divider = max(1, min(65535, round(odr / hz)))
    link.check(link.command("rate", value=divider), f"rate {hz}")
    return {"rate_hz": odr / divider, "divider": divider, "sample_rate_hz": odr}
