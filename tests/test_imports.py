"""The folders depend on each other one way only:

- ``hdl/`` (the gateware) imports nothing from ``sim/``, ``reference/`` or the command line:
  the hardware builds from ``hdl/`` alone;
- inside ``hdl/``, the wings import downward only, in the data's direction (``WING_ORDER``):
  board, link, engine, sensor, primitives, contract; each may import its own wing and those
  after it, and nothing sits beside the wings but the package's ``__init__``;
- ``reference/`` imports nothing from ``sim/`` or the command line, and from ``hdl/`` only its
  contract wing, the plain data both sides keep (``hdl/contract/``: formats, tables, register
  encodings and register maps; no Amaranth in them);
- ``sim/`` may import both (it drives the gateware and compares it with the reference), and of
  the host side only the frame format (``host.protocol``);
- the command line (``mpu9250_ahrs/``) imports all; the host tool (``mpu9250_ahrs/host/``)
  all but ``sim/``;
- and no module imports, through any chain, one that imports it (no import loop).

Every import counts, including those inside functions.
"""

import ast
import pathlib

import pytest


ROOT = pathlib.Path(__file__).resolve().parent.parent
FOLDERS = {"hdl": ROOT / "hdl", "sim": ROOT / "sim", "reference": ROOT / "reference"}
# hdl/'s wings, from the top (the boards) down: a wing imports its own and those after it
WING_ORDER = ("board", "control", "link", "engine", "sensor", "primitives", "contract")
# where each folder may reach: a package, or (package, wing or module) for parts of one
ALLOWED = {
    "hdl": {"hdl"},
    "reference": {"reference", ("hdl", "contract")},
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
                # relative: one dot is this package (``hdl`` or a sub-package such as
                # ``hdl.filters``), each further dot the one above it
                parts = package.split(".")
                base = parts[:len(parts) - node.level + 1]
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
    for path, _inner, line, package, module in _folder_imports(folder):
        if not _allowed(folder, package, module):
            target = package if module is None else f"{package}.{module}"
            bad.append(f"{path.relative_to(ROOT)}:{line} imports {target}")
    assert not bad, "forbidden import direction:\n" + "\n".join(bad)


def _folder_imports(folder):
    """``(path, inner, line, package, module)`` for every import in ``folder``'s modules,
    sub-packages too (``hdl/engine/filters/``); ``inner``: the path's sub-package parts."""
    for path in sorted(FOLDERS[folder].rglob("*.py")):
        inner = path.parent.relative_to(FOLDERS[folder]).parts
        for line, package, module in _imports(path, ".".join((folder, *inner))):
            yield path, inner, line, package, module


def test_contract_modules_are_plain_python():
    for path in sorted((FOLDERS["hdl"] / "contract").glob("*.py")):
        for line, package, module in _imports(path, "hdl.contract"):
            assert package == "hdl" and module == "contract", \
                f"hdl/contract/{path.name}:{line} imports {package}.{module}: a contract " \
                "module imports only other contract modules"
        assert "amaranth" not in path.read_text(), path.name


# sim/'s wings, top floor first: scenarios (what is simulated) use the benches (how), which
# drive the models (what the design talks to)
SIM_WING_ORDER = ("scenarios", "bench", "models")


@pytest.mark.parametrize("folder,order", [("hdl", WING_ORDER), ("sim", SIM_WING_ORDER)])
def test_wings_import_downward_only(folder, order):
    """Every module of ``hdl/`` and of ``sim/`` is in a wing (the package's ``__init__``
    aside), and a wing imports only its own and the wings after it in its order."""
    top = FOLDERS[folder]
    assert sorted(p.name for p in top.glob("*.py")) == ["__init__.py"]
    assert sorted(p.name for p in top.iterdir() if p.is_dir() and p.name != "__pycache__") == \
        sorted(order)
    bad = []
    for path, inner, line, package, target in _folder_imports(folder):
        if inner and package == folder and target is not None and \
                order.index(target) < order.index(inner[0]):
            bad.append(f"{path.relative_to(ROOT)}:{line} ({inner[0]}) imports the {target} "
                       f"wing, above it")
    assert not bad, "an import back up between wings:\n" + "\n".join(bad)


def test_checker_sees_a_bad_import(tmp_path):
    """The walker finds relative, absolute and function-level imports."""
    source = tmp_path / "x.py"
    source.write_text("from ..reference.fixed_point import sat\n"
                      "def f():\n    from mpu9250_ahrs.sim import board\n"
                      "from . import alu\nimport mpu9250_ahrs.host.link\n")
    assert _imports(source, "hdl") == [(1, "reference", "fixed_point"), (3, "sim", "board"),
                                       (4, "hdl", "alu"), (5, "host", "link")]


PACKAGE_DIRS = {"mpu9250_ahrs": ROOT / "mpu9250_ahrs", "mpu9250_ahrs.hdl": ROOT / "hdl",
                **{f"mpu9250_ahrs.hdl.{wing}": ROOT / "hdl" / wing for wing in WING_ORDER},
                "mpu9250_ahrs.hdl.engine.filters": ROOT / "hdl" / "engine" / "filters",
                "mpu9250_ahrs.cli": ROOT / "mpu9250_ahrs" / "cli",
                "mpu9250_ahrs.flows": ROOT / "mpu9250_ahrs" / "flows",
                "mpu9250_ahrs.sim": ROOT / "sim",
                **{f"mpu9250_ahrs.sim.{wing}": ROOT / "sim" / wing for wing in SIM_WING_ORDER},
                "mpu9250_ahrs.reference": ROOT / "reference",
                "mpu9250_ahrs.host": ROOT / "mpu9250_ahrs" / "host"}


def _modules():
    """Every module of the distribution package: dotted name -> path."""
    found = {}
    for package, folder in PACKAGE_DIRS.items():
        for path in folder.glob("*.py"):
            found[package if path.stem == "__init__" else f"{package}.{path.stem}"] = path
    return found


def _import_graph(modules):
    """Module -> the project's modules it imports (anywhere in it, functions included):
    ``from a.b import c`` counts as ``a.b.c`` if that is a module, else ``a.b``."""
    graph = {}
    for name, path in modules.items():
        package = name if path.stem == "__init__" else name.rsplit(".", 1)[0]
        targets = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                candidates = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = package.split(".")[:len(package.split(".")) - node.level + 1] \
                    if node.level else []
                stem = ".".join(base + (node.module.split(".") if node.module else []))
                candidates = [f"{stem}.{alias.name}" if f"{stem}.{alias.name}" in modules
                              else stem for alias in node.names]
            else:
                continue
            targets |= {c for c in candidates if c in modules and c != name}
        graph[name] = targets
    return graph


def _loops(graph):
    """The import loops of ``graph``: each a sorted list of the modules in one strongly
    connected component of more than one module (Tarjan's algorithm)."""
    index, low, stack, on_stack, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_import_loop():
    """No module imports, directly or through others, a module that imports it: not at the
    top and not inside a function (a loop works only as long as the imports stay in the
    right place, and makes the two halves one unit)."""
    loops = _loops(_import_graph(_modules()))
    assert not loops, "import loops:\n" + "\n".join(" <-> ".join(c) for c in loops)


def test_loop_finder_sees_a_loop():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": {"e2"}, "e2": set()}
    assert _loops(graph) == [["a", "b", "c"]]


def test_the_host_tool_imports_no_simulation():
    """``host/`` (the host tool, a board's link) imports nothing of ``sim/``: for ``--port
    sim`` the command line starts the simulated board and hands it to the link."""
    graph = _import_graph(_modules())
    bad = [f"{m} imports {t}" for m, targets in sorted(graph.items())
           if m.startswith("mpu9250_ahrs.host") for t in sorted(targets)
           if t.startswith("mpu9250_ahrs.sim")]
    assert not bad, "\n".join(bad)


# What the host tool reads of the gateware: the contract wing and the frame layouts, and (until
# it is lifted into the contract: it is built from the instruction set and the filters'
# modules) the engine's register map
HOST_MAY_READ = ("mpu9250_ahrs.hdl.contract", "mpu9250_ahrs.hdl.link.frame_types",
                 "mpu9250_ahrs.hdl.engine.register_map")


def test_the_host_reads_only_the_contract_and_the_frame_layouts():
    graph = _import_graph(_modules())
    bad = sorted(f"{module} imports {target}" for module, targets in graph.items()
                 if module.startswith("mpu9250_ahrs.host") for target in targets
                 if target.startswith("mpu9250_ahrs.hdl") and
                 not target.startswith(HOST_MAY_READ))
    assert not bad, "the host reads gateware beyond the contract:\n" + "\n".join(bad)


def test_contract_names_are_exported_once():
    """A class or table of the contract is importable under one name: no module outside
    ``hdl/contract/`` lists one in its ``__all__`` (``reference.fixed_point`` once offered
    ``KalmanFixedConfig`` beside the contract's)."""
    import importlib
    contract = {}
    for path in sorted((FOLDERS["hdl"] / "contract").glob("*.py")):
        module = importlib.import_module(f"mpu9250_ahrs.hdl.contract.{path.stem}")
        contract.update((n, getattr(module, n)) for n in getattr(module, "__all__", ())
                        if not isinstance(getattr(module, n), (int, float, str)))
    again = []
    for folder in ("reference", "sim", "hdl"):
        for path in sorted(FOLDERS[folder].rglob("*.py")):
            inner = path.relative_to(FOLDERS[folder]).with_suffix("").parts
            if folder == "hdl" and inner[0] == "contract" or inner[-1] == "__init__":
                continue
            module = importlib.import_module(".".join(("mpu9250_ahrs", folder, *inner)))
            again += [f"{folder}/{'/'.join(inner)}.py: {n}"
                      for n in getattr(module, "__all__", ())
                      if n in contract and getattr(module, n) is contract[n]]
    assert not again, "contract names exported again:\n" + "\n".join(again)
