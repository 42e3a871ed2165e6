"""Waveforms of the co-simulations, the same from both simulators: what a run traces
(``Waveform``: the file, VCD or FST by its name, and a window of the run), the GTKWave save file
beside it (the design's own signals, grouped by block, opening on the first sensor transaction
in the window) and what is done to Amaranth's simulator's VCD afterwards (cut to the window,
made FST by GTKWave's ``vcd2fst``).

A window's bound is a count of samples (``"5"``: once five samples have come out of the
driver, so the window from 5 to 7 holds the reads of the 6th and 7th) or a time of the
simulated run from its start (``"2ms"``, ``"150us"``, ``"0.01s"``). The compiled simulator
dumps only the window (its file is that small while it runs); Amaranth's simulator writes the
whole run, which is then cut.

``gtkwave_check`` opens a waveform in GTKWave itself (under Xvfb), the only reader that is a
check: ``vcd2fst`` takes files GTKWave refuses.
"""

import dataclasses
import math
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from .compiled_design import NEVER


__all__ = ["Waveform", "parse_bound", "describe", "TraceWindow", "RunTrace", "gtkw_beside",
           "GTKW_WIDTH_PX", "write_gtkw", "layout", "first_transaction_window", "crop_vcd",
           "finish_python_trace", "python_trace_path", "vcd_timescale_s", "gtkwave_check",
           "GTKWAVE_HINT"]

GTKWAVE_HINT = "apt-get install gtkwave xvfb"
FORMATS = {".vcd": "vcd", ".fst": "fst"}


def parse_bound(text, option="--trace-from"):
    """A window bound from its text: ("samples", n) for a whole number, ("s", seconds) for a
    time with its unit (s, ms, us, ns). ValueError naming ``option`` otherwise."""
    text = str(text).strip()
    found = re.fullmatch(r"(\d+)|(\d+(?:\.\d*)?|\.\d+)(?:e([+-]?\d+))?\s*(s|ms|us|ns)", text)
    if found is None:
        raise ValueError(f"{option}: {text!r} is neither a count of samples (5) nor a time "
                         f"with its unit (2ms, 150us, 0.01s)")
    if found.group(1) is not None:
        return ("samples", int(found.group(1)))
    value = float(found.group(2)) * 10 ** int(found.group(3) or 0)
    return ("s", value * {"s": 1, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}[found.group(4)])


@dataclasses.dataclass(frozen=True)
class Waveform:
    """A waveform to write: ``path`` (``.vcd`` or ``.fst``), traced from ``start`` to
    ``stop`` (``parse_bound``'s pairs; None: the run's start, its end)."""
    path: str
    start: tuple = None
    stop: tuple = None

    def __post_init__(self):
        suffix = Path(self.path).suffix.lower()
        if suffix not in FORMATS:
            raise ValueError(f"{self.path}: a waveform file ends in .vcd or .fst (GTKWave's "
                             f"compressed format), not {suffix or 'nothing'!r}")
        if self.start and self.stop and self.start[0] == self.stop[0] and \
                self.stop[1] <= self.start[1]:
            raise ValueError(f"the waveform's window ends ({self.stop[1]:g} {self.stop[0]}) "
                             f"where or before it starts ({self.start[1]:g} {self.start[0]})")

    @classmethod
    def of(cls, wave):
        """None, a ``Waveform``, or a path (the whole run)."""
        if wave is None or isinstance(wave, cls):
            return wave
        return cls(str(wave))

    @property
    def format(self):
        return FORMATS[Path(self.path).suffix.lower()]

    @property
    def gtkw(self):
        return gtkw_beside(self.path)


def describe(bound):
    """A window bound as words: '5 samples', '2 ms' (None: 'the start')."""
    if bound is None:
        return "the start"
    kind, value = bound
    return f"{value} samples" if kind == "samples" else f"{value * 1e3:g} ms"


