"""Any design (an Amaranth ``Elaboratable``) compiled by Verilator into a shared library and
stepped from Python: the compiled path of the whole-board co-simulations (``sim.bench.compiled_bench``).

Amaranth's simulator runs the whole core at a few thousand cycles per second; the models it
talks to (``MPU9250Model``, ``I2CBusModel``, the UART) only need to run when a pin they watch
changes. ``CompiledDesign`` exports the design with the signals the models and testbench drive
(``inputs``) and watch (``outputs``) as ports, compiles it with a small C API once (cached like
``sim.scenarios.compiled_engine``: key = Verilog + C++ + Verilator version), and loads it with ``ctypes``.

``run(until, watch)`` then clocks the design in C++ until one of the ``watch`` outputs (each at
most 64 bits) changes at a clock edge, or the edge count reaches ``until``, and returns the edge
count: the same count as ``CosimHarness.cycle``. ``set``/``get`` move integers in and out (any
width). An input keeps its value until set; it starts at its signal's ``init``. Between calls
the design is settled (inputs set after an edge are seen by the next edge), as a testbench sees
it in Amaranth's simulator.

Needs ``verilator`` and ``g++`` (``verilator_available()``); without them ``CompiledDesign``
raises ``RuntimeError`` with a hint, and callers fall back to Amaranth's simulator.
"""

import ctypes
import functools
import hashlib
import re
from pathlib import Path

from amaranth import Module, Signal, Value
from amaranth.back import verilog
from amaranth.lib import wiring
from amaranth.lib.wiring import In, Out

from .verilator import (BUILD_OPTIMISATION, HINT, cache_root, verilator_available, verilator_build,
    verilator_version)


__all__ = ["CompiledDesign", "NotBuilt", "NEVER", "verilator_available"]


# A cycle no run reaches: "no wake-up wanted" for the models at the pins.
NEVER = (1 << 40) - 1


class _Ports(wiring.Component):
    """``design`` with one port per named input (driving the value) and output (reading it)."""

    def __init__(self, design, inputs, outputs):
        self._design = design
        self._inputs, self._outputs = inputs, outputs
        members = {}
        for name, value in inputs.items():
            members[name] = In(len(Value.cast(value)), init=_init(value))
        for name, value in outputs.items():
            members[name] = Out(len(Value.cast(value)))
        super().__init__(members)

    def elaborate(self, platform):
        m = Module()
        m.submodules.design = self._design
        for name, value in self._inputs.items():
            m.d.comb += Value.cast(value).eq(getattr(self, name))
        for name, value in self._outputs.items():
            m.d.comb += getattr(self, name).eq(Value.cast(value))
        return m


def _init(value):
    value = Value.cast(value)
    return value.init if isinstance(value, Signal) else 0


def _words(width):
    return (width + 31) // 32


