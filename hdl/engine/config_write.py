"""The configuration layout: a host's write to the attitude engine's register map."""

from amaranth.hdl import signed
from amaranth.lib import data


__all__ = ["ConfigWrite"]


class ConfigWrite(data.Struct):
    """A write to the attitude engine's register map (``hdl/engine/register_map.py``)."""
    addr: 8
    data: signed(32)
