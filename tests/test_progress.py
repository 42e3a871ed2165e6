"""Progress on long jobs (issue #29): bars on stderr only on a terminal and without --quiet;
pipes, logs and tests see the output they saw before."""

import fcntl
import os
import struct
import subprocess
import sys
import termios

from mpu9250_ahrs import progress


def test_no_bar_off_a_terminal_or_when_quiet(monkeypatch):
    class Tty:
        def isatty(self):
            return True

        def write(self, text):
            pass

        def flush(self):
            pass

    assert isinstance(progress.bar(10, "x"), progress.NullBar)        # pytest's stderr
    monkeypatch.setattr(sys, "stderr", Tty())
    assert progress.enabled()
    progress.set_quiet(True)
    try:
        assert not progress.enabled()
        assert isinstance(progress.bar(10, "x"), progress.NullBar)
    finally:
        progress.set_quiet(False)
    with progress.steps(["a", "b"], "job") as shown:          # a real tqdm bar on the "tty"
        shown.next("a")
        shown.next("b")


def _run_in_a_terminal(argv):
    """stdout and stderr of ``argv`` with stderr on a pseudo-terminal."""
    master, slave = os.openpty()
    # a terminal's size, as a real one has (tqdm draws nothing on a terminal of 0 rows)
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=slave, text=True)
    os.close(slave)
    err = bytearray()
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:
            break
        if not chunk:
            break
        err += chunk
    out = proc.stdout.read()
    proc.wait()
    os.close(master)
    return proc.returncode, out, err.decode(errors="replace")


def test_a_long_job_shows_progress_on_a_terminal_only():
    argv = [sys.executable, "-m", "mpu9250_ahrs.host.protocol", "1000"]
    code, out, err = _run_in_a_terminal(argv)
    assert code == 0 and "corrupted frames" in err and "%" in err
    assert out.count('"case"') == 5                            # the results, unchanged
    piped = subprocess.run(argv, capture_output=True, text=True)
    assert piped.returncode == 0 and piped.stderr == "" and piped.stdout == out


def test_steps_off_a_terminal_say_each_step_on_stderr(capsys):
    """Off a terminal a job's steps (report's syntheses, the ECP5 place-and-route) are lines
    on stderr with the time since the job began, so a piped or logged run shows it moves;
    quiet, nothing."""
    with progress.steps(["a", "b"], "job") as shown:
        shown.next("first")
        shown.next("second")
        shown.next("a sub-step")
    assert capsys.readouterr().err.splitlines() == [
        "job: step 1/2: first (0:00 since start)", "job: step 2/2: second (0:00 since start)",
        "job: a sub-step (0:00 since start)"]
    progress.set_quiet(True)
    try:
        with progress.steps(["a"], "job") as shown:
            shown.next("first")
    finally:
        progress.set_quiet(False)
    assert capsys.readouterr().err == ""
