"""The comparison table on BROAD recordings, and the figure.

    python -m mpu9250_ahrs.sim.scenarios.benchmark ../shared/data/broad/*.hdf5 \\
        [--json results.json] [--figure trial.png] [--jobs 2]

Every filter gets the same quantised inputs (MPU9250 ±2000 °/s, ±16 g; AK8963 0.15 µT/LSB) and
one parameter set for all trials. Prints a markdown table of total RMSE (BROAD's metric,
degrees, over the movement samples) per trial and the mean. The fixed-point rows run the
bit-exact integer model of the engine (slow in Python: minutes per trial; the seven shared
trials took 17 minutes with ``--jobs 2`` on a 2-core machine, measured in review #60); the
gateware rows run the engine's Verilog in Verilator (needs verilator, g++ and make) and are checked
bit for bit against the fixed rows.
Needs the ``bench`` extra for the libraries (``pip install -e ".[bench]"``).
"""

import argparse
import json
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from ...hdl.contract.filter_registry import FILTER_NAMES, FLOAT_FILTERS
from ...reference.recording import Scales, load_broad, quantise, to_units
from ...reference.compare import external_filters, missing_external_filters
from ...reference.entry_point import count, run_main
from ...reference.evaluate import run_filter, run_fixed, score
from ...reference.kalman import KalmanParams


__all__ = ["FILTER_SET", "run_trial", "table", "split_table", "main"]

# Rows beside each filter's defaults (name: (what follows the name in the row, parameters)); a
# filter with rows here but no fixed point has only these
VARIANTS = {
    "kalman": [(", Euler rates", {"kalman": KalmanParams(rates="euler")})],
    "complementary": [(", Euler rates", {"rates": "euler"})],
    "madgwick": [(" β=0.2", {"beta": 0.2})],
}


def _filter_set():
    """(row name, kind, filter, parameters), one parameter set for all trials, from the
    registry (``hdl/contract/filter_registry.py``): each float filter (its defaults, its fixed point
    if the gateware has it, its variants), then the gateware's, the engine's Verilog in Verilator
    (``sim/scenarios/compiled_engine.py``; "≠" marks a result that is not bit for bit the fixed row's)."""
    rows = []
    for name in FLOAT_FILTERS:
        if name in FILTER_NAMES or name not in VARIANTS:
            rows.append((f"{name} (float)", "float", name, {}))
        if name in FILTER_NAMES:
            rows.append((f"{name} (fixed)", "fixed", name, {}))
        for label, params in VARIANTS.get(name, []):
            rows.append((f"{name}{label} (float)", "float", name, params))
    return rows + [(f"{name} (gateware)", "gateware", name, {}) for name in FILTER_NAMES]


FILTER_SET = _filter_set()


def run_trial(path, with_fixed=True):
    rec = load_broad(path)
    scales = Scales()
    counts = quantise(rec.gyr, rec.acc, rec.mag, scales)
    gyr, acc, mag = to_units(*counts, scales)
    units = {"gyro_lsb_per_dps": scales.gyro_lsb_per_dps,
             "accel_lsb_per_ms2": scales.accel_lsb_per_ms2}
    out, fixed = {}, {}
    for row, kind, name, params in FILTER_SET:
        if kind != "float" and not with_fixed:
            continue
        start = time.perf_counter()
        extra = {}
        if kind == "float":
            quat = run_filter(name, gyr, acc, mag, rec.dt, **params)
        elif kind == "fixed":
            quat = fixed[name] = run_fixed(name, *counts, rec.dt, **units, **params)
        else:
            from .compiled_engine import run_gateware
            from ...reference.flagship_fixed import q30_to_float
            run = run_gateware(name, *counts, rec.dt, **units, **params)[0]
            quat = q30_to_float(run.quat)
            extra = {"bit_exact": bool(np.array_equal(quat, fixed.get(name))),
                     "cycles_max": max(run.cycles[1:])}
        out[row] = {**score(quat, rec.quat, rec.movement), **extra,
                    "seconds": round(time.perf_counter() - start, 2)}
    for row, fn in external_filters().items():
        start = time.perf_counter()
        quat = fn(gyr, acc, mag, rec.rate)
        out[row] = {**score(quat, rec.quat, rec.movement),
                    "seconds": round(time.perf_counter() - start, 2)}
    return rec.name, out


def table(results):
    trials = sorted(results)
    rows = list(next(iter(results.values())))
    short = [t.split("_")[0] for t in trials]
    lines = ["| filter | " + " | ".join(short) + " | mean |",
             "|---" * (len(trials) + 2) + "|"]
    for row in rows:
        vals = [results[t][row]["total_rmse_deg"] for t in trials if row in results[t]]
        cells = [(f"{results[t][row]['total_rmse_deg']:.2f}"
                  + ("" if results[t][row].get("bit_exact", True) else " ≠"))
                 if row in results[t] else "–" for t in trials]
        lines.append(f"| {row} | " + " | ".join(cells) + f" | {np.mean(vals):.2f} |")
    return "\n".join(lines)


