"""No function in the gateware (``hdl/``, issue #27) or the simulation (``sim/``, issue #59) is
over 120 lines: a component's ``elaborate`` or a scenario that grows past it is split into named
parts (``_write_port``, ``_states``, a watch class, …), each a piece a reader can hold at once."""

import ast
import pathlib

import pytest


ROOT = pathlib.Path(__file__).resolve().parent.parent
LIMIT = 120


@pytest.mark.parametrize("folder", ["hdl", "sim"])
def test_no_function_over_120_lines(folder):
    long = []
    for path in sorted((ROOT / folder).rglob("*.py")):      # sub-packages too
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > LIMIT:
                    long.append(f"{path.name}:{node.lineno} {node.name} ({lines} lines)")
    assert not long, "split these: " + ", ".join(long)
