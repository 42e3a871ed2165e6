"""The compiled whole-board path (``sim.bench.compiled_bench``) against Amaranth's simulator: the
same stimulus gives the same samples, results, cycles, frames and bus transactions (the pin
trace as the models saw it), on both wirings and for the whole core."""

import pytest

from mpu9250_ahrs.hdl.contract.defaults import DEFAULT_BAUD
from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
from mpu9250_ahrs.sim.bench.compiled_design import verilator_available
from mpu9250_ahrs.sim.scenarios.setup import QUICK_CORE_BAUD, SimSetup, quick_core_setup
from mpu9250_ahrs.sim.scenarios.core import run_core
from mpu9250_ahrs.sim.scenarios.frontend import run_frontend


pytestmark = pytest.mark.skipif(not verilator_available(), reason="needs verilator and g++")


# In the default run at a 12 MHz clock (a quarter of the cycles for the same bring-up and
# samples: both paths together 5 to 6 s rather than 10 to 16), at the board's 48 MHz in the
# slow step
@pytest.mark.parametrize("clk_freq", [12e6, pytest.param(48e6, marks=pytest.mark.slow)],
                         ids=["12MHz", "48MHz"])
@pytest.mark.parametrize("wiring,samples", [("spi", 4), ("i2c", 2)])
def test_front_end_same_on_both_paths(wiring, samples, clk_freq):
    config = MPU9250Config(wiring=wiring)
    setup = SimSetup(clk_freq=clk_freq, config=config,
                     odr_scale=SimSetup.default_odr_scale(config, clk_freq))
    fast = run_frontend(setup, n_samples=samples, compiled=True)
    slow = run_frontend(setup, n_samples=samples, compiled=False)
    assert fast.compiled and not slow.compiled
    assert len(fast.samples) == samples
    for name in ("samples", "sample_cycles", "status_log", "cycles", "bring_up_cycles",
                 "asa", "who_am_i", "self_test", "rate_errors"):
        assert getattr(fast, name) == getattr(slow, name), name
    assert fast.model.transactions == slow.model.transactions
    if wiring == "i2c":
        assert fast.bus.log == slow.bus.log and fast.bus.frames == slow.bus.frames


def test_slow_consumer_same_on_both_paths():
    """A consumer ready one cycle in seven: the compiled path steps a cycle at a time. (At
    48 MHz: its build is the one test_slow_consumer_gets_overrun_flags then takes.)"""
    setup = SimSetup(config=MPU9250Config(magnetometer=False), odr_scale=0.1)
    runs = [run_frontend(setup, n_samples=4, ready=lambda c: c % 7 == 0, compiled=compiled,
                         model=setup.model(magnetometer=False)) for compiled in (True, False)]
    for name in ("samples", "sample_cycles", "status_log", "cycles"):
        assert getattr(runs[0], name) == getattr(runs[1], name), name


def _i2c_core_setup():
    config = MPU9250Config(wiring="i2c")
    return SimSetup(clk_freq=12e6, config=config,
                    odr_scale=SimSetup.default_odr_scale(config, 12e6))


# The whole core on both paths: in the default run on the quick set-up (``quick_core_setup``:
# a 12 MHz clock, a quarter of the cycles: Amaranth's simulator's side takes 8 s rather than
# 27 s), whose build the other core tests and the catalogue's host_garbage then take; at the
# board's 48 MHz, and with the I2C wiring at 12 MHz (a build of its own, 14 s), in the slow
# step
@pytest.mark.parametrize("clock", ["12MHz", pytest.param("48MHz", marks=pytest.mark.slow),
                                   pytest.param("i2c-12MHz", marks=pytest.mark.slow)])
def test_core_same_on_both_paths(clock):
    setup, baud = {"12MHz": lambda: (quick_core_setup(), QUICK_CORE_BAUD),
                   "48MHz": lambda: (SimSetup(), DEFAULT_BAUD),
                   "i2c-12MHz": lambda: (_i2c_core_setup(), QUICK_CORE_BAUD)}[clock]()
    fast = run_core(setup, n_results=2, n_frames=1, compiled=True, baud=baud)
    slow = run_core(setup, n_results=2, n_frames=1, compiled=False, baud=baud)
    assert fast.compiled and not slow.compiled
    assert len(fast.results) >= 2 and len(fast.frames) >= 1
    for name in ("results", "result_cycles", "int_cycles", "frames", "counters", "status",
                 "samples",
                 "asa", "cycles"):
        assert getattr(fast, name) == getattr(slow, name), name
    assert fast.model.transactions == slow.model.transactions
    if setup.config.wiring == "i2c":
        assert fast.bus.log and fast.bus.log == slow.bus.log
        assert fast.bus.frames == slow.bus.frames


