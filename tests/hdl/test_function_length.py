"""No function in ``hdl/`` is longer than ``LIMIT`` lines (issue #27): an ``elaborate`` that
grows past it is split into named parts (the decoder's ``_parse`` and ``_execute``, the
reader's ``_interrupt`` ...), so that each can be read whole."""

import ast
import pathlib

HDL = pathlib.Path(__file__).resolve().parents[2] / "hdl"
LIMIT = 120


def test_no_function_in_hdl_is_over_the_limit():
    long = []
    for path in sorted(HDL.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > LIMIT:
                    long.append(f"{path.relative_to(HDL)}:{node.lineno} {node.name}: {lines}")
    assert not long, long
