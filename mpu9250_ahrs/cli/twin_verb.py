"""The ``twin`` verb: the balance controller's closed-loop digital twin (``sim/scenarios/twin.py``),
pushed, summarised as one JSON line, optionally plotted."""

import json
import sys

from .options import _number, _positive


__all__ = ["add_twin", "cmd_twin"]


def add_twin(sub, quiet):
    from ..sim.scenarios.twin import LOOPS
    p = sub.add_parser(
        "twin", parents=[quiet], help="a balancing robot's loop closed around a plant model",
        description="A two-wheeled inverted pendulum (NXTway-GS figures: sim/models/"
                    "balance_plant.py) under a balance controller, pushed; prints one JSON line "
                    "last: upright, max_abs_pitch_deg, fell_at_s, pushes_recovered, wall_s "
                    "(--loop chip: estimate_rms_deg, the gateware's pitch against the plant's). "
                    "--loop off is the negative control (no controller: it falls).")
    p.add_argument("--seconds", type=_positive, default=10.0, help="plant time (default 10)")
    p.add_argument("--loop", choices=LOOPS, default="model",
                   help="model: the controller's fixed-point model on the plant's tilt "
                        "(default); float: its float law; chip: the gateware, the whole core "
                        "co-simulated with its sensor models reading the plant (about 15 s of "
                        "wall time per simulated second); host: the law on a PC reading the "
                        "co-simulated board's frames and writing its PWM registers back "
                        "(--host-latency-ms); off: none")
    p.add_argument("--push", action="append", default=[], metavar="F@T",
                   help="a horizontal force of F newtons on the body's centre of mass for "
                        "100 ms from T seconds (repeatable)")
    p.add_argument("--tilt", type=_number("an angle"), default=1.0, metavar="DEG",
                   help="the tilt at the start (default 1°)")
    p.add_argument("--host-latency-ms", type=_number("a latency", low=0), default=None,
                   metavar="L", help="with --loop host: how long after its last byte the host "
                                     "has a frame (an FTDI adapter's latency timer: 16 ms by "
                                     "default, 1 at best; default 1)")
    p.add_argument("--fault", default=None, metavar="NAME",
                   help="with --loop chip: a fault of the catalogue (simulate --fault list) "
                        "injected with the controller armed, for its catalogue duration: the "
                        "summary says when the motors were off (disarmed_after_ms) or that "
                        "they ran on (motors_ran_on); the mid-run SPI faults "
                        "(hdl/FAULTS.md)")
    p.add_argument("--fault-at", type=_positive, default=1.0, metavar="S",
                   help="the fault's time after arming (default 1 s)")
    p.add_argument("--plot", default=None, metavar="FILE",
                   help="an image of the tilt, the controller's tilt, the duty and the pushes")
    p.add_argument("--vcd", default=None, metavar="FILE",
                   help="with --loop chip: the gateware's waveform (every signal of the core, "
                        "traced by the compiled design: a build of its own) and a GTKWave "
                        ".gtkw beside it; FILE ending in .fst: GTKWave's compressed format. "
                        "The window: --trace-from/--trace-to, times from the arming; default "
                        "its first 50 ms")
    p.add_argument("--trace-from", default=None, metavar="WHEN",
                   help="with --vcd: trace from WHEN after the arming (10ms, 2.9s); default 0")
    p.add_argument("--trace-to", default=None, metavar="WHEN",
                   help="with --vcd: trace until WHEN after the arming; default 50 ms after "
                        "the start of the window")
    p.set_defaults(func=cmd_twin)


def cmd_twin(args):
    from ..progress import bar
    from ..sim.scenarios.twin import TwinTrace, parse_push, run_twin
    pushes = [parse_push(text) for text in args.push]
    if args.vcd and args.loop != "chip":
        raise ValueError("--vcd needs --loop chip: the waveform is the gateware's")
    from .simulation import _waveform
    wave = _waveform(args)
    if args.host_latency_ms is not None and args.loop != "host":
        raise ValueError("--host-latency-ms needs --loop host")
    trace = TwinTrace() if args.plot else None
    with bar(total=round(args.seconds), desc="twin", unit="s") as shown:
        summary = run_twin(args.seconds, loop=args.loop, pushes=pushes, tilt_deg=args.tilt,
                           trace=trace, progress=lambda t: shown.update(1) if t else None,
                           host_latency_ms=args.host_latency_ms or 1.0, fault=args.fault,
                           fault_at_s=args.fault_at, vcd=wave)
    if args.plot:
        _plot(trace, args.plot, summary)
    print(json.dumps(summary), file=sys.stdout)
    return 0


def _plot(trace, path, summary):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RuntimeError("--plot needs matplotlib (pip install matplotlib)") from None
    fig, (ax_tilt, ax_duty) = plt.subplots(2, 1, sharex=True, figsize=(10, 6))
    ax_tilt.plot(trace.t, trace.tilt_deg, label="plant tilt")
    ax_tilt.plot(trace.t, trace.seen_deg, label="controller's tilt", linestyle="--")
    ax_tilt.set_ylabel("tilt (°)")
    ax_tilt.legend(loc="upper right")
    ax_duty.plot(trace.t, trace.duty, label="duty", color="tab:green")
    ax_duty.plot(trace.t, [f / 10 for f in trace.push], label="push (N/10)", color="tab:red")
    ax_duty.set_ylabel("duty, push")
    ax_duty.set_xlabel("time (s)")
    ax_duty.legend(loc="upper right")
    fig.suptitle(f"twin, loop {summary['loop']}: upright {summary['upright']}, "
                 f"max |tilt| {summary['max_abs_pitch_deg']}°")
    fig.savefig(path, dpi=100)
    plt.close(fig)
