"""Waveforms of the co-simulations: the GTKWave save file beside a VCD, and where it opens
(the first sensor transaction, at a readable scale)."""

import math
import re
from pathlib import Path


__all__ = ["gtkw_beside", "GTKW_WIDTH_PX", "gtkw_window", "first_transaction_window",
           "vcd_timescale_s", "open_on_first_transaction"]


def gtkw_beside(vcd):
    """The GTKWave save file written beside the VCD ``vcd`` (its name, ``.gtkw``)."""
    return str(vcd).rsplit(".", 1)[0] + ".gtkw"


# The width of GTKWave's wave area the save file's zoom is set for, pixels.
GTKW_WIDTH_PX = 1000


def gtkw_window(gtkw, window_s, timescale_s):
    """Make the GTKWave save file ``gtkw`` open on ``window_s`` = (start, end), seconds of
    simulated time (a VCD whose time unit is ``timescale_s``), about ``GTKW_WIDTH_PX`` pixels
    wide: ``[timestart]`` and the zoom line. GTKWave shows ``2**-zoom`` time units per 200
    pixels (its zoom base, 2 unless changed in its settings)."""
    start, end = window_s
    span = max(end - start, 1e-9) / timescale_s
    zoom = -math.log2(span * 200 / GTKW_WIDTH_PX)
    lines = [line for line in Path(gtkw).read_text().splitlines()
             if not line.startswith(("[timestart]", "*"))]
    at = max(i for i, line in enumerate(lines) if line.startswith("[dumpfile")) + 1
    lines[at:at] = [f"[timestart] {max(0, round(start / timescale_s))}",
                    f"*{zoom:.6f} -1" + " -1" * 26]
    Path(gtkw).write_text("\n".join(lines) + "\n")


def first_transaction_window(model, bus, margin=0.25):
    """(start, end) of the first sensor transaction, seconds, widened by ``margin`` of its
    length either side: the SPI model's first chip select, or the I2C bus's first START to
    STOP. None if there was none."""
    spans = bus.frames if bus is not None else (model.transactions if model else [])
    if not spans:
        return None
    start, end = spans[0][0], spans[0][1]
    pad = (end - start) * margin
    return start - pad, end + pad


_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "ps": 1e-12, "fs": 1e-15}


def vcd_timescale_s(vcd):
    """The time unit of the VCD file ``vcd``, seconds, from its ``$timescale`` header (the
    compiled path's counts picoseconds, Amaranth's femtoseconds)."""
    with open(vcd) as f:
        head = f.read(4096)
    found = re.search(r"\$timescale\s*(\d+)\s*([munpf]?s)\s*\$end", head)
    if found is None:
        raise ValueError(f"{vcd}: no $timescale in its header")
    return int(found.group(1)) * _UNITS[found.group(2)]


def open_on_first_transaction(vcd, model, bus):
    """The save file beside ``vcd`` opens on the first sensor transaction, in the VCD's own
    time unit."""
    window = first_transaction_window(model, bus)
    if window is not None:
        gtkw_window(gtkw_beside(vcd), window, vcd_timescale_s(vcd))