def _cxx(top, inputs, outputs, trace=False):
    """The C API: sim_new, sim_free, sim_set, sim_get, sim_run (see the module docstring);
    with ``trace`` ("vcd" or "fst") also sim_trace and sim_trace_window: a waveform of every
    signal, dumped at each clock edge of a window of cycles."""
    cls = f"V{top}"
    if trace:
        writer = {"vcd": "VerilatedVcdC", "fst": "VerilatedFstC"}[trace]
        trace_include = f'#include "verilated_{trace}_c.h"\n'
        trace_member = f" {writer} *tfp; uint64_t half_ps, from, to;"
        trace_init = "    s->tfp = nullptr; s->half_ps = 1;\n    s->ctx->traceEverOn(true);\n"
        trace_close = "if (s->tfp) { s->tfp->close(); delete s->tfp; } "
        # dumped only inside the window: the first dump writes every value, so a waveform
        # that starts late still opens with the whole state
        dump = ("if (s->tfp && s->cycle >= s->from && s->cycle < s->to) "
                "s->tfp->dump((2 * s->cycle + {}) * s->half_ps); ")
        trace_api = f"""// A waveform of every signal into path, at each clock edge (half_ps: half a
// period) of the cycles from .. to - 1
void sim_trace(void *p, const char *path, uint64_t half_ps, uint64_t from, uint64_t to) {{
    Sim *s = (Sim *)p;
    s->tfp = new {writer};
    s->half_ps = half_ps;
    s->from = from; s->to = to;
    s->top->trace(s->tfp, 99);
    s->tfp->set_time_unit("1ps");
    s->tfp->set_time_resolution("1ps");
    s->tfp->open(path);
    if (s->cycle >= from && s->cycle < to) s->tfp->dump(2 * s->cycle * s->half_ps);
}}
// The window moved (a bound known only once the run reaches it: a sample's cycle)
void sim_trace_window(void *p, uint64_t from, uint64_t to) {{
    Sim *s = (Sim *)p;
    s->from = from; s->to = to;
    if (s->tfp && s->cycle >= to) s->tfp->flush();
}}
"""
    else:
        trace_include = trace_member = trace_init = trace_close = trace_api = ""
        dump = ""
    def access(name, width, direction):
        # Verilator: up to 64 bits an integer member, wider a VlWide of 32-bit words
        if width > 64:
            if direction == "set":
                return "".join(f"s->top->{name}[{i}] = w[{i}]; " for i in range(_words(width)))
            return "".join(f"w[{i}] = s->top->{name}[{i}]; " for i in range(_words(width)))
        if direction == "set":
            return (f"s->top->{name} = (uint64_t)w[0]" +
                    (" | ((uint64_t)w[1] << 32)" if width > 32 else "") + "; ")
        return (f"{{ uint64_t v = s->top->{name}; w[0] = (uint32_t)v; " +
                ("w[1] = (uint32_t)(v >> 32); " if width > 32 else "") + "} ")
    sets = "".join(f"    case {k}: {access(n, w, 'set')}break;\n"
                   for k, (n, w) in enumerate(inputs))
    # outputs of up to 64 bits are read from the snapshot, wider ones through sim_get
    gets = "".join(f"    case {k}: {access(n, w, 'get')}break;\n"
                   for k, (n, w) in enumerate(outputs) if w > 64)
    small = [(k, n) for k, (n, w) in enumerate(outputs) if w <= 64]
    snap = "".join(f"    s->snap[{k}] = s->top->{n};\n" for k, n in small)
    watched = [(k, n) for k, n in small if k < 64]          # a bit of the mask each
    # a watched output that changes ends the run: until then each equals its value at entry
    keep = "".join(f"    if (mask & (1ULL << {k})) prev[{k}] = s->top->{n};\n"
                   for k, n in watched)
    compare = "".join(
        f"        if ((mask & (1ULL << {k})) && s->top->{n} != prev[{k}]) hit = true;\n"
        for k, n in watched)
    return f"""// Generated by mpu9250_ahrs.sim.bench.compiled_design
#include <cstdint>
#include "{cls}.h"
#include "verilated.h"
{trace_include}
struct Sim {{ VerilatedContext *ctx; {cls} *top; uint64_t cycle; uint64_t *snap;{trace_member} }};

// the outputs of up to 64 bits, copied where Python reads them without a call
static void snapshot(Sim *s) {{
{snap}}}

extern "C" {{
void *sim_new(uint64_t *snap) {{
    Sim *s = new Sim;
    s->snap = snap;
    s->ctx = new VerilatedContext;
{trace_init}    s->top = new {cls}(s->ctx);
    s->cycle = 0;
    s->top->clk = 0; s->top->rst = 0;
    s->top->eval();
    snapshot(s);
    return s;
}}
void sim_free(void *p) {{
    Sim *s = (Sim *)p; {trace_close}s->top->final(); delete s->top; delete s->ctx; delete s;
}}
{trace_api}
void sim_set(void *p, int k, const uint32_t *w) {{
    Sim *s = (Sim *)p;
    switch (k) {{
{sets}    }}
    s->top->eval();
    snapshot(s);
}}
void sim_get(void *p, int k, uint32_t *w) {{
    Sim *s = (Sim *)p;
    switch (k) {{
{gets}    }}
}}
uint64_t sim_cycle(void *p) {{ return ((Sim *)p)->cycle; }}
// Clock edges until a watched output changed at one, or the count reached until.
uint64_t sim_run(void *p, uint64_t until, uint64_t mask) {{
    Sim *s = (Sim *)p;
    uint64_t prev[64];
{keep}    while (s->cycle < until) {{
        s->top->clk = 1; s->top->eval(); {dump.format(1)}
        s->top->clk = 0; s->top->eval(); {dump.format(2)}
        ++s->cycle;
        bool hit = false;
{compare}        if (hit) break;
    }}
    snapshot(s);
    return s->cycle;
}}
}}
"""


class NotBuilt(LookupError):
    """``CompiledDesign(cached_only=True)`` of a design the cache does not have."""


@functools.lru_cache(maxsize=None)
def _sources_hash():
    """A hash of the package's gateware and simulation sources and Amaranth's version: what,
    beside a caller's parameters, decides the Verilog of a design made by this package (read
    once a process)."""
    import amaranth
    h = hashlib.sha256(amaranth.__version__.encode())
    for name, path in _source_files():
        h.update(name.encode() + b"\0" + path.read_bytes())
    return h.hexdigest()


