"""What the ``python -m`` tools of the package (``reference.soak``, ``host.protocol``,
``sim.scenarios.benchmark``, ``sim.scenarios.faults``, ``sim.scenarios.speed``) share with the command line's verbs: a bad
argument is argparse's one usage line, an error while running one ``PROG: error: ...`` line
(exit 2), Ctrl-C one ``PROG: interrupted`` line (exit 130), never a traceback. Here, where
every folder that has such a tool may import it (``tests/test_imports.py``)."""

import argparse
import math
import sys


__all__ = ["count", "positive", "run_main"]


def count(text):
    """An argparse type: a whole number of at least 1."""
    try:
        value = int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text} is less than 1")
    return value


def positive(text):
    """An argparse type: a finite number above 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text} is not a finite number above 0")
    return value


def run_main(prog, main, argv=None):
    """``main(argv)``'s exit code, with its errors and Ctrl-C as one line on stderr."""
    try:
        return main(argv)
    except (ValueError, OSError, RuntimeError) as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
