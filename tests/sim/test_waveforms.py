"""The co-simulations' waveforms (``sim/bench/waveforms.py``): window bounds, the VCD cut, the names
GTKWave refuses renamed before tracing; then, in the slow step, every kind of waveform the
project writes opened in GTKWave itself under Xvfb (its VCD reader is stricter than
``vcd2fst``'s, which took the files GTKWave refused)."""

import os

import pytest

from mpu9250_ahrs.sim.bench.compiled_design import readable_names
from mpu9250_ahrs.sim.bench.waveforms import (GTKWAVE_HINT, RunTrace, TraceWindow, Waveform,
    crop_vcd, gtkwave_check, parse_bound)
from tests.conftest import require_tool


def test_bounds():
    assert parse_bound("5") == ("samples", 5)
    assert parse_bound("0") == ("samples", 0)
    assert parse_bound("2ms") == ("s", pytest.approx(2e-3))
    assert parse_bound("150us") == ("s", pytest.approx(150e-6))
    assert parse_bound("0.01s") == ("s", pytest.approx(0.01))
    assert parse_bound("1.5e2 ns") == ("s", pytest.approx(150e-9))
    for bad in ("", "-1", "2 m", "x", "5.5", "inf s", "ms", "3 samples"):
        with pytest.raises(ValueError, match="--trace-to: .* neither a count of samples"):
            parse_bound(bad, "--trace-to")


def test_waveform_file_and_window_are_checked():
    assert Waveform("a/b.vcd").format == "vcd" and Waveform("b.FST").format == "fst"
    assert Waveform("a/b.vcd").gtkw == "a/b.gtkw"
    with pytest.raises(ValueError, match="ends in .vcd or .fst"):
        Waveform("out/x.txt")
    with pytest.raises(ValueError, match="ends .* where or before it starts"):
        Waveform("x.vcd", ("samples", 5), ("samples", 5))
    # a window in time is in cycles from the start; in samples, met during the run
    window = TraceWindow(Waveform("x.vcd", ("s", 1e-3), ("samples", 4)), 48e6)
    assert window.cycles() == (48_000, TraceWindow.NEVER)
    moved = []
    window.on_change = lambda *c: moved.append(c)
    window.at_sample(3, 70_000)
    window.at_sample(4, 80_000)
    assert window.cycles() == (48_000, 80_000) and moved == [(48_000, 80_000)]


def test_a_window_the_run_never_reached_is_an_error_and_no_file(tmp_path):
    wave = Waveform(str(tmp_path / "w.vcd"), ("samples", 9))
    (tmp_path / "w.vcd").write_text("$enddefinitions $end\n")
    trace = RunTrace(wave, 48e6, "frontend", "spi", [])
    with pytest.raises(ValueError, match=r"nothing traced: the run ended \(1.000 ms, 3 "
                                         r"samples\) before the waveform's window started "
                                         r"\(9 samples\)"):
        trace.finish(None, None, 48_000, 3)
    assert not (tmp_path / "w.vcd").exists()


def test_crop_keeps_the_state_at_the_start_and_the_changes_inside(tmp_path):
    source, target = tmp_path / "a.vcd", tmp_path / "b.vcd"
    source.write_text("$timescale 1 ps $end\n$var wire 1 ! a $end\n$var wire 4 \" b $end\n"
                      "$enddefinitions $end\n#0\n$dumpvars\n0!\nb0 \"\n$end\n#10\n1!\n"
                      "#20\nb101 \"\n#30\n0!\n#40\nb1 \"\n#50\n1!\n")
    crop_vcd(source, target, 25, 40)
    body = target.read_text().split("$enddefinitions $end\n", 1)[1]
    assert body == "#25\n$dumpvars\n1!\nb101 \"\n$end\n#30\n0!\n#40\nb1 \"\n"


def test_generated_names_renamed_out_of_the_trace():
    text = ("  reg \\$auto$verilog_backend.cc:2355:dump_module$1  = 0;\n"
            "    if (\\$auto$verilog_backend.cc:2355:dump_module$1 ) begin end\n"
            "  reg \\$auto$verilog_backend.cc:2355:dump_module$2  = 0;\n"
            "  wire \\status.mag_ok ;\n")
    out = readable_names(text)
    assert "$auto" not in out and "\\status.mag_ok " in out
    # one name for each, the same at each use; a leading underscore: Verilator leaves it out
    assert out.count("_auto_1 ") == 2 and out.count("_auto_2 ") == 1


