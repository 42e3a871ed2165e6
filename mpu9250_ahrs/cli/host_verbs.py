"""The host verbs, for a board on a serial port or the simulated one: ``monitor``, ``config``,
``calibrate``, ``board`` (the simulated board kept running) and ``plot``."""

import json
import sys
import time

from ..hdl.contract.defaults import DEFAULT_BAUD
from ..hdl.contract.filter_registry import FILTER_NAMES
from .options import _add_full_scale_options, _count, _positive


__all__ = ["add_host_verbs", "cmd_board", "cmd_monitor", "cmd_config", "cmd_calibrate",
           "cmd_plot"]


def _add_port_options(p):
    p.add_argument("port", metavar="PORT",
                   help="serial device (/dev/ttyUSB0, COM3), or 'sim': the co-simulated design "
                        "behind a pseudo-terminal, started here")
    p.add_argument("--baud", type=_count, default=DEFAULT_BAUD,
                   help=f"the board's UART ({DEFAULT_BAUD})")
    p.add_argument("--timeout", type=_positive, default=1.0, metavar="S",
                   help="seconds without a valid frame (or a reply) before giving up (1)")


def add_host_verbs(sub, quiet):
    """The host verbs' options."""
    p = sub.add_parser("monitor", parents=[quiet], help="decode and log a board's frames",
                       description="Decode the board's frames: a live line on stderr (frame "
                                   "rate, attitude, flags, CRC errors, frames lost by the "
                                   "sequence numbers), every frame logged, a JSON summary "
                                   "on stdout at the end.")
    _add_port_options(p)
    log = p.add_mutually_exclusive_group()
    log.add_argument("--csv", default=None, metavar="FILE", help="log every frame as CSV")
    log.add_argument("--hdf5", default=None, metavar="FILE", help="... or as HDF5")
    p.add_argument("--frames", type=_count, default=None, metavar="N",
                   help="stop after N frames (default: until Ctrl-C)")
    p.set_defaults(func=cmd_monitor)

    p = sub.add_parser("config", parents=[quiet], help="read or write the board's registers",
                       description="get NAME | set NAME VALUE | filter NAME | reset | rate HZ | "
                                   "list. Names, formats and units: hdl/FRAMES.md (VALUE in the "
                                   "register's unit; the tool converts).")
    _add_port_options(p)
    p.add_argument("action", choices=("get", "set", "filter", "reset", "rate", "list"),
                   help=f"get NAME, set NAME VALUE, filter NAME ({', '.join(FILTER_NAMES)}), "
                        "reset (the filter's state), rate HZ (telemetry), list")
    p.add_argument("args", nargs="*", metavar="ARG", help="the action's arguments")
    p.set_defaults(func=cmd_config)

    p = sub.add_parser("calibrate", parents=[quiet],
                       help="guided calibration, written to the board and saved",
                       description="Gyro bias at rest, the accelerometer in six poses, the "
                                   "magnetometer turned through all orientations; each step "
                                   "checked; the result written to the board and saved as "
                                   "JSON (build --calibration FILE bakes it in). With PORT=sim "
                                   "a simulated user moves the simulated board.")
    _add_port_options(p)
    p.add_argument("--out", default="calibration.json", metavar="FILE",
                   help="where to save the result (calibration.json)")
    _add_full_scale_options(p, gyro=False, whose="the board's ")
    p.add_argument("--quick", action="store_true",
                   help="collect less and skip the read-back (for a simulated board; the "
                        "default with PORT=sim)")
    p.set_defaults(func=cmd_calibrate)

    p = sub.add_parser("board", parents=[quiet], help="the simulated board on a pseudo-terminal, "
                                                      "kept running",
                       description="Start the co-simulated design (the models, the driver, the "
                                   "engine, the command channel) behind a pseudo-terminal, print "
                                   "its path and keep it running until Ctrl-C: monitor, config "
                                   "and calibrate then use that path as a serial port, so a "
                                   "configuration made by one command is seen by the next. "
                                   "Compiled (Verilator and g++ there) it sends tens of frames a "
                                   "second; in Amaranth's simulator about one: then give the "
                                   "host verbs --timeout 60.")
    p.add_argument("--seconds", type=_positive, default=None, metavar="S",
                   help="stop after S seconds (default: run until Ctrl-C)")
    p.set_defaults(func=cmd_board)

    p = sub.add_parser("plot", parents=[quiet], help="plot a monitor log",
                       description="Attitude, gyro rates and flags of a monitor log (CSV or "
                                   "HDF5) against time, written as an image.")
    p.add_argument("log", metavar="LOG", help="a monitor log (CSV or HDF5)")
    p.add_argument("--out", required=True, metavar="FILE.png", help="the image to write")
    p.set_defaults(func=cmd_plot)