def _source_files():
    """(name, path) of every module of the package's ``hdl`` and ``sim``, sub-packages
    included: the filters' microcode is in ``hdl/engine/filters/`` (a change there alone once left
    a stale build in the cache)."""
    root = Path(__file__).resolve().parents[2]          # the package: hdl/, sim/ beside
    return [(str(path.relative_to(root)), path) for folder in ("hdl", "sim")
            for path in sorted((root / folder).rglob("*.py"))]


def _mark_used(root):
    """Mark ``root`` and the elaboratables it holds (attributes, lists, dicts) as used."""
    from amaranth.hdl import Elaboratable
    seen, todo = set(), [root]
    while todo:
        obj = todo.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, Elaboratable):
            obj._MustUse__used = True
            todo.extend(vars(obj).values())
        elif isinstance(obj, (list, tuple)):
            todo.extend(obj)
        elif isinstance(obj, dict):
            todo.extend(obj.values())


# Yosys' Verilog backend declares a register per module to start its ``always @*`` blocks at
# time 0, named ``\$auto$verilog_backend.cc:2355:dump_module$1``: GTKWave's VCD reader refuses
# that name ("$VAR parse error"). Renamed with a leading underscore, Verilator leaves it out of
# its traces (signals starting with ``_`` are not traced without --trace-underscore).
_GENERATED_NAME = re.compile(r"\\\$auto\$\S*")


def readable_names(text):
    """The Verilog ``text`` with Yosys' generated identifiers (``$auto$...``, escaped, up to
    the white space that ends them) renamed ``_auto_N``: same design, nothing GTKWave refuses
    in a trace of it."""
    names = {}
    return _GENERATED_NAME.sub(
        lambda m: names.setdefault(m.group(0), f"_auto_{len(names) + 1}"), text)


# Verilator's options for a build that traces, by the waveform's format
_TRACE_OPTIONS = {"vcd": ["--trace"], "fst": ["--trace-fst"]}