def test_compiled_refuses_what_it_cannot_run():
    with pytest.raises(ValueError, match="compiled path does not take"):
        run_frontend(SimSetup(), n_samples=1, stuck_miso=1, compiled=True)


@pytest.mark.slow
def test_waveforms_from_the_compiled_path(tmp_path):
    """A VCD from a traced build, and a GTKWave save file whose every trace is in it; the run
    the same as without the trace."""
    import re
    vcd = tmp_path / "fe.vcd"
    traced = run_frontend(SimSetup(), n_samples=2, vcd=vcd, compiled=True)
    plain = run_frontend(SimSetup(), n_samples=2, compiled=True)
    assert traced.compiled and traced.samples == plain.samples
    assert traced.sample_cycles == plain.sample_cycles
    text = vcd.read_text()
    header = text[:text.index("$enddefinitions")]
    names = set(re.findall(r"\$var \w+ +\d+ \S+ ([\w.$]+)", header))
    # the save file shows the design's own signals (a field's name escaped as GTKWave reads it)
    shown = re.findall(r"^\+\{[^}]*\} TOP\.frontend_spi_top\.design\.dut\.\\?([\w.]+?)"
                       r"(?:\[[\d:]+\])?$", (tmp_path / "fe.gtkw").read_text(), re.M)
    assert len(shown) > 10 and set(shown) <= names, (shown, sorted(names)[:20])
    # no name of Yosys' own in the trace (GTKWave refuses them)
    assert "$auto" not in header
    # the clock edges are there: a few thousand time steps at least
    assert text.count("\n#") > 1000


def test_cache_key_covers_the_microcode():
    """A compiled build is looked up by its parameters and a hash of the package's sources:
    those of the sub-packages (the filters' microcode in ``hdl/engine/filters/``) are in the hash,
    so a change to a filter's program alone builds again rather than running the old one."""
    from mpu9250_ahrs.sim.bench.compiled_design import _source_files
    names = {name for name, _ in _source_files()}
    assert {"hdl/engine/filters/flagship.py", "hdl/engine/attitude_engine.py",
            "sim/bench/harness.py"} <= names


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "python"])
def test_an_interrupted_run_keeps_what_it_simulated(compiled):
    """Issue #60: Ctrl-C (a KeyboardInterrupt, here raised after the 3rd sample) ends the run
    with what it had: the samples so far, ``interrupted`` set, on both simulators."""
    def ctrl_c(cycle, status, cycles, samples):
        if len(samples) >= 3:
            raise KeyboardInterrupt
        return False
    # compiled: the 12 MHz front end the other tests build; Amaranth's simulator: 4 MHz,
    # bring-up in a third of the cycles
    setup = SimSetup(clk_freq=12e6 if compiled else 4e6)
    run = run_frontend(setup, n_samples=50, stop=ctrl_c, compiled=compiled,
                       keep_on_interrupt=True)
    assert run.interrupted and run.compiled == compiled
    assert len(run.samples) == 3 and run.cycles >= run.sample_cycles[-1] > 0
    # a caller that did not ask for it (the fault harness, the tests) gets the interrupt
    with pytest.raises(KeyboardInterrupt):
        run_frontend(setup, n_samples=50, stop=ctrl_c, compiled=compiled)


@pytest.mark.slow
def test_a_first_build_says_so_piped_or_not(tmp_path, monkeypatch, capsys):
    """Issue #60: a design's first Verilator build (seconds to minutes) printed its line only
    on a terminal: piped or logged, simulate was silent for all of it. Now a line when it
    starts and one with the time it took, whatever stderr is."""
    from amaranth import Module, Signal
    from mpu9250_ahrs.sim.bench.compiled_design import CompiledDesign
    monkeypatch.setenv("MPU9250_AHRS_CACHE", str(tmp_path))
    m, a, b = Module(), Signal(4), Signal(4)
    m.d.sync += b.eq(a + 1)
    CompiledDesign(m, {"a": a}, {"b": b}, name="tiny").close()
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("mpu9250-ahrs: compiling the tiny with Verilator")
    assert err[-1].startswith("mpu9250-ahrs: compiled the tiny in ") and err[-1].endswith(" s")
    CompiledDesign(m, {"a": a}, {"b": b}, name="tiny").close()         # cached: no word
    assert capsys.readouterr().err == ""
