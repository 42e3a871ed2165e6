"""The AXI4-Lite slave's channels, proven by k-induction (issue #56): against any master that
keeps the AXI rules on AW, W and AR (valid held until ready, its address or data still), B and
R keep them too (``bvalid``/``rvalid`` held until ``bready``/``rready``, the response and data
still), for any back-pressure; its lib.stream ports (the results, the engine's port) keep the
stream rules (``contract_harness``), and no valid or ready depends combinationally on the
other side's (the netlist check of ``comb_paths``, on its streams)."""

from types import SimpleNamespace

import pytest
from amaranth import Cat
from amaranth.hdl import Assert, Assume

from mpu9250_ahrs.hdl.link.axi_lite_slave import AXILiteSlave

from .stream_contract import _rules, contract_harness


def _channel(valid, ready, *payload):
    return SimpleNamespace(valid=valid, ready=ready, payload=Cat(*payload))


def axi_harness():
    dut = AXILiteSlave()
    m = contract_harness(dut)
    a = dut.axi
    for name, ch in (("aw", _channel(a.awvalid, a.awready, a.awaddr, a.awprot)),
                     ("w", _channel(a.wvalid, a.wready, a.wdata, a.wstrb)),
                     ("ar", _channel(a.arvalid, a.arready, a.araddr, a.arprot))):
        _rules(m, ch, Assume, name, cover=False)
    for name, ch in (("b", _channel(a.bvalid, a.bready, a.bresp)),
                     ("r", _channel(a.rvalid, a.rready, a.rdata, a.rresp))):
        _rules(m, ch, Assert, name, cover=True)
    return m


@pytest.mark.formal
def test_axi_channels_keep_the_rules(formal):
    formal(axi_harness(), name="axi_lite_slave", mode="prove", depth=8)