def _open(args):
    """The link of a host verb: ``--port sim`` starts a simulated board here and hands it to
    the link (which stops it on close)."""
    from ..host.link import open_link
    board = None
    if args.port == "sim":
        from ..sim.scenarios.board import SimulatedBoard
        board = SimulatedBoard().start()
    try:
        return open_link(args.port, args.baud, timeout=args.timeout, board=board)
    except Exception:
        if board is not None:
            board.stop()
        raise


def _progress(what, k, n):
    if k == 1 or k == n or k % 10 == 0:
        sys.stderr.write(f"\r{what}: {k}/{n}   ")
        if k == n:
            sys.stderr.write("\n")
        sys.stderr.flush()


def cmd_board(args):
    """``board``: a SimulatedBoard on a pseudo-terminal until Ctrl-C (or ``--seconds``)."""
    from ..sim.scenarios.board import SimulatedBoard
    board = SimulatedBoard().start()
    print(f"simulated board on {board.port}", flush=True)
    if board.compiled:
        print(f"use it as the PORT of monitor, config and calibrate (compiled: tens of frames "
              f"a second), e.g.: python -m mpu9250_ahrs config {board.port} filter "
              f"complementary; Ctrl-C stops it", file=sys.stderr, flush=True)
    else:
        print(f"use it as the PORT of monitor, config and calibrate, with --timeout 60 "
              f"(Amaranth's simulator, no verilator/g++ here: about a frame a second), e.g.: "
              f"python -m mpu9250_ahrs config {board.port} --timeout 60 filter complementary; "
              f"Ctrl-C stops it", file=sys.stderr, flush=True)
    start = time.monotonic()
    try:
        while args.seconds is None or time.monotonic() - start < args.seconds:
            if board.error is not None:
                break
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    cycles = board.cycles
    board.stop()                        # raises (one line, exit 2) if the simulation failed
    print(f"simulated board stopped after {cycles:,} cycles", file=sys.stderr)
    return 0


def cmd_monitor(args):
    from ..host.monitor import monitor
    with _open(args) as link:
        summary = monitor(link, frames=args.frames, csv_path=args.csv, hdf5_path=args.hdf5)
    print(json.dumps(summary))
    return 0


def cmd_config(args):
    from ..host import config as c
    from ..host.regmap import REGISTERS
    expected = {"get": 1, "set": 2, "filter": 1, "reset": 0, "rate": 1, "list": 0}[args.action]
    if len(args.args) != expected:
        raise ValueError(f"config {args.action} takes {expected} argument(s), not "
                         f"{len(args.args)}")
    # checked before the board is opened (a simulated one is started for nothing else)
    rate = _positive(args.args[0]) if args.action == "rate" else None
    if args.action == "list":
        for reg in REGISTERS.values():
            print(f"{reg.name:16} {reg.space:6} 0x{reg.addr:02X} {reg.format:6} "
                  f"{'rw' if reg.writable else 'ro'} {reg.unit}")
        return 0
    with _open(args) as link:
        link.identify()
        if args.action == "get":
            result = c.get(link, args.args[0])
        elif args.action == "set":
            result = c.set_register(link, *args.args)
        elif args.action == "filter":
            result = c.select_filter(link, args.args[0])
        elif args.action == "reset":
            result = c.reset_filter(link)
        else:
            result = c.set_rate(link, rate)
    if "note" in result:
        print(f"mpu9250-ahrs config: warning: {result['note']}", file=sys.stderr)
    print(json.dumps(result))
    return 0


def cmd_calibrate(args):
    from ..host.calibrate import Amounts, calibrate, human_operator
    sim = args.port == "sim"
    amounts = Amounts(rest=12, pose=6, fields=24, settle=2, read_back=False) \
        if (args.quick or sim) \
        else Amounts()
    with _open(args) as link:
        operator = human_operator
        if link.board is not None:
            operator = _simulated_user(link.board)
        result = calibrate(link, operator=operator, amounts=amounts, accel_fs_g=args.accel_fs,
                           progress=_progress, out_json=args.out)
    print(json.dumps({k: result[k] for k in ("gyro_offset", "accel_offset", "accel_scale",
                                             "hard_iron", "checks")}))
    print(f"saved to {args.out}; build --calibration {args.out} bakes it in", file=sys.stderr)
    return 0


def _simulated_user(board):
    """Moves the simulated board as ``calibrate`` asks."""
    from ..host.calibrate import POSES

    def operator(step, text):
        print(f"[simulated user] {text}", file=sys.stderr)
        if step == "tumble":
            board.tumble()
        else:
            board.set_pose(*POSES.get(step, (0, 0, 0)))
    return operator


def cmd_plot(args):
    from ..host.plot import plot_log
    print(json.dumps(plot_log(args.log, args.out)))
    return 0
