"""Command line: ``python -m mpu9250_ahrs <verb>`` (or ``mpu9250-ahrs <verb>``).

The verbs by audience, a module each: ``gateware`` (build, report), ``simulation``
(simulate, replay), ``host_verbs`` (monitor, config, calibrate, board, plot); ``options``: what
they share. This module: the parser, ``main`` and what every verb goes through."""

import argparse
import os
import sys
from pathlib import Path

from . import gateware, host_verbs, simulation, twin_verb


__all__ = ["build_parser", "main"]


VERBS_HELP = """verbs:
  build      write the Quartus project for the 10M08SCU169 (top.v, top.qsf, top.sdc, build
             scripts) without running Quartus; --verilog-only writes the core as plain Verilog
  simulate   cycle-accurate co-simulation: the gateware brings an MPU9250 model up over SPI
             and reads samples; prints them, the bring-up time and the simulator's speed;
             with --attitude the whole core (driver, engine, telemetry): every result,
             samples filtered / lost, saturated results, data-ready-to-attitude latency;
             with --fault NAME a fault of the catalogue (hdl/FAULTS.md) injected into the
             models: when it was detected, the flags, recovery, stale samples passed on
  replay     run a filter on a recording (BROAD HDF5 format), quantised to MPU9250/AK8963
             counts: the float reference, the bit-exact model (--engine fixed) or the gateware
             in a compiled simulation (--engine gateware); print its errors against the optical
             truth as JSON
  twin       a two-wheeled balancing robot's plant in a closed loop with the balance
             controller: its fixed-point model, or the gateware (--loop chip: the whole
             core co-simulated, its sensor models reading the plant, its PWM pins moving
             it), pushed: upright, worst tilt, when it fell, pushes recovered, as JSON
  report     resources of the attitude datapath and of the whole design from Yosys (MAX10
             mapping), cycles per filter update, the clock, the co-simulated latency and the
             highest sample rate the design sustains, as JSON
  monitor    decode a board's frames on a serial port (or PORT=sim: the co-simulated design
             behind a pseudo-terminal): a live line, a CSV or HDF5 log, a JSON summary
  config     read or write the board's registers by name in physical units, select the
             filter, reset it, set the telemetry rate (hdl/FRAMES.md)
  board      start the co-simulated board on a pseudo-terminal and keep it running: its
             path is a PORT for monitor, config and calibrate, as a real board's (configure,
             then watch, as on hardware)
  calibrate  guided calibration (gyro at rest, six accelerometer poses, magnetometer turned
             through all orientations), checked, written to the board and saved as JSON for
             build --calibration
  plot       a monitor log's attitude, rates and flags against time, as an image
"""


def _version():
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version("mpu9250-ahrs")
    except PackageNotFoundError:
        return "(not installed)"


def _prepare_outputs(args):
    """Every file a verb will write (``--vcd``, ``--csv``, ``--hdf5``, a file ``--out``):
    its folder made and checked writable before any work starts, so that a long run (a
    calibration turned by hand, a simulation) never ends in a missing folder."""
    names = ["vcd", "csv", "hdf5"] + (["out"] if args.verb != "build" else [])
    out = getattr(args, "out", None)
    if args.verb == "build" and out and Path(out).exists() and not Path(out).is_dir():
        # build writes a folder of files (was "File exists", naming no option)
        raise ValueError(f"--out {out} is a file; build writes a folder: name a new or an "
                         f"existing folder")
    for name in names:
        path = getattr(args, name, None)
        if not path:
            continue
        path = Path(path)
        if path.is_dir():
            raise ValueError(f"--{name} {path} is a folder, not a file")
        path.parent.mkdir(parents=True, exist_ok=True)
        if not os.access(path.parent, os.W_OK):
            raise OSError(f"--{name} {path}: the folder {path.parent} is not writable")


def build_parser():
    parser = argparse.ArgumentParser(
        prog="mpu9250-ahrs", description="MPU9250 attitude reference in FPGA gateware.",
        epilog=VERBS_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB", required=True)
    quiet = argparse.ArgumentParser(add_help=False)
    quiet.add_argument("--quiet", action="store_true",
                       help="no progress bars on stderr (they show only on a terminal anyway)")

    # the verbs by audience (build and report: gateware; simulate and replay: no board; the
    # host verbs), in the order the help lists them
    gateware.add_build(sub, quiet)
    simulation.add_simulate(sub, quiet)
    simulation.add_replay(sub, quiet)
    twin_verb.add_twin(sub, quiet)
    gateware.add_report(sub, quiet)
    host_verbs.add_host_verbs(sub, quiet)
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    from ..progress import set_quiet
    set_quiet(getattr(args, "quiet", False))
    try:
        _prepare_outputs(args)
        return args.func(args)
    except (ValueError, OSError, RuntimeError) as e:
        if isinstance(e, OSError) and e.filename is not None and e.strerror:
            e = f"{e.filename}: {e.strerror}"     # not "[Errno 2] No such file ...: 'x'"
        print(f"mpu9250-ahrs {args.verb}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"mpu9250-ahrs {args.verb}: interrupted; {_kept(args)}", file=sys.stderr)
        return 130


def _kept(args):
    """What an interrupted verb leaves behind, in words: the files it was writing that exist
    (complete up to the interruption), or that nothing was written."""
    names = ["vcd", "csv", "hdf5", "out"]
    found = []
    for name in names:
        path = getattr(args, name, None)
        if path and Path(path).exists():
            found.append(f"{path}{'/' if Path(path).is_dir() else ''}")
    if not found:
        return "nothing was written"
    return "kept as far as it got: " + ", ".join(found)