class TraceWindow:
    """The cycles a run traces (``start`` .. ``stop`` - 1), known from the start for time
    bounds, and set as the run reaches them for sample bounds (``at_sample``). ``on_change``:
    called with (start, stop) when a sample bound moves them (the compiled design's
    ``trace_window``)."""

    NEVER = NEVER                               # the compiled design's "no cycle"

    def __init__(self, wave, clk_freq, on_change=None):
        self.wave, self.on_change = wave, on_change
        self.start = self._cycles(wave.start, clk_freq, 0)
        self.stop = self._cycles(wave.stop, clk_freq, self.NEVER)

    @staticmethod
    def _cycles(bound, clk_freq, default):
        if bound is None:
            return default
        kind, value = bound
        if kind == "s":
            return round(value * clk_freq)
        return 0 if value == 0 else None            # a count of samples: met in the run

    def at_sample(self, count, cycle):
        """``count`` samples have come out, at ``cycle``."""
        moved = False
        for name in ("start", "stop"):
            bound = getattr(self.wave, name)
            if bound and bound[0] == "samples" and bound[1] == count and \
                    getattr(self, name) is None:
                setattr(self, name, cycle)
                moved = True
        if moved and self.on_change is not None:
            self.on_change(*self.cycles())

    def place(self, start, stop):
        """Sets the window to the cycles ``start`` .. ``stop`` (None: not known yet) as a run
        finds them (the twin's, counted from its arming), telling ``on_change``."""
        self.start, self.stop = start, stop
        if self.on_change is not None:
            self.on_change(*self.cycles())

    def cycles(self):
        """(start, stop): a sample bound not met yet is NEVER."""
        return (self.NEVER if self.start is None else self.start,
                self.NEVER if self.stop is None else self.stop)


def gtkw_beside(vcd):
    """The GTKWave save file written beside the waveform ``vcd`` (its name, ``.gtkw``)."""
    return str(vcd).rsplit(".", 1)[0] + ".gtkw"


# The width of GTKWave's wave area the save file's zoom is set for, pixels.
GTKW_WIDTH_PX = 1000


def layout(kind, wiring, status_fields=()):
    """What a save file shows, grouped by block: [(group, [(name, width, label)])], each name
    relative to the harness's scope (``sim.bench.harness.CosimHarness``: the design is ``dut``).
    ``kind``: "frontend" or "core"; ``status_fields``: the status flags by (name, width)."""
    pins = "pins" if kind == "frontend" else "imu"
    if wiring == "spi":
        bus = ("SPI", [(f"dut.{pins}__{n}", 1, n) for n in ("cs_n", "sclk", "copi", "cipo")])
    else:
        bus = ("I2C", [("scl", 1, "scl"), ("sda", 1, "sda"),
                       (f"dut.{pins}__scl_oe", 1, "scl_oe"),
                       (f"dut.{pins}__sda_oe", 1, "sda_oe")])
    status = [(f"dut.\\status.{n}", w, n) for n, w in status_fields]
    if kind == "frontend":
        driver = [("dut.int_pin", 1, "int"), ("dut.samples__valid", 1, "samples.valid")]
        return [bus, ("driver", driver), ("status", status)]
    core = [("dut.imu_int", 1, "int"), ("dut.engine.results__valid", 1, "results.valid"),
            ("dut.uart_tx", 1, "uart_tx")]
    return [bus, ("core", core), ("status", status)]


def write_gtkw(wave, scope, groups, window_s=None, timescale_s=1e-12, escaped=True):
    """The save file beside ``wave`` (a ``Waveform``): the traces of ``groups`` (``layout``)
    under ``scope`` (the harness's scope in the file), each group a GTKWave group, opening on
    ``window_s`` = (start, end) seconds (None: GTKWave's default) at ``timescale_s``.
    ``escaped``: a field's name (``status.mag_ok``, one name with a dot) is written as GTKWave
    reads it from a VCD, ``\\status.mag_ok``; False: as it reads Verilator's FST, plain."""
    # a window whose wave area is about GTKW_WIDTH_PX wide: the zoom below is set for it
    lines = [f'[dumpfile] "{Path(wave.path).resolve()}"',
             f"[size] {GTKW_WIDTH_PX + 470} 860", "[sst_width] 190", "[signals_width] 170"]
    if window_s is not None:
        start, end = window_s
        span = max(end - start, 1e-9) / timescale_s
        # GTKWave shows 2**-zoom time units per 200 pixels (its zoom base 2)
        zoom = -math.log2(span * 200 / GTKW_WIDTH_PX)
        lines += [f"[timestart] {max(0, round(start / timescale_s))}",
                  f"*{zoom:.6f} -1" + " -1" * 26]
    lines += [f"[treeopen] {scope}.", "@22"]
    for group, traces in groups:
        if not traces:
            continue
        lines += ["@800200", f"-{group}"]
        for name, width, label in traces:
            bits = f"[{width - 1}:0]" if width > 1 else ""
            if not escaped:
                name = name.replace("\\", "")
            lines += ["@22" if width > 1 else "@28", f"+{{{label}}} {scope}.{name}{bits}"]
        lines += ["@1000200", f"-{group}"]
    Path(wave.gtkw).write_text("\n".join(lines) + "\n")


