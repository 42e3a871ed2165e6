"""The folders depend on each other one way only:

- ``hdl/`` (the gateware) imports nothing from ``sim/``, ``reference/`` or the command line:
  the hardware builds from ``hdl/`` alone;
- ``reference/`` imports nothing from ``sim/`` or the command line, and from ``hdl/`` only the
  plain-data modules that state the contract both sides keep (``CONTRACT``: formats, tables,
  register encodings and register maps; no Amaranth in them);
- ``sim/`` may import both (it drives the gateware and compares it with the reference), and of
  the host side only the frame format (``host.protocol``);
- the command line (``mpu9250_ahrs/``, ``host/``) imports all.

Every import counts, including those inside functions.
"""

import ast
import pathlib

import pytest


ROOT = pathlib.Path(__file__).resolve().parent.parent
FOLDERS = {"hdl": ROOT / "hdl", "sim": ROOT / "sim", "reference": ROOT / "reference"}
CONTRACT = {"numeric_contract", "ak8963_regs", "mpu9250_regs"}
# where each folder may reach: a package, or (package, module) for single modules
ALLOWED = {
    "hdl": {"hdl"},
    "reference": {"reference", *(("hdl", name) for name in CONTRACT)},
    "sim": {"sim", "hdl", "reference", ("host", "protocol")},
}


def _imports(path, package):
    """``(line, package, module)`` for every import of the project in ``path``, a module of
    ``package`` (``module`` None for the package itself)."""
    tree = ast.parse(path.read_text(), str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                names = [f"{node.module}.{alias.name}" for alias in node.names]
            else:
                # relative: one dot is this package, two the distribution package
                base = [package] if node.level == 1 else []
                module = (node.module or "").split(".") if node.module else []
                names = [".".join(["mpu9250_ahrs", *base, *module, alias.name])
                         for alias in node.names]
        else:
            continue
        for name in names:
            parts = name.split(".")
            if parts[0] != "mpu9250_ahrs" or len(parts) < 2:
                continue
            found.append((node.lineno, parts[1], parts[2] if len(parts) > 2 else None))
    return sorted(found)


def _allowed(folder, package, module):
    allowed = ALLOWED[folder]
    return package in allowed or (package, module) in allowed


@pytest.mark.parametrize("folder", sorted(FOLDERS))
def test_imports_go_one_way(folder):
    bad = []
    for path in sorted(FOLDERS[folder].glob("*.py")):
        for line, package, module in _imports(path, folder):
            if not _allowed(folder, package, module):
                target = package if module is None else f"{package}.{module}"
                bad.append(f"{folder}/{path.name}:{line} imports {target}")
    assert not bad, "forbidden import direction:\n" + "\n".join(bad)


def test_contract_modules_are_plain_python():
    for name in sorted(CONTRACT):
        for line, package, module in _imports(FOLDERS["hdl"] / f"{name}.py", "hdl"):
            assert package == "hdl" and module in CONTRACT, \
                f"hdl/{name}.py:{line} imports {package}.{module}: a contract module imports " \
                "only other contract modules"
        assert "amaranth" not in (FOLDERS["hdl"] / f"{name}.py").read_text(), name


def test_checker_sees_a_bad_import(tmp_path):
    """The walker finds relative, absolute and function-level imports."""
    source = tmp_path / "x.py"
    source.write_text("from ..reference.fixed_point import sat\n"
                      "def f():\n    from mpu9250_ahrs.sim import board\n"
                      "from . import alu\nimport mpu9250_ahrs.host.link\n")
    assert _imports(source, "hdl") == [(1, "reference", "fixed_point"), (3, "sim", "board"),
                                       (4, "hdl", "alu"), (5, "host", "link")]