def _gtkwave():
    require_tool("gtkwave", GTKWAVE_HINT)
    require_tool("xvfb-run", GTKWAVE_HINT)


STATUS = {"streaming", "mag_ok", "bad_burst", "rate_error"}


def _opens(wave, pins, block):
    """The waveform opens in GTKWave with its save file: no parse error, the bus pins, the
    block's signals and the named status flags shown, the view inside the file."""
    opened = gtkwave_check(wave.path, wave.gtkw)
    assert opened["returncode"] == 0 and opened["errors"] == [], opened
    assert set(pins) | set(block) | STATUS <= set(opened["traces"]), opened
    return opened


@pytest.mark.slow
@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
@pytest.mark.parametrize("wiring", ["spi", "i2c"])
def test_front_end_waveforms_open_in_gtkwave(tmp_path, compiled, wiring):
    """Both simulators, both wirings: a VCD of the front end opens in GTKWave, the window of
    the save file on a sensor transaction."""
    from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
    from mpu9250_ahrs.sim.scenarios.setup import SimSetup
    from mpu9250_ahrs.sim.scenarios.frontend import run_frontend
    from mpu9250_ahrs.sim.bench.compiled_design import verilator_available
    _gtkwave()
    if compiled and not verilator_available():
        require_tool("verilator", "apt-get install verilator g++ make")
    setup = SimSetup(clk_freq=12e6, config=MPU9250Config(wiring=wiring))
    wave = Waveform(str(tmp_path / "fe.vcd"))
    run = run_frontend(setup, n_samples=2, vcd=wave, compiled=compiled)
    assert run.compiled == compiled
    pins = ("cs_n", "sclk", "copi", "cipo") if wiring == "spi" else ("scl", "sda", "scl_oe")
    opened = _opens(wave, pins, ("int",))
    first = (run.model.transactions if wiring == "spi" else run.bus.frames)[0]
    unit = 1e-12 if compiled else 1e-15
    start, end = (t * unit for t in opened["window"])
    assert start <= first[0] < first[1] <= end + 1e-6, (opened["window"], first)


@pytest.mark.slow
@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_core_waveform_in_a_window_as_fst(tmp_path, compiled):
    """The whole core, FST (Verilator's own writer; Amaranth's VCD through vcd2fst), traced
    from the 2nd sample out to the 3rd: it opens in GTKWave, holds only that window, and
    shows the read of the 3rd sample."""
    from mpu9250_ahrs.sim.scenarios.setup import quick_core_setup
    from mpu9250_ahrs.sim.scenarios.core import run_core
    _gtkwave()
    wave = Waveform(str(tmp_path / "core.fst"), ("samples", 2), ("samples", 3))
    run = run_core(quick_core_setup(), n_results=4, vcd=wave, compiled=compiled)
    assert run.compiled == compiled
    opened = _opens(wave, ("cs_n", "sclk", "cipo"), ("uart_tx", "int"))
    unit = 1e-12 if compiled else 1e-15
    start, end = (t * unit for t in opened["window"])
    # the sample leaves the driver just before its read's chip select rises: 1 us allowed
    reads = [t for t in run.model.transactions if start <= t[0] and t[1] <= end + 1e-6]
    assert reads, (opened["window"], run.model.transactions[-4:])


@pytest.mark.slow
def test_fst_of_twenty_samples_is_small_and_a_window_smaller(tmp_path):
    """simulate's bring-up + 20 samples as FST: at most a tenth of the 126 MB its VCD was;
    with --trace-from 18 only the last samples, smaller again."""
    from mpu9250_ahrs.cli import main
    _gtkwave()
    fst, win = tmp_path / "sim.fst", tmp_path / "win.fst"
    assert main(["simulate", "--samples", "20", "--vcd", str(fst), "--quiet"]) == 0
    assert main(["simulate", "--samples", "20", "--vcd", str(win), "--trace-from", "18",
                 "--quiet"]) == 0
    assert os.path.getsize(fst) < 12.6e6 and os.path.getsize(win) < os.path.getsize(fst) / 4
    for path in (fst, win):
        _opens(Waveform(str(path)), ("cs_n", "sclk"), ("int",))
