"""The attitude engine's gateware in a compiled simulator (Verilator), for whole recordings.

Amaranth's simulator runs the engine at a few thousand cycles per second, so a 53,000-sample
recording (about 3×10⁷ cycles) would take hours; Verilator runs the same Verilog several hundred
times faster (``python -m mpu9250_ahrs.sim.compiled_engine`` measures both on one stimulus).
``CompiledEngine`` exports the engine (inside ``EngineHarness``, which gives every field its
own narrow port), writes a small C++ driver, builds both with Verilator once and caches the
binary under a key made of the Verilog, the driver and the Verilator version, so a changed
design rebuilds by itself. ``run`` then replays samples and register writes exactly as
``attitude_bench.run_engine`` does in Amaranth's simulator (the same handshakes and cycle
counts) and returns an ``EngineRun``.

Cache folder: ``$MPU9250_AHRS_CACHE`` or ``~/.cache/mpu9250-ahrs``. Needs ``verilator`` and a
C++ compiler (Debian: ``apt-get install verilator g++``); without them ``run`` raises
``RuntimeError`` with that hint.

Stimulus (little-endian int32): asa0..2, N, then per sample: the number of register writes W,
W × (address, value), gyro xyz, accel xyz, mag xyz (AK8963 axes), counter, mag_valid, overrun.
Results (int32 per sample): quat wxyz, angles, bias, counter, flags (``AttitudeFlags`` packed),
cycles (sample offered to result valid, as ``run_engine`` counts them).
"""

import contextlib
import fcntl
import functools
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from amaranth import *
from amaranth.back import verilog
from amaranth.lib import data, wiring
from amaranth.lib.wiring import In, Out

from ..hdl.attitude_isa import REG_BITS
from ..hdl.attitude_result import AttitudeFlags
from .attitude_bench import EngineRun


__all__ = ["EngineHarness", "CompiledEngine", "verilator_available", "configuration_writes",
           "run_gateware", "replay_gateware", "speed_benchmark"]

HINT = "install it with: apt-get install verilator g++"
# g++'s optimisation of Verilator's output: the per-cycle code ("fast") as much as its speed
# needs, the once-run code ("slow": construction, initial values) and Verilator's runtime not
# at all or little. Measured on the whole core (2 cores): -O1 for the fast code builds in 14 s
# instead of 18 s (Verilator's default -Os with -O3) and runs as fast; the engine runs whole
# recordings, so it keeps -O2 where it counts.
BUILD_OPTIMISATION = {
    "design": "OPT_FAST=-O1 OPT_SLOW=-O0 OPT_GLOBAL=-O1",
    "engine": "OPT_FAST=-O2 OPT_SLOW=-O0 OPT_GLOBAL=-O1",
}
_FLAG_NAMES = [name for name, _ in data.Layout.cast(AttitudeFlags)]


class EngineHarness(wiring.Component):
    """An ``AttitudeEngine`` with one port per field (for a C++ driver): the sample stream
    (``s_*``), register writes (``cfg_*``), the ASA bytes and the result stream (``r_*``,
    flags packed as ``AttitudeFlags``)."""

    def __init__(self, engine):
        self.engine = engine
        ports = {"s_valid": In(1), "s_ready": Out(1), "s_counter": In(32),
                 "s_mag_valid": In(1), "s_overrun": In(1),
                 "cfg_valid": In(1), "cfg_ready": Out(1), "cfg_addr": In(REG_BITS),
                 "cfg_data": In(signed(32)), "busy": Out(1),
                 "r_valid": Out(1), "r_ready": In(1), "r_counter": Out(32),
                 "r_flags": Out(data.Layout.cast(AttitudeFlags).size)}
        for v in ("gyro", "accel", "mag"):
            ports.update({f"s_{v}{i}": In(signed(16)) for i in range(3)})
        ports.update({f"asa{i}": In(8) for i in range(3)})
        ports.update({f"r_quat{i}": Out(signed(32)) for i in range(4)})
        for v in ("angles", "bias"):
            ports.update({f"r_{v}{i}": Out(signed(32)) for i in range(3)})
        super().__init__(ports)

    def elaborate(self, platform):
        m = Module()
        m.submodules.engine = e = self.engine
        s, r = e.samples, e.results
        m.d.comb += [
            s.valid.eq(self.s_valid), self.s_ready.eq(s.ready),
            s.payload.counter.eq(self.s_counter), s.payload.flags.mag_valid.eq(self.s_mag_valid),
            s.payload.flags.overrun.eq(self.s_overrun), s.payload.flags.data_ready.eq(1),
            e.cfg.valid.eq(self.cfg_valid), self.cfg_ready.eq(e.cfg.ready),
            e.cfg.payload.addr.eq(self.cfg_addr), e.cfg.payload.data.eq(self.cfg_data),
            self.busy.eq(e.busy),
            self.r_valid.eq(r.valid), r.ready.eq(self.r_ready),
            self.r_counter.eq(r.payload.counter), self.r_flags.eq(r.payload.flags.as_value()),
        ]
        for i in range(3):
            m.d.comb += [s.payload.gyro[i].eq(getattr(self, f"s_gyro{i}")),
                         s.payload.accel[i].eq(getattr(self, f"s_accel{i}")),
                         s.payload.mag[i].eq(getattr(self, f"s_mag{i}")),
                         e.asa[i].eq(getattr(self, f"asa{i}")),
                         getattr(self, f"r_angles{i}").eq(r.payload.angles[i]),
                         getattr(self, f"r_bias{i}").eq(r.payload.bias[i])]
        for i in range(4):
            m.d.comb += getattr(self, f"r_quat{i}").eq(r.payload.quat[i])
        return m


