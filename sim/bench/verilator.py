"""Verilator builds of the package's compiled simulations, cached: the one build path the
compiled engine (``sim.scenarios.compiled_engine``) and the compiled designs (``sim.bench.compiled_design``)
share (the cache, a lock per entry, a temporary folder, the command, the atomic publish, and
Verilator's run-time library built once for all of them: ``_Runtime``).
"""

import contextlib
import fcntl
import functools
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


__all__ = ["HINT", "BUILD_OPTIMISATION", "verilator_available", "verilator_version",
           "cache_root", "build_lock", "publish", "verilator_build"]

HINT = "install it with: apt-get install verilator g++ make"
# g++'s optimisation of Verilator's output: the per-cycle code ("fast") as much as its speed
# needs, the once-run code ("slow": construction, initial values) and Verilator's runtime not
# at all or little. Measured on the whole core (2 cores): -O1 for the fast code builds in 14 s
# instead of 18 s (Verilator's default -Os with -O3) and runs as fast; the engine runs whole
# recordings, so it keeps -O2 where it counts.
BUILD_OPTIMISATION = {
    "design": "OPT_FAST=-O1 OPT_SLOW=-O0 OPT_GLOBAL=-O1",
    "engine": "OPT_FAST=-O2 OPT_SLOW=-O0 OPT_GLOBAL=-O1",
}


def verilator_available():
    """Verilator, g++ and make (which runs Verilator's makefile: ``verilator_build``)."""
    return all(shutil.which(tool) is not None for tool in ("verilator", "g++", "make"))


@functools.lru_cache(maxsize=None)
def verilator_version():
    """``verilator --version``: part of every cache key (asked once a process)."""
    return subprocess.run(["verilator", "--version"], capture_output=True,
                          text=True).stdout.strip()


def cache_root():
    """The cache of compiled builds: ``$MPU9250_AHRS_CACHE`` or ``~/.cache/mpu9250-ahrs``."""
    root = os.environ.get("MPU9250_AHRS_CACHE") or os.path.join(
        os.path.expanduser("~"), ".cache", "mpu9250-ahrs")
    return Path(root)


@contextlib.contextmanager
def build_lock(folder):
    """Held while ``folder`` (a cache entry) is looked for and built: a second process that
    wants the same design (two test workers) waits for the first's build and takes it, rather
    than building it again beside it."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    with open(folder.parent / f"{folder.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def publish(built, folder):
    """Put the file ``built`` (inside a temporary folder of the cache) into the cache folder
    ``folder`` under its name, atomically: concurrent builds of one design race fine."""
    done = built.parent / "done"
    done.mkdir()
    shutil.copy2(built, done / built.name)
    try:
        os.replace(done, folder)
    except OSError:
        if not (folder / built.name).exists():
            raise


def verilator_build(folder, output, sources, *, top, what, options=(), make_flags=""):
    """``folder``/``output`` built by Verilator and g++ unless the cache has it, one process
    at a time (``build_lock``: another waits for the build and takes it). ``sources``: file
    name: its text, or a callable giving it (asked only when a build is needed), in the order
    Verilator takes them; ``top``: the top module; ``options``: Verilator's, beside the
    common ones; ``make_flags``: its makefile's (``BUILD_OPTIMISATION``). Returns the
    seconds spent building (0 when the cache had it)."""
    target = folder / output
    if target.exists():
        return 0.0
    with build_lock(folder):
        if target.exists():
            return 0.0
        # a one-time wait worth a word (the build is cached afterwards), on a terminal or in
        # a log alike: a piped run was silent for the minutes of a first build
        print(f"mpu9250-ahrs: compiling the {what} with Verilator (seconds to minutes, once: "
              f"cached in {folder.parent}) ...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        with tempfile.TemporaryDirectory(dir=folder.parent) as tmp:
            tmp = Path(tmp)
            for name, text in sources.items():
                (tmp / name).write_text(text() if callable(text) else text)
            # Verilator's C++, then g++ through its makefile (what ``--build`` does), with
            # its run-time library's objects from the cache (``_Runtime``)
            obj = tmp / "obj"
            cmd = ["verilator", "--cc", "--exe", "-O3", "-Wno-fatal", "-Wno-lint", "-Wno-style",
                   "--top-module", top, *options, "--Mdir", str(obj), "-o", output, *sources]
            make = ["make", "-s", "-C", str(obj), "-f", f"V{top}.mk", *make_flags.split()]

            def run(step):
                result = _run_group(step, cwd=tmp)
                if result.returncode:
                    raise RuntimeError(f"verilator failed to build the {what}:\n"
                                       + (result.stderr or result.stdout)[-3000:])
            run(cmd)
            runtime = _Runtime(obj, make)
            run(make)
            runtime.keep()
            publish(obj / output, folder)
        took = time.perf_counter() - start
        print(f"mpu9250-ahrs: compiled the {what} in {took:.0f} s", file=sys.stderr, flush=True)
        return took


def _run_group(cmd, cwd):
    """``subprocess.run(cmd, capture_output, text)`` in a process group of its own, ended
    whole if this process is interrupted: make's compilers are its children, and Ctrl-C left
    them compiling (they are not in the terminal's group when a tool started this one)."""
    import signal
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        out, err = proc.communicate()
    except BaseException:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            pass
        proc.wait()
        raise
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


class _Runtime:
    """Verilator's run-time library (``verilated.o`` and the like, about 4 s of g++ in every
    build) is the same in every build that compiles it the same way: its objects are kept in
    the cache, under a hash of their compile commands (``make -n``: the flags, the paths) and
    Verilator's version, and copied into a new build's folder before its ``make`` (then
    newer than their makefile: ``make`` takes them as built). ``keep()`` after a build stores
    them if the cache had none."""

    # a line of ``make -n`` compiling one of them: its object, from Verilator's include folder
    LINE = re.compile(r"^.* -c -o (\S+\.o) \S+/include/\S+\.cpp$")

    def __init__(self, obj, make):
        self.obj = obj
        dry = subprocess.run([*make, "-n"], capture_output=True, text=True).stdout
        commands = [line for line in dry.splitlines() if self.LINE.match(line)]
        self.names = sorted({self.LINE.match(line).group(1) for line in commands})
        self.commands = commands
        key = hashlib.sha256("\0".join((verilator_version(), *commands)).encode()).hexdigest()
        self.folder = cache_root() / f"verilator-runtime-{key[:20]}"
        self.cached = bool(self.names) and all(
            (self.folder / name).exists() for name in self.names)
        if self.cached:
            for name in self.names:
                shutil.copy(self.folder / name, obj / name)

    def keep(self):
        if self.cached or not self.names:
            return
        self.folder.parent.mkdir(parents=True, exist_ok=True)
        built = Path(tempfile.mkdtemp(dir=self.folder.parent))
        for name in self.names:
            shutil.copy2(self.obj / name, built / name)
        (built / "commands").write_text("\n".join(self.commands) + "\n")    # to look at
        try:
            os.replace(built, self.folder)
        except OSError:                 # another build stored them first
            shutil.rmtree(built, ignore_errors=True)
