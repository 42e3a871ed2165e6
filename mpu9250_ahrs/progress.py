"""Progress on stderr for the jobs that take more than a few seconds (``tqdm``).

Bars are shown only when stderr is a terminal and ``--quiet`` was not given (``set_quiet``),
so logs, pipes and tests see the same output as before. ``bar(total, desc, unit)`` gives a
tqdm bar, or an object with the same methods that does nothing; ``steps(names, desc)`` a bar
over named steps (``next(name)`` moves it on) whose elapsed time moves while a step runs, and
off a terminal (unless quiet) one line on stderr per step and a line a minute within one: the
synthesis and place-and-route steps it is used for take minutes. The simulators take any
object with ``update(n)`` and ``set_postfix_str(text)``.
"""

import sys
import threading
import time


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
    """A job's named steps. On a terminal a bar whose elapsed time moves every second while
    a step runs (synthesis and place-and-route steps take minutes, and a bar redrawn only
    when a step ends looked hung); off a terminal (unless quiet) a line on stderr as each step
    begins, with the time since the job began, and every ``HEARTBEAT_S`` within a step."""
    HEARTBEAT_S = 60.0

    def __init__(self, names, desc):
        self.total, self.desc = len(names), desc
        self.bar = bar(self.total, desc, "step")
        self.lines = not enabled() and not _quiet
        self.count = 0                  # steps begun
        self.name = ""
        self.t0 = self.step_t0 = self.last_line = time.monotonic()
        self._stop = threading.Event()
        self._thread = None
        if not isinstance(self.bar, NullBar) or self.lines:
            self._thread = threading.Thread(target=self._tick, daemon=True)
            self._thread.start()

    def _elapsed(self, since):
        seconds = int(time.monotonic() - since)
        return f"{seconds // 60}:{seconds % 60:02d}"

    def _tick(self):
        if not self.lines:
            while not self._stop.wait(1.0):
                self.bar.refresh()
            return
        # a line once a step or the last line is ``HEARTBEAT_S`` old
        while not self._stop.wait(min(1.0, self.HEARTBEAT_S)):
            if self.count and time.monotonic() - self.last_line >= self.HEARTBEAT_S:
                self.last_line = time.monotonic()
                print(f"{self.desc}: {self.name}: still running, "
                      f"{self._elapsed(self.step_t0)} in this step", file=sys.stderr,
                      flush=True)

    def next(self, name):
        if self.count:
            self.bar.update(1)
        self.count += 1
        self.name = name
        self.step_t0 = self.last_line = time.monotonic()
        self.bar.set_postfix_str(name)
        if self.lines:
            # a job may name sub-steps of its few (the ECP5 build's): no count for those
            label = f"step {self.count}/{self.total}: " if self.count <= self.total else ""
            print(f"{self.desc}: {label}{name} ({self._elapsed(self.t0)} since start)",
                  file=sys.stderr, flush=True)

    def close(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.bar.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def steps(names, desc):
    """A bar over the named steps of a job; ``next(name)`` as each begins."""
    return _Steps(list(names), desc)
