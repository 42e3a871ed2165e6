"""The AXI4-Lite slave (issue #56) checked by a bus model nobody here wrote: its Verilog (the
slave wired as the core wires it, on the real engine fed samples: ``tests/cocotb/axi_harness.py``)
under cocotb and ``cocotbext-axi``'s ``AxiLiteMaster`` on Icarus: 10,000 random transactions
with back-pressure on every channel, every kind of refusal, the result block read while
results arrive (SEQUENCE the same before and after: one result's words, bit for bit), the
interrupt's set and clear (``tests/cocotb/axi_lite_bench.py``). And the
register map's table in ``hdl/AXI_LITE.md`` is the contract's."""

import pathlib

import pytest

from ..conftest import require_tool

ROOT = pathlib.Path(__file__).resolve().parents[2]


def _run(tmp_path, transactions, **harness):
    from tests.cocotb.axi_harness import verilog
    source = tmp_path / "axi_harness.v"
    verilog(source, **harness)
    return _cocotb(tmp_path, source, "axi_harness", "axi_lite_bench", transactions)


def _cocotb(tmp_path, source, top, module, transactions=0, env=None):
    pytest.importorskip("cocotb")
    pytest.importorskip("cocotbext.axi")
    require_tool("iverilog", "apt-get install iverilog")
    from cocotb_tools.runner import get_runner
    runner = get_runner("icarus")
    # -g2005: Icarus runs a declaration's initial value as an event only in Verilog-2005's
    # rules, and Yosys' Verilog wakes its ``always @*`` blocks at time 0 with one (the
    # runner's -g2012 leaves a combinational output X until its inputs first change)
    runner.build(sources=[source], hdl_toplevel=top, build_dir=tmp_path / "build",
                 always=True, build_args=["-g2005"], timescale=("1ns", "1ps"))
    # the bench module from its folder (cocotb puts ``test_dir`` on the path)
    results = runner.test(hdl_toplevel=top, test_module=module,
                          build_dir=tmp_path / "build", test_dir=ROOT / "tests" / "cocotb",
                          results_xml=str(tmp_path / "results.xml"),
                          extra_env={"MPU9250_AXI_TRANSACTIONS": str(transactions),
                                     **(env or {})})
    from cocotb_tools.runner import get_results
    return get_results(results)


# 10,000 random transactions take about 30 s (Icarus, one core, the engine updating every
# 1,100 cycles): the slow step; the default run (over its budget already) takes a tenth
@pytest.mark.parametrize("transactions", [
    1_000, pytest.param(10_000, marks=pytest.mark.slow)])
def test_axi_lite_slave_under_cocotbext_axi(tmp_path, transactions):
    tests, failed = _run(tmp_path, transactions)
    assert tests == 3 and failed == 0


# about 19 s (the core's build, then Icarus): the slow step, the default run being over its
# budget already
@pytest.mark.slow
def test_exported_core_under_cocotbext_axi(tmp_path):
    """The Verilog a user instantiates (``build --verilog-only --axi-lite``): its AXI slave
    reaches the engine, the board's registers (RAW_MODE on the core's pin) and the PWM block
    through the command decoder's executor (``tests/cocotb/core_axi_bench.py``)."""
    from mpu9250_ahrs.cli import main
    from mpu9250_ahrs.hdl.board.top import AHRSCore
    assert main(["build", "--verilog-only", "--axi-lite", "--out", str(tmp_path)]) == 0
    version = AHRSCore(axi_lite=True).version
    tests, failed = _cocotb(tmp_path, tmp_path / "mpu9250_ahrs_core.v", "mpu9250_ahrs_core",
                            "core_axi_bench", 1_000, env={"MPU9250_CORE_VERSION": str(version)})
    assert tests == 1 and failed == 0


def test_the_documented_map_is_the_contracts():
    from mpu9250_ahrs.hdl.contract.axi_regs import markdown_table
    assert markdown_table() in (ROOT / "hdl" / "AXI_LITE.md").read_text()


def test_platform_designer_component_names_every_port_once(tmp_path):
    """``build --verilog-only --axi-lite`` writes a ``_hw.tcl`` (untested in Quartus: there is
    none here) with every top port of the core in one interface, the AXI signals under their
    AMBA roles."""
    import re
    from mpu9250_ahrs.cli import main
    assert main(["build", "--verilog-only", "--axi-lite", "--out", str(tmp_path)]) == 0
    verilog = (tmp_path / "mpu9250_ahrs_core.v").read_text()
    tcl = (tmp_path / "mpu9250_ahrs_core_hw.tcl").read_text()
    top = re.search(r"^module mpu9250_ahrs_core\b.*?^endmodule", verilog, re.M | re.S).group(0)
    ports = re.findall(r"^\s*(?:input|output)\s+(?:\[[^\]]+\]\s+)?(\w+)\s*;", top, re.M)
    listed = re.findall(r"^add_interface_port \w+ (\w+) ", tcl, re.M)
    assert sorted(listed) == sorted(ports)
    assert "add_interface_port s_axi s_axi__awvalid awvalid Input 1" in tcl
    assert "add_interface_port irq irq irq Output 1" in tcl


def test_sequence_moves_as_an_update_starts_and_as_it_ends():
    """SEQUENCE changes with ``busy``'s rise (COUNTER changes then) and with its fall (FLAGS'
    bits set at the end): a block read whose FLAGS came before an update's end and its other
    words after cannot hold SEQUENCE (pysim, the slave alone)."""
    from amaranth.sim import Simulator
    from mpu9250_ahrs.hdl.contract.axi_regs import AXI_REGS
    from mpu9250_ahrs.hdl.link.axi_lite_slave import AXILiteSlave
    dut = AXILiteSlave()
    axi = dut.axi
    seen = []

    async def read_sequence(ctx):
        ctx.set(axi.araddr, AXI_REGS["SEQUENCE"][0])
        ctx.set(axi.arvalid, 1)
        await ctx.tick().until(axi.arready)
        ctx.set(axi.arvalid, 0)
        ctx.set(axi.rready, 1)
        data, = await ctx.tick().sample(axi.rdata).until(axi.rvalid)
        ctx.set(axi.rready, 0)
        return data

    async def bench(ctx):
        for busy in (0, 1, 1, 0, 0, 1, 0):
            ctx.set(dut.busy, busy)
            await ctx.tick().repeat(3)
            seen.append(await read_sequence(ctx))

    sim = Simulator(dut)
    sim.add_clock(1e-6)
    sim.add_testbench(bench)
    sim.run()
    assert seen == [0, 1, 1, 2, 2, 3, 4]
