"""Export: plain Verilog of the core (compiled by Icarus, linted by Verilator) and the Quartus
project written by ``build``. Needs the system tools iverilog and verilator
(Debian: ``apt-get install iverilog verilator``)."""

import json
import re
import subprocess

import pytest
from amaranth.back import verilog

from mpu9250_ahrs.cli import main
from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
from mpu9250_ahrs.hdl.board.top import AHRSCore
from tests.conftest import require_tool


@pytest.fixture(scope="module", params=["spi", "i2c"])
def core_verilog(request, tmp_path_factory):
    path = tmp_path_factory.mktemp("verilog") / "mpu9250_ahrs_core.v"
    core = AHRSCore(clk_freq=12e6, config=MPU9250Config(wiring=request.param))
    path.write_text(verilog.convert(core, name="mpu9250_ahrs_core"))
    return path


def test_core_compiles_in_icarus(core_verilog, tmp_path):
    iverilog = require_tool("iverilog", "apt-get install iverilog")
    # -g2005: under -g2012 Amaranth's initialised-at-declaration always blocks never fire.
    result = subprocess.run([iverilog, "-g2005", "-o", str(tmp_path / "core.vvp"),
                             "-s", "mpu9250_ahrs_core", str(core_verilog)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr


def test_core_lints_in_verilator(core_verilog):
    verilator = require_tool("verilator", "apt-get install verilator")
    # Amaranth's output trips WIDTH/CASEINCOMPLETE style warnings: show them, fail on errors.
    result = subprocess.run([verilator, "--lint-only", "-Wno-fatal", "-Wall",
                             "--top-module", "mpu9250_ahrs_core", str(core_verilog)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert "%Error" not in result.stderr


def test_build_writes_quartus_project(tmp_path, capsys):
    assert main(["build", "--out", str(tmp_path)]) == 0
    for name in ("top.v", "top.qsf", "top.sdc", "build_top.sh"):
        assert (tmp_path / name).is_file(), name
    qsf = (tmp_path / "top.qsf").read_text()
    assert "set_global_assignment -name DEVICE 10M08SCU169C8G" in qsf
    assert 'set_location_assignment -to "clk12_0__io" PIN_H6' in qsf
    assert 'set_location_assignment -to "imu_spi_0__clk__io" PIN_M1' in qsf
    assert "3.3-V LVTTL" in qsf
    assert "arm_0__io" not in qsf           # the arming pin: --controller balance builds only
    sdc = (tmp_path / "top.sdc").read_text()
    assert "create_clock" in sdc and "83.33" in sdc           # the 12 MHz oscillator
    assert "derive_pll_clocks" in sdc                          # its PLL's 48 MHz output
    # issue #23: the SPI pins constrained from the I/O budget (CIPO's round trip 111 ns
    # outside the FPGA's input, sampled 6 cycles = 125 ns on), their registers in the I/O
    assert "set_input_delay -clock [get_clocks {*pll1|clk[0]}] -max 111 " \
           "[get_ports {imu_spi_0__cipo__io}]" in sdc
    assert "set_multicycle_path -setup -from [get_ports {imu_spi_0__cipo__io}] 6" in sdc
    assert "set_output_delay" in sdc and "imu_spi_0__clk__io" in sdc
    assert "FAST_INPUT_REGISTER ON -to imu_spi_0__cipo__io" in qsf
    assert "FAST_OUTPUT_REGISTER ON -to imu_spi_0__clk__io" in qsf
    top = (tmp_path / "top.v").read_text()
    assert "altpll" in top and ".clk0_multiply_by(32'd4)" in top
    out, err = capsys.readouterr()
    assert "system clock 48 MHz" in out and "warning" not in err


def test_build_above_the_checked_clock_says_where_timing_is_checked(tmp_path, capsys):
    """--clk-freq 200e6 wrote a project without a word: the core is checked at 48 MHz."""
    assert main(["build", "--out", str(tmp_path), "--clk-freq", "96e6"]) == 0
    err = capsys.readouterr().err
    assert "warning: the core's timing is checked at 48 MHz; at 96 MHz only Quartus's" in err


def test_build_without_pll_at_the_oscillator_clock(tmp_path):
    assert main(["build", "--out", str(tmp_path), "--clk-freq", "12e6"]) == 0
    assert "altpll" not in (tmp_path / "top.v").read_text()


def test_build_refuses_a_rate_the_design_cannot_filter(tmp_path, capsys):
    """I2C at 400 kHz reads a nine-axis sample in about 0.67 ms: 8 kHz is refused, with the
    reason in one line; 1 kHz with a slow UART is built, with a warning."""
    assert main(["build", "--out", str(tmp_path), "--wiring", "i2c", "--odr", "8000"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "8000 Hz is more than this design filters" in err[0]
    assert main(["build", "--verilog-only", "--out", str(tmp_path), "--baud", "115200"]) == 0
    err = capsys.readouterr().err
    assert "warning: telemetry sends one result in 8 " in err


def test_build_i2c_wiring(tmp_path):
    assert main(["build", "--out", str(tmp_path), "--wiring", "i2c", "--i2c-address", "0x69"]) == 0
    qsf = (tmp_path / "top.qsf").read_text()
    assert 'set_location_assignment -to "imu_i2c_0__scl__io" PIN_M1' in qsf
    assert 'set_location_assignment -to "imu_i2c_0__sda__io" PIN_L3' in qsf


def test_the_controller_build_has_its_arming_pin():
    """Issue #57: a robot runs with no host: the arming input is a pin of the board (Arduino
    D2 on the MAX10 board; on the ULX3S GP11, pulled down so an open header never arms). The
    default build has none (``test_build_writes_quartus_project``)."""
    from mpu9250_ahrs.hdl.board.platform import MAX10Platform
    from mpu9250_ahrs.hdl.board.top import BoardTop
    from mpu9250_ahrs.hdl.board.ulx3s import ULX3SPlatform
    qsf = MAX10Platform().build(BoardTop(clk_freq=48e6, controller="balance"), name="top",
                                do_build=False).files["top.qsf"]
    assert 'set_location_assignment -to "arm_0__io" PIN_H5' in qsf
    assert 'set_location_assignment -to "pwm_0__io" PIN_H4' in qsf
    lpf = ULX3SPlatform().build(BoardTop(clk_freq=48e6, controller="balance"), name="top",
                                do_build=False).files["top.lpf"]
    assert 'IOBUF PORT "arm_0__io" IO_TYPE=LVCMOS33 PULLMODE=DOWN;' in lpf


def test_build_pin_override(tmp_path):
    assert main(["build", "--out", str(tmp_path), "--pin", "imu_sclk=J1"]) == 0
    assert 'set_location_assignment -to "imu_spi_0__clk__io" PIN_J1' in \
        (tmp_path / "top.qsf").read_text()


def test_build_unknown_pin_is_a_clear_error(tmp_path, capsys):
    assert main(["build", "--out", str(tmp_path), "--pin", "imu_sck=J1"]) == 2
    assert "unknown pin names ['imu_sck']" in capsys.readouterr().err


def test_build_verilog_only(tmp_path):
    assert main(["build", "--verilog-only", "--out", str(tmp_path)]) == 0
    text = (tmp_path / "mpu9250_ahrs_core.v").read_text()
    assert "module mpu9250_ahrs_core" in text


def test_simulate_command(tmp_path, capsys):
    vcd = tmp_path / "x.vcd"
    assert main(["simulate", "--samples", "3", "--vcd", str(vcd)]) == 0     # self-tests too
    lines = capsys.readouterr().out.strip().splitlines()
    samples = [json.loads(line) for line in lines[:3]]
    assert [s["counter"] for s in samples] == [0, 1, 2]
    summary = json.loads(lines[3])
    assert summary["violations"] == [] and summary["status"]["streaming"] == 1
    assert summary["status"]["mag_ok"] == 1 and summary["sample_read_us"] > 0
    assert summary["bring_up_cycles"] > 0 and summary["cycles_per_s"] > 0
    assert summary["self_test"] == {"done": 1, "mag_done": 1, "fail": 0}
    assert summary["who_am_i"] == 0x71
    # the model's part (100 ns) trains (issue #58)
    assert summary["spi_training"]["trained"] == 1 and summary["spi_training"]["fallbacks"] == 0
    assert vcd.stat().st_size > 0 and (tmp_path / "x.gtkw").is_file()
    from mpu9250_ahrs.sim.bench.compiled_design import verilator_available
    # waveforms from the compiled path too (a build that traces); the save file's traces
    # are in the VCD (a traced run equals an untraced one: the slow step,
    # tests/sim/test_compiled_bench.py)
    assert summary["simulator"] == ("compiled (Verilator)" if verilator_available()
                                    else "python (Amaranth)")
    text = vcd.read_text()
    header = text[:text.index("$enddefinitions")]
    gtkw = (tmp_path / "x.gtkw").read_text()
    # each trace of the save file is a variable of the VCD: its name after its scope (a
    # field's name, 'status.mag_ok', written '\\status.mag_ok' as GTKWave reads it)
    traced = re.findall(r"^\+\{[^}]*\} [\w.]+\.\\?([\w.]+?)(?:\[[\d:]+\])?$", gtkw, re.M)
    assert len(traced) > 10 and all(
        re.search(rf"\$var \w+ +\d+ \S+ {re.escape(t)}(?: \[[\d:]+\])? \$end", header)
        for t in traced), traced
    # and GTKWave itself opens it with the save file: no parse error, every trace found
    from mpu9250_ahrs.sim.bench.waveforms import GTKWAVE_HINT, gtkwave_check
    require_tool("gtkwave", GTKWAVE_HINT)
    require_tool("xvfb-run", GTKWAVE_HINT)
    opened = gtkwave_check(vcd, tmp_path / "x.gtkw")
    assert opened["errors"] == [] and opened["facs"] > 1000, opened
    assert {"cs_n", "sclk", "cipo", "streaming", "mag_ok"} <= set(opened["traces"]), opened
    # it opens on the first sensor transaction (chip select low to high) at a readable scale:
    # from [timestart], 2**-zoom time units per 200 pixels of a 1000-pixel wave area
    from mpu9250_ahrs.sim.bench.waveforms import GTKW_WIDTH_PX
    start = int(re.search(r"^\[timestart\] (\d+)$", gtkw, re.M).group(1))
    zoom = float(re.search(r"^\*(-?[\d.]+) ", gtkw, re.M).group(1))
    end = start + 2 ** -zoom * GTKW_WIDTH_PX / 200
    unit = {"1ps": 1e-12, "1 fs": 1e-15}[re.search(r"\$timescale\s*(.*?)\s*\$end",
                                                  header).group(1)]
    cs = re.search(r"\$var \w+ +1 (\S+) (?:pin_a|pins__cs_n) \$end", header).group(1)
    body = text[len(header):]
    edges = [m.start() for m in re.finditer(rf"^[01]{re.escape(cs)}$", body, re.M)][1:3]
    fall, rise = (int(re.findall(r"^#(\d+)$", body[:at], re.M)[-1]) for at in edges)
    assert start < fall < rise < end and (end - start) * unit < 100e-6


def test_simulate_i2c_wiring(capsys):
    assert main(["simulate", "--samples", "2", "--wiring", "i2c", "--no-self-test"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["wiring"] == "i2c" and summary["violations"] == []
    assert summary["status"]["mag_ok"] == 1
    from mpu9250_ahrs.sim.bench.compiled_design import verilator_available
    assert summary["simulator"] == ("compiled (Verilator)" if verilator_available()
                                    else "python (Amaranth)")


class _Stop(Exception):
    pass


@pytest.mark.parametrize("wiring,clk_freq,smplrt_div,scale", [
    ("spi", 48e6, 0, 0.2), ("spi", 12e6, 0, 0.2), ("i2c", 48e6, 0, 1.0), ("i2c", 48e6, 9, 0.2),
    ("spi", 1e6, 0, 1.0), ("spi", 1e6, 9, 0.2)])
def test_simulated_period_is_shortened_only_where_the_design_keeps_up(
        wiring, clk_freq, smplrt_div, scale, monkeypatch):
    """``simulate`` shortens the sample period (0.2) only where the shortened period still
    holds twice the cycles a sample needs; else it runs in real time: at 1 MHz a sample's
    read (772 us) is longer than a fifth of 1 ms, and the shortened period lost 9 samples in
    14 that the design reads at the real rate."""
    from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
    from mpu9250_ahrs.hdl.board.top import rate_budget
    from mpu9250_ahrs.sim.scenarios import frontend
    from mpu9250_ahrs.sim.scenarios.setup import SimSetup
    config = MPU9250Config(wiring=wiring, smplrt_div=smplrt_div)
    assert SimSetup.default_odr_scale(config, clk_freq) == scale
    period = 0.2 * clk_freq / config.output_data_rate
    assert (period >= 2 * rate_budget(config, clk_freq)["cycles_per_sample"]) == (scale == 0.2)
    seen = {}

    def run_frontend(setup, **kwargs):
        seen["scale"] = setup.odr_scale
        raise _Stop
    monkeypatch.setattr(frontend, "run_frontend", run_frontend)
    with pytest.raises(_Stop):
        main(["simulate", "--samples", "1", "--clk-freq", str(clk_freq), "--wiring", wiring,
              "--smplrt-div", str(smplrt_div), "--baud", "9600"])
    assert seen["scale"] == scale


@pytest.mark.parametrize("option,left_out", [("--no-pwm", {"pwm": False}),
                                             ("--no-commands", {"commands": False})])
def test_simulate_leaves_out_what_build_does(option, left_out, monkeypatch):
    """``simulate --attitude`` takes ``build``'s --no-pwm and --no-commands: the core it
    simulates is the one built (such cores run in tests/hdl/test_top_options.py)."""
    from mpu9250_ahrs.sim.scenarios import core
    seen = {}

    def run_core(setup, **kwargs):
        seen.update(kwargs["core_kwargs"])
        raise _Stop
    monkeypatch.setattr(core, "run_core", run_core)
    with pytest.raises(_Stop):
        main(["simulate", "--samples", "1", "--attitude", "--no-self-test", option])
    assert {k: seen.get(k) for k in left_out} == left_out


def test_help_lists_verbs(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    assert "build" in out and "simulate" in out


def test_verilog_only_writes_an_instance_of_every_port(tmp_path):
    """Issue #56: ``build --verilog-only`` writes an instantiation template beside the core,
    every port of its top module once, with its direction; the attitude stream's fields as
    build/README.md lists them."""
    import pathlib
    import re
    from mpu9250_ahrs.flows.instantiation import payload_fields
    from mpu9250_ahrs.hdl.engine.attitude_result import Attitude
    from mpu9250_ahrs.hdl.sensor.sample import Sample
    assert main(["build", "--verilog-only", "--attitude-port", "--out", str(tmp_path)]) == 0
    verilog = (tmp_path / "mpu9250_ahrs_core.v").read_text()
    template = (tmp_path / "mpu9250_ahrs_core_inst.v").read_text()
    top = re.search(r"^module mpu9250_ahrs_core\b.*?^endmodule", verilog, re.M | re.S).group(0)
    ports = re.findall(r"^\s*(input|output)\s+(?:\[[^\]]+\]\s+)?(\w+)\s*;", top, re.M)
    assert ports and len(re.findall(r"^    \.", template, re.M)) == len(ports)
    for direction, name in ports:
        assert re.search(rf"^    \.{name}\({name}\)[, ]\s*// {direction}\b", template, re.M), name
    assert ".attitude__payload(" in template and "[361:0]" in template
    readme = (pathlib.Path(__file__).resolve().parents[1] / "build" / "README.md").read_text()
    assert all(line in readme for line in payload_fields(Attitude) + payload_fields(Sample))
    assert ".sample__payload(" in template and "[202:0]" in template
