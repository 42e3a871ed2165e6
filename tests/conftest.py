import os
import re
import shutil

import pytest


def pytest_addoption(parser):
    parser.addoption(
        "--vcd-dir", default=os.environ.get("MPU9250_AHRS_VCD_DIR"),
        help="write a VCD and a GTKWave save file for each co-simulation test into this folder "
             "(also: environment variable MPU9250_AHRS_VCD_DIR); off by default")


@pytest.fixture
def vcd(request):
    """``vcd(tag="")`` -> a VCD path for this test, or None when waveforms are off."""
    folder = request.config.getoption("--vcd-dir")

    def path(tag=""):
        if not folder:
            return None
        os.makedirs(folder, exist_ok=True)
        name = re.sub(r"[^A-Za-z0-9_.-]+", "_", request.node.name) + tag
        return os.path.join(folder, name + ".vcd")
    return path


def broad_files():
    """The shared BROAD recordings (``../shared/data/broad/*.hdf5`` beside the checkout, or
    from the working folder), sorted; [] where they are not there."""
    import glob
    import pathlib
    return sorted(glob.glob("../shared/data/broad/*.hdf5")) or sorted(glob.glob(
        str(pathlib.Path(__file__).resolve().parents[2] / "shared/data/broad/*.hdf5")))


def require_tool(name, install):
    """Path of a system tool. Missing: a skip on a developer machine, a failure in CI."""
    found = shutil.which(name)
    if found:
        return found
    message = f"{name} is not installed; install it with: {install}"
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)


def pytest_terminal_summary(terminalreporter):
    """The formal checks' method, depth and solver time (``formal`` fixture, tests/formal)."""
    lines = []
    stats = terminalreporter.stats
    for report in stats.get("passed", []) + stats.get("failed", []):
        if report.when != "call":
            continue
        lines += [value for key, value in report.user_properties if key == "formal"]
    if lines:
        terminalreporter.section("formal checks")
        for line in sorted(lines):
            terminalreporter.write_line(line)
