"""``board`` (issue #29): the simulated board kept running on a pseudo-terminal, used by host
verbs in other processes exactly as a real port: a configuration made by one command is seen
by the next (configure, then watch)."""

import csv
import json
import signal
import subprocess
import sys

from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_CODES


def _cli(*argv, timeout=120):
    return subprocess.run([sys.executable, "-m", "mpu9250_ahrs", *argv], capture_output=True,
                          text=True, timeout=timeout)


def test_config_then_monitor_against_one_board(tmp_path):
    # Ctrl-C as in a terminal: a process started by one that ignores SIGINT (a script's
    # background job, a CI runner) inherits that, and Python then keeps ignoring it (the
    # board ran on, and the test hung in communicate)
    board = subprocess.Popen([sys.executable, "-m", "mpu9250_ahrs", "board", "--seconds", "300"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        line = board.stdout.readline()
        assert line.startswith("simulated board on /dev/"), line
        port = line.split()[-1]
        done = _cli("config", port, "--timeout", "60", "filter", "complementary")
        assert done.returncode == 0, done.stderr
        assert json.loads(done.stdout) == {"filter": "complementary"}
        log = tmp_path / "log.csv"
        watched = _cli("monitor", port, "--timeout", "60", "--frames", "3", "--csv", str(log))
        assert watched.returncode == 0, watched.stderr
        assert json.loads(watched.stdout)["frames"] == 3
        rows = list(csv.DictReader(log.open()))
        attitude = [r for r in rows if r["type"] == "2"]
        assert attitude and {int(r["attitude.flags.filter"]) for r in attitude} == \
            {FILTER_CODES["complementary"]}
    finally:
        board.send_signal(signal.SIGINT)                  # Ctrl-C: stops cleanly
        _, err = board.communicate(timeout=60)
    assert board.returncode == 0, err
    assert "simulated board stopped after" in err
