"""Verilator builds: the run-time library's objects are compiled once and taken from the
cache by every build that compiles them the same way (``sim.bench.verilator._Runtime``), here on a
stand-in makefile (no compiler run)."""

from mpu9250_ahrs.sim.bench import verilator
from tests.conftest import require_tool

MAKEFILE = """default: verilated.o design.o
verilated.o:
\tg++ {flags} -c -o verilated.o /usr/share/verilator/include/verilated.cpp
design.o:
\tg++ {flags} -c -o design.o Vtop.cpp
"""


def _build_folder(path, flags):
    path.mkdir()
    (path / "Vtop.mk").write_text(MAKEFILE.format(flags=flags))
    return path, ["make", "-s", "-C", str(path), "-f", "Vtop.mk"]


def test_runtime_objects_are_shared_by_builds_that_compile_them_alike(tmp_path, monkeypatch):
    require_tool("verilator", "apt-get install verilator")     # its version is in the key
    require_tool("make", "apt-get install make")
    monkeypatch.setenv("MPU9250_AHRS_CACHE", str(tmp_path / "cache"))
    first, make = _build_folder(tmp_path / "first", "-O1")
    runtime = verilator._Runtime(first, make)
    assert runtime.names == ["verilated.o"] and not runtime.cached     # not the design's
    (first / "verilated.o").write_text("built once")
    runtime.keep()

    second, make = _build_folder(tmp_path / "second", "-O1")
    assert verilator._Runtime(second, make).cached
    assert (second / "verilated.o").read_text() == "built once"
    # copied after the makefile was written: make takes it as built
    assert (second / "verilated.o").stat().st_mtime_ns >= (second / "Vtop.mk").stat().st_mtime_ns

    other, make = _build_folder(tmp_path / "other", "-O2")       # compiled otherwise
    assert not verilator._Runtime(other, make).cached
    assert not (other / "verilated.o").exists()