def first_transaction_window(model, bus, margin=0.25, after_s=0.0):
    """(start, end) of the first sensor transaction that starts at or after ``after_s``,
    seconds, widened by ``margin`` of its length either side: the SPI model's chip selects, or
    the I2C bus's START to STOP. None if there was none."""
    spans = bus.frames if bus is not None else (model.transactions if model else [])
    spans = [s for s in spans if s[0] >= after_s]
    if not spans:
        return None
    start, end = spans[0][0], spans[0][1]
    pad = (end - start) * margin
    return max(after_s, start - pad), end + pad


def crop_vcd(source, target, start, stop):
    """Copy the VCD ``source`` to ``target`` keeping the times ``start`` .. ``stop`` (in the
    file's time unit): the header, every value as it stood at ``start`` (a ``$dumpvars``),
    then the changes up to ``stop``. Read and written a line at a time."""
    values = {}                         # identifier -> its last value-change line
    state = "header"
    with open(source) as src, open(target, "w") as out:
        for line in src:
            if state == "header":
                out.write(line)
                if line.startswith("$enddefinitions"):
                    state = "before"
                continue
            if line.startswith("#"):
                time = int(line[1:])
                if time > stop:
                    break
                if state == "before" and time >= start:
                    out.write(f"#{start}\n$dumpvars\n")
                    out.writelines(values.values())
                    out.write("$end\n")
                    state = "inside"
                if state == "inside" and time > start:
                    out.write(line)
                continue
            if line.startswith("$"):
                continue                # $dumpvars / $end around the first values
            stripped = line.strip()
            if not stripped:
                continue
            ident = stripped.split()[-1] if stripped[0] in "brRs" else stripped[1:]
            if state == "before":
                values[ident] = line if line.endswith("\n") else line + "\n"
            else:
                out.write(line)


def finish_python_trace(wave, written, timescale_s, window_cycles, clk_freq):
    """Amaranth's simulator wrote the whole run's VCD into ``written``: cut it to the window
    (``window_cycles`` = (start, stop) cycles; the NEVER of a bound not met is the end) and,
    for an FST, convert it with ``vcd2fst``; the result at ``wave.path``."""
    start, stop = window_cycles
    cut = (start > 0 or stop < TraceWindow.NEVER)
    source = written
    if cut:
        unit = 1 / clk_freq / timescale_s
        cropped = written + ".cut.vcd"
        crop_vcd(written, cropped, round(start * unit),
                 round(min(stop, TraceWindow.NEVER) * unit))
        os.replace(cropped, written)
    if wave.format == "fst":
        result = subprocess.run(["vcd2fst", source, wave.path], capture_output=True, text=True)
        if result.returncode:
            raise RuntimeError(f"vcd2fst failed on {source}: {result.stderr.strip()[-500:]}")
        os.remove(source)
    elif source != wave.path:
        os.replace(source, wave.path)


def python_trace_path(wave):
    """Where Amaranth's simulator writes its VCD for ``wave``: the file itself, or a
    temporary VCD beside it when it is cut or converted afterwards (FST: ``vcd2fst`` needed,
    asked before the run)."""
    if wave.format == "fst" and shutil.which("vcd2fst") is None:
        raise RuntimeError(f"FST from Amaranth's simulator is converted by vcd2fst, not found: "
                           f"{GTKWAVE_HINT} (the compiled simulator writes FST itself)")
    if wave.format == "vcd" and wave.start is None and wave.stop is None:
        return wave.path
    return str(wave.path) + ".whole.vcd"


def vcd_timescale_s(vcd):
    """The time unit of the VCD file ``vcd``, seconds, from its ``$timescale`` header."""
    with open(vcd) as f:
        head = f.read(4096)
    found = re.search(r"\$timescale\s*(\d+)\s*([munpf]?s)\s*\$end", head)
    if found is None:
        raise ValueError(f"{vcd}: no $timescale in its header")
    return int(found.group(1)) * {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9, "ps": 1e-12,
                                  "fs": 1e-15}[found.group(2)]