# the rows the inclination/heading split is printed for (those present)
SPLIT_ROWS = ("flagship (float)", "vqf")


def split_table(results, rows=SPLIT_ROWS):
    """Inclination / heading RMSE (degrees) per trial and their means, for ``rows``: where
    each filter's error comes from (tilt, or heading)."""
    trials = sorted(results)
    short = [t.split("_")[0] for t in trials]
    lines = ["| inclination / heading | " + " | ".join(short) + " | mean |",
             "|---" * (len(trials) + 2) + "|"]
    for row in rows:
        if not all(row in results[t] for t in trials):
            continue
        pairs = [(results[t][row]["inclination_rmse_deg"], results[t][row]["heading_rmse_deg"])
                 for t in trials]
        cells = [f"{i:.2f} / {h:.2f}" for i, h in pairs]
        mean_i, mean_h = np.mean(pairs, axis=0)
        lines.append(f"| {row} | " + " | ".join(cells) + f" | {mean_i:.2f} / {mean_h:.2f} |")
    return "\n".join(lines)


def figure(path, out_png, filter_name="flagship"):
    """Estimated vs true roll, pitch, yaw over time for one trial."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from ...reference.frames import quat_to_euler

    rec = load_broad(path)
    gyr, acc, mag = to_units(*quantise(rec.gyr, rec.acc, rec.mag))
    est = np.degrees(quat_to_euler(run_filter(filter_name, gyr, acc, mag, rec.dt)))
    truth = np.degrees(quat_to_euler(rec.quat))
    t = np.arange(len(est)) * rec.dt
    fig, axes = plt.subplots(3, 1, figsize=(11, 7), sharex=True)
    for ax, k, label in zip(axes, range(3), ("roll", "pitch", "yaw")):
        ax.plot(t, truth[:, k], "k-", lw=1.0, label="optical truth")
        ax.plot(t, est[:, k], "C1-", lw=0.8, label=f"{filter_name} (MPU9250-quantised)")
        ax.set_ylabel(f"{label} [°]")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right")
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"BROAD trial {rec.name}")
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)


def _ignore_interrupt():
    import signal
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m mpu9250_ahrs.sim.scenarios.benchmark",
                                description=__doc__.split("\n\n")[0])
    p.add_argument("files", nargs="+", help="BROAD recordings (HDF5)")
    p.add_argument("--json", help="write all figures as JSON")
    p.add_argument("--figure", help="PNG of roll/pitch/yaw vs truth for the first file")
    p.add_argument("--no-fixed", action="store_true",
                   help="skip the (slow) fixed-point and gateware rows")
    p.add_argument("--jobs", type=count, default=1, help="trials run in parallel (1)")
    args = p.parse_args(argv)
    # the files it writes: their folders made, and checked writable, before minutes of work
    for name in ("json", "figure"):
        path = getattr(args, name)
        if path:
            folder = os.path.dirname(os.path.abspath(path))
            try:
                os.makedirs(folder, exist_ok=True)
            except OSError as e:
                print(f"benchmark: error: --{name} {path}: {e}", file=sys.stderr)
                return 2
            if os.path.isdir(path) or not os.access(folder, os.W_OK):
                print(f"benchmark: error: --{name} {path}: not a writable file path",
                      file=sys.stderr)
                return 2
    missing = missing_external_filters()
    if missing:
        # said at the start, not left for the reader to notice the rows are gone
        print(f"benchmark: note: no rows for {', '.join(missing)}: their libraries are not "
              f"installed (pip install -e \".[bench]\")", file=sys.stderr)
    try:
        from tqdm import tqdm
        # the workers leave Ctrl-C to this process (each would print its traceback)
        pool = ProcessPoolExecutor(args.jobs, initializer=_ignore_interrupt)
        try:
            # progress on stderr, on a terminal only: a trial takes minutes
            results = dict(tqdm(pool.map(run_trial, args.files,
                                         [not args.no_fixed] * len(args.files)),
                                total=len(args.files), desc="benchmark", unit="trial",
                                file=sys.stderr, leave=False, disable=not sys.stderr.isatty()))
        except KeyboardInterrupt:
            for process in list(getattr(pool, "_processes", {}).values()):
                process.terminate()             # a trial takes minutes: not waited for
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown()
    except (OSError, ValueError) as e:          # a missing or malformed recording: one line
        print(f"benchmark: error: {e}", file=sys.stderr)
        return 2
    print(table(results))
    print()
    print(split_table(results))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    if args.figure:
        figure(args.files[0], args.figure)
    return 0


if __name__ == "__main__":
    sys.exit(run_main("python -m mpu9250_ahrs.sim.scenarios.benchmark", main))