_DRIVER = r"""
// Generated by mpu9250_ahrs.sim.compiled_engine: replays a stimulus file through the engine.
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <vector>
#include "Vengine_harness.h"
#include "verilated.h"

static Vengine_harness *top;
static uint64_t cycles_total = 0;

static void tick() {
    top->clk = 0; top->eval();
    top->clk = 1; top->eval();
    ++cycles_total;
}

static int32_t next(FILE *f) {
    int32_t v;
    if (fread(&v, 4, 1, f) != 1) { fprintf(stderr, "stimulus file ends early\n"); exit(3); }
    return v;
}

int main(int argc, char **argv) {
    if (argc != 3) { fprintf(stderr, "usage: %s STIMULUS RESULTS\n", argv[0]); return 2; }
    Verilated::commandArgs(1, argv);
    FILE *in = fopen(argv[1], "rb"), *out = fopen(argv[2], "wb");
    if (!in || !out) { perror("open"); return 2; }
    top = new Vengine_harness;
    top->rst = 1; tick(); top->rst = 0; tick();
    top->asa0 = next(in); top->asa1 = next(in); top->asa2 = next(in);
    int32_t n = next(in);
    std::vector<int32_t> row(16);
    for (int32_t k = 0; k < n; ++k) {
        int32_t writes = next(in);
        for (int32_t w = 0; w < writes; ++w) {
            top->cfg_addr = next(in); top->cfg_data = next(in); top->cfg_valid = 1;
            top->eval();
            while (!top->cfg_ready) { tick(); top->eval(); }
            tick();
            top->cfg_valid = 0;
        }
        top->s_gyro0 = next(in); top->s_gyro1 = next(in); top->s_gyro2 = next(in);
        top->s_accel0 = next(in); top->s_accel1 = next(in); top->s_accel2 = next(in);
        top->s_mag0 = next(in); top->s_mag1 = next(in); top->s_mag2 = next(in);
        top->s_counter = next(in); top->s_mag_valid = next(in); top->s_overrun = next(in);
        top->s_valid = 1;
        top->eval();
        // as run_engine: wait out a reset still running, then count from the offer
        while (top->busy) { tick(); top->eval(); }
        int32_t count = 0;
        while (!top->s_ready) { tick(); top->eval(); ++count; }
        tick(); ++count;
        top->s_valid = 0; top->eval();
        while (!top->r_valid) { tick(); top->eval(); ++count; }
        row[0] = top->r_quat0; row[1] = top->r_quat1; row[2] = top->r_quat2;
        row[3] = top->r_quat3; row[4] = top->r_angles0; row[5] = top->r_angles1;
        row[6] = top->r_angles2; row[7] = top->r_bias0; row[8] = top->r_bias1;
        row[9] = top->r_bias2; row[10] = top->r_counter; row[11] = top->r_flags;
        row[12] = count;
        fwrite(row.data(), 4, 13, out);
        top->r_ready = 1; tick(); top->r_ready = 0; top->eval();
    }
    fprintf(stderr, "cycles %llu\n", (unsigned long long)cycles_total);
    fclose(out); fclose(in);
    top->final();
    delete top;
    return 0;
}
"""


def verilator_available():
    return shutil.which("verilator") is not None and shutil.which("g++") is not None


@functools.lru_cache(maxsize=None)
def verilator_version():
    """``verilator --version``: part of every cache key (asked once a process)."""
    return subprocess.run(["verilator", "--version"], capture_output=True,
                          text=True).stdout.strip()


def _cache_root():
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