class RunTrace:
    """The waveform of one co-simulation run, on either simulator: ``wave`` (``Waveform``, or
    a path) of a harness (``sim.bench.harness.CosimHarness``) around a ``kind`` ("frontend" or
    "core") design on ``wiring`` whose status has ``status_fields`` ((name, width) each).

    Compiled: ``start_compiled(design)`` before the run (a build with ``trace=format``);
    Amaranth's simulator: ``python_writer(sim)``, a context around ``sim.run()``.
    Either way ``at_sample(count, cycle)`` as samples come out (sample bounds), and
    ``finish(model, bus, end_cycle, samples)`` after the run (the compiled design closed
    first): the file cut and converted where it must be, the save file beside it; a window
    the run never reached is a ValueError (and no file)."""

    def __init__(self, wave, clk_freq, kind, wiring, status_fields):
        self.wave = Waveform.of(wave)
        self.clk_freq = clk_freq
        self.groups = layout(kind, wiring, status_fields)
        self.window = TraceWindow(self.wave, clk_freq)
        self.scope = self.written = None

    def start_compiled(self, design):
        self.scope, self.timescale_s = design.scope, 1e-12
        self.window.on_change = design.trace_window
        design.trace_to(self.wave.path, self.clk_freq, *self.window.cycles())

    def python_writer(self, sim):
        # Amaranth's writer dumps every signal of the design: the save file names its own
        self.scope = "bench.top"
        self.written = python_trace_path(self.wave)
        return sim.write_vcd(self.written)

    def at_sample(self, count, cycle):
        self.window.at_sample(count, cycle)

    def finish(self, model, bus, end_cycle, samples):
        start, stop = self.window.cycles()
        if start >= min(stop, end_cycle):
            for path in (self.wave.path, self.written):
                if path is not None and os.path.exists(path):
                    os.remove(path)
            raise ValueError(f"{self.wave.path}: nothing traced: the run ended "
                             f"({end_cycle / self.clk_freq * 1e3:.3f} ms, {samples} samples) "
                             f"before the waveform's window started ({describe(self.wave.start)})"
                             f"; ask for an earlier start or a longer run")
        if self.written is not None:
            self.timescale_s = vcd_timescale_s(self.written)
            finish_python_trace(self.wave, self.written, self.timescale_s, (start, stop),
                                self.clk_freq)
        shown = first_transaction_window(model, bus, after_s=start / self.clk_freq)
        if shown is not None and stop < TraceWindow.NEVER:
            # GTKWave ignores a start whose view would pass the file's end: slide it back
            late = shown[1] - stop / self.clk_freq
            if late > 0:
                shown = (max(start / self.clk_freq, shown[0] - late), shown[1] - late)
        write_gtkw(self.wave, self.scope, self.groups, shown, self.timescale_s,
                   escaped=self.written is not None or self.wave.format == "vcd")


_GTKWAVE_SCRIPT = """
set out [open {report} w]
puts $out "facs [gtkwave::getNumFacs]"
set n [gtkwave::getTotalNumTraces]
for {{set i 0}} {{$i < $n}} {{incr i}} {{ puts $out "trace [gtkwave::getTraceNameFromIndex $i]" }}
puts $out "window [gtkwave::getWindowStartTime] [gtkwave::getWindowEndTime]"
close $out
{shot}
gtkwave::/File/Quit
"""


def gtkwave_check(wave_path, gtkw=None, screenshot=None, timeout=120):
    """Open the waveform ``wave_path`` (with the save file ``gtkw``) in GTKWave under Xvfb, as
    a user would, and say what it read: {"returncode", "errors" (its parse-error lines),
    "facs" (signals in the file), "traces" (those the save file showed), "window" (the first
    and last time shown)}. ``screenshot``: a PNG of the screen at first open (needs ``xwd``
    and ImageMagick's ``convert``). RuntimeError if GTKWave or xvfb-run is missing."""
    for tool in ("gtkwave", "xvfb-run"):
        if shutil.which(tool) is None:
            raise RuntimeError(f"{tool} not found: {GTKWAVE_HINT}")
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "report.txt"
        shot = ""
        if screenshot is not None:
            xwd = Path(tmp) / "screen.xwd"
            shot = (f"gtkwave::setZoomFactor [gtkwave::getZoomFactor]\nupdate\nafter 1500\n"
                    f"update\nexec xwd -root -silent -out {xwd}\n"
                    f"exec convert {xwd} {Path(screenshot).resolve()}\n")
        script = Path(tmp) / "check.tcl"
        script.write_text(_GTKWAVE_SCRIPT.format(report=report, shot=shot))
        cmd = ["xvfb-run", "-a", "-s", "-screen 0 1400x900x24", "gtkwave", "-S", str(script),
               str(wave_path), *([str(gtkw)] if gtkw else [])]
        result = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        text = report.read_text() if report.exists() else ""
    lines = (result.stdout + result.stderr).splitlines()
    errors = [line for line in lines if "error" in line.lower()]
    window = re.search(r"^window (\d+) (\d+)$", text, re.M)
    return {"returncode": result.returncode, "errors": errors,
            "facs": int(re.search(r"^facs (\d+)$", text, re.M).group(1)) if text else 0,
            "traces": re.findall(r"^trace (.*)$", text, re.M),
            "window": tuple(map(int, window.groups())) if window else None,
            "output": lines[-20:]}
