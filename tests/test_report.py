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
    from mpu9250_ahrs.report import report
    return report()


def test_report_keys_and_sanity(figures):
    for part in ("design", "datapath"):
        f = figures[part]
        for key in ("logic_elements", "registers", "memory_bits", "multipliers_18x18",
                    "logic_levels"):
            assert isinstance(f[key], int) and f[key] > 0, (part, key)
    # one 32x32 multiplier in four 18x18 blocks, nothing else multiplies
    assert figures["datapath"]["multipliers_18x18"] == 4
    assert figures["design"]["multipliers_18x18"] == 4
    assert figures["design"]["logic_elements"] > figures["datapath"]["logic_elements"]
    from amaranth.lib import data
    from mpu9250_ahrs.hdl.attitude_isa import REG_COUNT, Instr
    from mpu9250_ahrs.hdl.attitude_program import build_program
    rom_bits = len(build_program()[0]) * data.Layout.cast(Instr).size
    # the register file twice (one copy per read port) and the microcode ROM
    assert figures["datapath"]["memory_bits"] == 2 * REG_COUNT * 32 + rom_bits
    cycles = figures["cycles_per_update"]
    assert set(cycles) == {"kalman", "complementary", "flagship"}
    assert cycles["complementary"] < cycles["kalman"] <= cycles["flagship"] + 8
    assert figures["clock_hz"] == 48e6
    assert figures["update_us"]["flagship"] == round(cycles["flagship"] / 48, 2)
    # the whole core co-simulated: the SPI burst plus the flagship's update, at 48 MHz
    latency = figures["latency_us"]["drdy_to_attitude"]
    assert cycles["flagship"] / 48 < latency < 60
    assert figures["max_sample_rate_hz"] >= 8000


def test_report_verb_prints_json(monkeypatch, capsys, figures):
    import mpu9250_ahrs.report as report_module
    monkeypatch.setattr(report_module, "report", lambda **kw: figures)
    assert main(["report"]) == 0
    assert json.loads(capsys.readouterr().out)["datapath"] == json.loads(
        json.dumps(figures["datapath"]))