def verilator_build(folder, output, sources, *, top, what, options=()):
    """``folder``/``output`` built by Verilator and g++ unless the cache has it, one process
    at a time (``build_lock``: another waits for the build and takes it). ``sources``: file
    name: its text, or a callable giving it (asked only when a build is needed), in the order
    Verilator takes them; ``top``: the top module; ``options``: Verilator's, beside the
    common ones. Returns the seconds spent building (0 when the cache had it)."""
    target = folder / output
    if target.exists():
        return 0.0
    with build_lock(folder):
        if target.exists():
            return 0.0
        if sys.stderr.isatty():
            # a one-time wait worth a word (the build is cached afterwards)
            print(f"mpu9250-ahrs: compiling the {what} with Verilator (seconds, once: cached "
                  f"in {folder.parent}) ...", file=sys.stderr, flush=True)
        start = time.perf_counter()
        with tempfile.TemporaryDirectory(dir=folder.parent) as tmp:
            tmp = Path(tmp)
            for name, text in sources.items():
                (tmp / name).write_text(text() if callable(text) else text)
            cmd = ["verilator", "--cc", "--exe", "--build", "-O3", "-Wno-fatal", "-Wno-lint",
                   "-Wno-style", "--top-module", top, *options, "--Mdir", str(tmp / "obj"),
                   "-o", output, *sources]
            result = subprocess.run(cmd, cwd=tmp, capture_output=True, text=True)
            if result.returncode:
                raise RuntimeError(f"verilator failed to build the {what}:\n"
                                   + (result.stderr or result.stdout)[-3000:])
            publish(tmp / "obj" / output, folder)
        return time.perf_counter() - start


class CompiledEngine:
    """One engine design (``make_engine()`` returns a fresh ``AttitudeEngine``) as a compiled
    Verilator model; ``build()`` is implicit in ``run``."""

    def __init__(self, make_engine):
        self.make_engine = make_engine
        self.binary = None
        self.build_s = 0.0            # seconds spent building (0 when the cache had it)
        self.last_cycles = 0          # simulated cycles of the last run
        self.last_wall_s = 0.0

    def _verilog(self):
        return verilog.convert(EngineHarness(self.make_engine()), name="engine_harness")

    def build(self):
        """Path of the compiled model, building it unless the cache has it."""
        if self.binary is not None:
            return self.binary
        if not verilator_available():
            raise RuntimeError(f"the compiled engine needs verilator and g++; {HINT}")
        text = self._verilog()
        key = hashlib.sha256("\0".join((text, _DRIVER, verilator_version(),
                                        BUILD_OPTIMISATION["engine"])).encode()
                             ).hexdigest()[:20]
        folder = _cache_root() / f"engine-{key}"
        self.build_s = verilator_build(
            folder, "engine_sim", {"engine_harness.v": text, "driver.cpp": _DRIVER},
            top="engine_harness", what="engine",
            options=["-MAKEFLAGS", BUILD_OPTIMISATION["engine"]])
        self.binary = folder / "engine_sim"
        return self.binary

    def run(self, gyro, accel, mag_ak, mag_valid=None, *, asa=(128, 128, 128), writes=None,
            counter=None, overrun=None):
        """Like ``attitude_bench.run_engine`` (same arguments, same ``EngineRun``)."""
        binary = self.build()
        n = len(gyro)
        valid = np.ones(n, bool) if mag_valid is None else np.asarray(mag_valid, bool)
        counter = np.arange(n) % (1 << 32) if counter is None else np.asarray(counter)
        overrun = np.zeros(n, bool) if overrun is None else np.asarray(overrun, bool)
        writes = writes or {}
        per_sample = np.column_stack([np.asarray(gyro, np.int64), np.asarray(accel, np.int64),
                                      np.asarray(mag_ak, np.int64), counter, valid,
                                      overrun]).astype("<i4") if n else np.empty((0, 12), "<i4")
        chunks = [np.array([*asa, n], "<i4").tobytes()]
        for k in range(n):
            w = writes.get(k, ())
            chunks.append(np.array([len(w), *(int(x) for pair in w for x in pair)],
                                   "<i4").tobytes())
            chunks.append(per_sample[k].tobytes())
        with tempfile.TemporaryDirectory() as tmp:
            stim, res = Path(tmp) / "stimulus.bin", Path(tmp) / "results.bin"
            stim.write_bytes(b"".join(chunks))
            start = time.perf_counter()
            result = subprocess.run([str(binary), str(stim), str(res)], capture_output=True,
                                    text=True)
            self.last_wall_s = time.perf_counter() - start
            if result.returncode:
                raise RuntimeError(f"compiled engine failed: {result.stderr.strip()}")
            self.last_cycles = int(result.stderr.split()[-1])
            rows = np.frombuffer(res.read_bytes(), "<i4").reshape(-1, 13).astype(np.int64)
        flags = rows[:, 11]
        layout = data.Layout.cast(AttitudeFlags)
        unpack = lambda name: (flags >> layout[name].offset) & ((1 << layout[name].width) - 1)
        return EngineRun(quat=rows[:, 0:4], angles=rows[:, 4:7], bias=rows[:, 7:10],
                         **{name: unpack(name).astype(bool) for name in _FLAG_NAMES
                            if name not in ("filter", "overrun")},
                         filter=unpack("filter"), counter=rows[:, 10] & 0xFFFFFFFF,
                         cycles=rows[:, 12].tolist())

    @property
    def cycles_per_s(self):
        return self.last_cycles / self.last_wall_s if self.last_wall_s else 0.0


