"""The twin's comparison (issue #57), a benchmark, not a test: the largest push each loop
recovers from (a binary search on the force of one 100 ms push, 1 s into a 3 s run; the host
loop at ``--host-latency-ms``), the host loop's largest latency at which it still balances
(5 s, no push, at each of ``--latencies``), and the negative control's fall.

    python -m mpu9250_ahrs.sim.scenarios.twin_benchmark [--loops model,chip,host]
        [--steps 6] [--latencies 1,2,4,8,16]

prints one JSON line per search, then a summary line. The chip and host loops take about a
minute a run.
"""

import argparse
import json
import sys
import time

from .twin import Push, run_twin


__all__ = ["largest_push", "main"]


def largest_push(loop, *, low=0.5, high=40.0, steps=6, seconds=3.0, at_s=1.0,
                 host_latency_ms=1.0):
    """The largest force (N, within ``high``/2^steps) of a push at ``at_s`` the ``loop``
    recovers from (upright to the end, back within 2° in time): (force, runs)."""
    runs = []

    def holds(force):
        summary = run_twin(seconds, loop=loop, pushes=[Push(force, at_s)],
                           host_latency_ms=host_latency_ms)
        runs.append({"newtons": force, **summary})
        return summary["upright"] and summary["pushes_recovered"] == 1

    if not holds(low):
        return 0.0, runs
    for _ in range(steps):
        middle = (low + high) / 2
        low, high = (middle, high) if holds(middle) else (low, middle)
    return round(low, 2), runs


def largest_latency(latencies, seconds=5.0):
    """The largest of ``latencies`` (ms) at which the host loop stays upright for ``seconds``
    (None if none), and the runs."""
    runs, best = [], None
    for latency in latencies:
        summary = run_twin(seconds, loop="host", host_latency_ms=latency)
        runs.append({"latency_ms": latency, **summary})
        if summary["upright"]:
            best = latency
    return best, runs


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--loops", default="model,chip,host")
    parser.add_argument("--steps", type=int, default=6)
    parser.add_argument("--host-latency-ms", type=float, default=1.0)
    parser.add_argument("--latencies", default="1,2,4,8,16")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    out = {"off_fell_at_s": run_twin(5, loop="off")["fell_at_s"]}
    for loop in args.loops.split(","):
        force, runs = largest_push(loop, steps=args.steps,
                                   host_latency_ms=args.host_latency_ms)
        out[f"{loop}_largest_push_n"] = force
        print(json.dumps({"loop": loop, "largest_push_n": force, "runs": runs}), flush=True)
    if args.latencies:
        latency, runs = largest_latency([float(x) for x in args.latencies.split(",")])
        out["host_largest_latency_ms"] = latency
        print(json.dumps({"loop": "host", "largest_latency_ms": latency, "runs": runs}),
              flush=True)
    out["wall_s"] = round(time.perf_counter() - start, 1)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
