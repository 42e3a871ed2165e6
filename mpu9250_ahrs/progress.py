"""Progress on stderr for the jobs that take more than a few seconds (``tqdm``).

Shown only when stderr is a terminal and ``--quiet`` was not given (``set_quiet``), so logs,
pipes and tests see the same output as before. ``bar(total, desc, unit)`` gives a tqdm bar, or
an object with the same methods that does nothing; ``steps(names, desc)`` a bar over named
steps (``next(name)`` moves it on). The simulators take any object with ``update(n)`` and
``set_postfix_str(text)``.
"""

import sys


__all__ = ["set_quiet", "enabled", "bar", "steps", "NullBar"]

_quiet = False


def set_quiet(quiet):
    global _quiet
    _quiet = bool(quiet)


def enabled(stream=None):
    stream = sys.stderr if stream is None else stream
    return not _quiet and hasattr(stream, "isatty") and stream.isatty()


class NullBar:
    """A bar that shows nothing (not a terminal, or ``--quiet``)."""
    def update(self, n=1):
        pass

    def set_postfix_str(self, text, refresh=True):
        pass

    def set_description_str(self, text, refresh=True):
        pass

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def bar(total=None, desc="", unit="it"):
    """A progress bar on stderr (``total`` None: a counter)."""
    if not enabled():
        return NullBar()
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr, leave=False,
                dynamic_ncols=True)


class _Steps:
    def __init__(self, names, desc):
        self.bar = bar(len(names), desc, "step")
        self.started = False

    def next(self, name):
        if self.started:
            self.bar.update(1)
        self.started = True
        self.bar.set_postfix_str(name)

    def close(self):
        self.bar.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def steps(names, desc):
    """A bar over the named steps of a job; ``next(name)`` as each begins."""
    return _Steps(list(names), desc)