def configuration_writes(filter, kalman, flagship, cal=None):
    """Register writes that set an engine up for ``filter`` with these configurations (and
    calibration), then select it with a filter reset (so that INIT starts from the new P₀):
    what a host sends, and what makes one compiled build serve every recording."""
    from ..hdl.attitude_program import CONFIG_REGS, CONTROL_ADDR, control_word
    from ..reference.fixed_point import CalibrationFixed, calibration_registers
    regs = {**kalman.registers(), **flagship.registers(),
            **calibration_registers(CalibrationFixed() if cal is None else cal)}
    return [(CONFIG_REGS[name], value) for name, value in regs.items()] + [
        (CONTROL_ADDR, control_word(filter, reset=True))]


def run_gateware(filter, gyr_counts, acc_counts, mag_counts, dt, *, mag_valid=None,
                 engine=None, **scales_and_params):
    """A recording (body-axis counts) through the compiled engine, set up for ``filter`` by
    register writes before the first sample: (EngineRun, CompiledEngine, the configurations
    (KalmanFixedConfig, FlagshipFixedConfig))."""
    from ..hdl.attitude_engine import AttitudeEngine
    from ..reference.evaluate import engine_configs
    from ..reference.frames import body_to_mag
    configs = engine_configs(filter, dt, **scales_and_params)
    engine = CompiledEngine(AttitudeEngine) if engine is None else engine
    run = engine.run(gyr_counts, acc_counts, body_to_mag(mag_counts), mag_valid,
                     writes={0: configuration_writes(filter, *configs)})
    return run, engine, configs


def replay_gateware(filter, gyr_counts, acc_counts, mag_counts, dt, *, mag_valid=None,
                    engine=None, **scales_and_params):
    """``run_gateware``, and the bit-exact model over the same samples: (EngineRun,
    AttitudeFixed, CompiledEngine)."""
    from ..reference.fixed_point import attitude_fixed
    from ..reference.frames import body_to_mag
    run, engine, (kalman, flagship) = run_gateware(filter, gyr_counts, acc_counts, mag_counts,
                                                   dt, mag_valid=mag_valid, engine=engine,
                                                   **scales_and_params)
    ref = attitude_fixed(gyr_counts, acc_counts, body_to_mag(mag_counts), mag_valid,
                         config=kalman, flagship=flagship, select=filter)
    return run, ref, engine


def speed_benchmark(samples=150, filter="flagship"):
    """The same stimulus (static, then random motion; the field valid every third sample)
    through Amaranth's simulator and the compiled model: cycles/s of each and their ratio,
    with the results checked equal. A benchmark, not a test: the figures depend on the
    machine."""
    from ..hdl.attitude_engine import AttitudeEngine
    from ..hdl.attitude_program import CONTROL_ADDR, control_word
    from ..reference.frames import body_to_mag
    from .attitude_bench import RESULT_FIELDS, run_engine
    from .motion import SensorModel, concat, random_motion, static
    traj = concat(static((10, 20, 30), samples / 200), random_motion(samples / 200, seed=1))
    gc, ac, mc = SensorModel(seed=2).counts(traj)
    mk = body_to_mag(mc)
    valid = np.arange(len(gc)) % 3 == 0
    writes = {0: [(CONTROL_ADDR, control_word(filter, reset=True))]}
    compiled = CompiledEngine(AttitudeEngine)
    compiled.build()
    fast = compiled.run(gc, ac, mk, valid, writes=writes)
    start = time.perf_counter()
    slow = run_engine(AttitudeEngine(), gc, ac, mk, valid, writes=writes)
    pysim_s = time.perf_counter() - start
    same = all(np.array_equal(np.asarray(getattr(slow, f)), np.asarray(getattr(fast, f)))
               for f in RESULT_FIELDS + ("cycles",))
    # both simulate the same cycles (the compiled count includes the reset and INIT)
    pysim_rate = compiled.last_cycles / pysim_s
    return {"filter": filter, "samples": len(gc), "cycles": compiled.last_cycles,
            "identical_results": same, "pysim_s": round(pysim_s, 2),
            "pysim_cycles_per_s": round(pysim_rate),
            "compiled_s": round(compiled.last_wall_s, 4),
            "compiled_cycles_per_s": round(compiled.cycles_per_s),
            "speed_ratio": round(compiled.cycles_per_s / pysim_rate),
            "build_s": round(compiled.build_s, 1)}


if __name__ == "__main__":
    import json
    print(json.dumps(speed_benchmark()))
