"""No function in the gateware (``hdl/``) is over 120 lines (issue #27): a component's
``elaborate`` that grows past it is split into named parts (``_write_port``, ``_states``, …),
each a piece a reader can hold at once."""

import ast
import pathlib


HDL = pathlib.Path(__file__).resolve().parent.parent / "hdl"
LIMIT = 120


def test_no_function_in_hdl_over_120_lines():
    long = []
    for path in sorted(HDL.rglob("*.py")):      # sub-packages too (hdl/engine/filters/)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > LIMIT:
                    long.append(f"{path.name}:{node.lineno} {node.name} ({lines} lines)")
    assert not long, "split these: " + ", ".join(long)