class CompiledDesign:
    """``design`` (an ``Elaboratable`` with a ``sync`` domain) compiled with ports for
    ``inputs`` and ``outputs`` (name: signal or value-castable; names must be Verilog
    identifiers). ``name``: the cache folder's prefix. ``key``: what makes the design (its
    parameters, with a repr that says all of them); given, the cache is looked up without
    converting the design to Verilog (the package's sources are part of the key).
    ``cached_only``: raise ``NotBuilt`` rather than build. ``trace``: a build that writes
    waveforms (``trace_to``), "vcd" or "fst" (True: "vcd")."""

    def __init__(self, design, inputs, outputs, *, name="design", key=None, cached_only=False,
                 trace=False):
        self.cached_only = cached_only
        self.trace = "vcd" if trace is True else (trace or False)
        if self.trace not in (False, "vcd", "fst"):
            raise ValueError(f"trace: 'vcd', 'fst' or False, not {trace!r}")
        self.name = name
        self.key = key
        self.inputs = {n: Value.cast(v) for n, v in inputs.items()}
        self.outputs = {n: Value.cast(v) for n, v in outputs.items()}
        self._in_index = {n: k for k, n in enumerate(self.inputs)}
        self._out_index = {n: k for k, n in enumerate(self.outputs)}
        self._in_width = {n: len(v) for n, v in self.inputs.items()}
        self._out_width = {n: len(v) for n, v in self.outputs.items()}
        self._out_shape = {n: v.shape() for n, v in self.outputs.items()}
        self.build_s = 0.0
        self._lib = self._build(design)
        self._snap = (ctypes.c_uint64 * max(1, len(self.outputs)))()
        self._handle = ctypes.c_void_p(self._lib.sim_new(self._snap))
        # name -> (index, width, signed) for the outputs read from the snapshot
        self._small = {n: (self._out_index[n], w, self._out_shape[n].signed)
                       for n, w in self._out_width.items() if w <= 64}
        self._buf = (ctypes.c_uint32 * max(2, *(_words(w) for w in
                                                 [*self._in_width.values(),
                                                  *self._out_width.values()])))()
        for n, v in self.inputs.items():
            self.set(n, _init(v))

    def _build(self, design):
        if not verilator_available():
            raise RuntimeError(f"the compiled co-simulation needs verilator, g++ and make; "
                               f"{HINT}")
        top = self.name.replace("-", "_") + "_top"
        cxx = _cxx(top, [(n, self._in_width[n]) for n in self.inputs],
                   [(n, self._out_width[n]) for n in self.outputs], trace=self.trace)
        converted = []                  # the design's Verilog, once made

        def verilog_text():
            if not converted:
                converted.append(readable_names(verilog.convert(
                    _Ports(design, self.inputs, self.outputs), name=top, emit_src=False)))
            return converted[0]
        if self.key is None:
            key = verilog_text()
        else:
            # converting the whole core to Verilog takes seconds: a caller that knows what
            # makes its design (its parameters; the sources are added here) names it instead
            key = "\0".join((repr(self.key), _sources_hash()))
        key = hashlib.sha256("\0".join((key, cxx, verilator_version(),
                                        BUILD_OPTIMISATION["design"])).encode()
                             ).hexdigest()[:20]
        folder = cache_root() / f"{self.name}-{key}"
        library = folder / "design.so"
        if self.cached_only and not library.exists():
            raise NotBuilt(f"{self.name}: not in the cache")
        # an "executable" linked as a shared object: Verilator builds its runtime with the
        # design and our C API (api.cpp), all position-independent
        self.build_s = verilator_build(
            folder, "design.so", {f"{top}.v": verilog_text, "api.cpp": cxx}, top=top,
            what=self.name, options=[
                "-CFLAGS", "-fPIC", "-LDFLAGS", "-shared", "--x-assign", "fast",
                "--x-initial", "fast", "--noassert", *_TRACE_OPTIONS.get(self.trace, [])],
            make_flags=BUILD_OPTIMISATION["design"])
        if not converted:
            # the design was never elaborated (the cache had it): its blocks would each warn,
            # when collected, that they were "created but never used"
            _mark_used(design)
        lib = ctypes.CDLL(str(library))
        lib.sim_new.restype = ctypes.c_void_p
        lib.sim_new.argtypes = [ctypes.c_void_p]
        lib.sim_free.argtypes = [ctypes.c_void_p]
        lib.sim_set.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p]
        lib.sim_get.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p]
        lib.sim_cycle.argtypes = [ctypes.c_void_p]
        lib.sim_cycle.restype = ctypes.c_uint64
        lib.sim_run.argtypes = [ctypes.c_void_p, ctypes.c_uint64, ctypes.c_uint64]
        lib.sim_run.restype = ctypes.c_uint64
        if self.trace:
            lib.sim_trace.argtypes = [ctypes.c_void_p, ctypes.c_char_p, *[ctypes.c_uint64] * 3]
            lib.sim_trace_window.argtypes = [ctypes.c_void_p, *[ctypes.c_uint64] * 2]
        return lib

    def close(self):
        if self._handle is not None:
            self._lib.sim_free(self._handle)
            self._handle = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

    @property
    def cycle(self):
        return self._lib.sim_cycle(self._handle)

    def set(self, name, value):
        width = self._in_width[name]
        value = int(value) & ((1 << width) - 1)
        for i in range(_words(width)):
            self._buf[i] = (value >> (32 * i)) & 0xFFFFFFFF
        self._lib.sim_set(self._handle, self._in_index[name], self._buf)

    def get(self, name):
        """The output's value: an int (signed if its value is signed)."""
        small = self._small.get(name)
        if small is not None:
            index, width, signed = small
            value = self._snap[index]
        else:
            width, signed = self._out_width[name], self._out_shape[name].signed
            self._lib.sim_get(self._handle, self._out_index[name], self._buf)
            value = sum(self._buf[i] << (32 * i) for i in range(_words(width)))
            value &= (1 << width) - 1
        if signed and value >> (width - 1):
            value -= 1 << width
        return value

    def mask(self, *names):
        """The watch mask of these outputs (for ``run``)."""
        bits = 0
        for n in names:
            k = self._out_index[n]
            if self._out_width[n] > 64 or k >= 64:
                raise ValueError(f"output {n} cannot be watched (wider than 64 bits or past "
                                 f"the 64th output)")
            bits |= 1 << k
        return bits

    def trace_to(self, path, clk_freq, start=0, stop=NEVER):
        """Dump every signal into the waveform file ``path`` (VCD or FST, as built: ``trace``),
        the clock at ``clk_freq``, at the clock edges of the cycles ``start`` .. ``stop`` - 1
        (by ``cycle``); the file is complete once the design is closed. The design's own
        signals are in scope ``TOP.<name>_top.design`` (``scope``), the ports in ``TOP``;
        time in picoseconds."""
        if not self.trace:
            raise ValueError("this design was built without trace")
        self._lib.sim_trace(self._handle, str(path).encode(), max(1, round(0.5e12 / clk_freq)),
                            int(start), int(stop))

    def trace_window(self, start, stop=NEVER):
        """Move the traced cycles to ``start`` .. ``stop`` - 1 (a bound met during the run)."""
        self._lib.sim_trace_window(self._handle, int(start), int(stop))

    @property
    def scope(self):
        """The waveform's scope of the design's own signals (``trace_to``)."""
        return f"TOP.{self.name.replace('-', '_')}_top.design"

    def run(self, until, mask=0):
        """Clock edges until a watched output (``mask``) changes at one, or the edge count is
        ``until``; the edge count."""
        return self._lib.sim_run(self._handle, int(until), mask)
