"""The package layout is the architecture: stages import only downward, the live loop and
the planner never import logs, ROS or Rerun, no import cycles, small documented modules."""

from __future__ import annotations

import ast
import functools
import importlib
import tomllib
import types
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "itt_planner"

#: The data path, bottom to top; a module may import its own stage and those before it.
STAGES = ("errors", "units", "course", "model", "ocp", "live", "logs", "view", "session", "sim",
          "calibration", "sweep", "cli")
#: Third-party edges the core stages (course .. live) must never reach.
EDGE_PACKAGES = ("itt_msgs_py", "rclpy", "rerun", "mcap", "mcap_ros2", "rosbags",
                 "itt_planner_ros")
MAX_LINES = 400


def _module_name(path: Path) -> str:
    parts = path.relative_to(PKG.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in sorted(PKG.rglob("*.py"))}


def _source(path: Path) -> Path:
    """The file that says what a module imports: a lazy package's stub (`__init__.pyi`,
    whose imports lazy_loader makes on first use), else the module itself."""
    stub = path.with_suffix(".pyi")
    return stub if path.name == "__init__.py" and stub.is_file() else path


def _absolute(path: Path, node: ast.ImportFrom) -> str:
    """The module a `from` import in `path` names (a relative one resolved)."""
    if node.level == 0:
        return str(node.module)
    name = _module_name(path)
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    base = package[:len(package) - (node.level - 1)]
    return ".".join([*base, *([node.module] if node.module else [])])


def _stub_origins(package: Path) -> dict[str, str]:
    """Public name -> the module a lazy package's stub imports it from."""
    return {alias.name: _absolute(package, node)
            for node in ast.parse(_source(package).read_text()).body
            if isinstance(node, ast.ImportFrom) for alias in node.names}


@functools.cache
def _imports(path: Path) -> set[str]:
    """Every module named by an import anywhere in the file (function-level ones too); a
    lazy package's are its stub's, relative to the package."""
    source = _source(path)
    names: set[str] = set()
    for node in ast.walk(ast.parse(source.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and (node.module or node.level):
            module = _absolute(path, node)
            names.add(module)
            names.update(f"{module}.{alias.name}" for alias in node.names)
    return names


def _stage(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "itt_planner" else None


MODULES = _modules()


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _stage(m)))
def test_imports_only_downward(module: str) -> None:
    own = STAGES.index(_stage(module))
    upward = sorted(name for name in _imports(MODULES[module])
                    if name in MODULES and _stage(name) and STAGES.index(_stage(name)) > own)
    assert not upward, f"{module} ({STAGES[own]}) imports a later stage: {upward}"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _stage(m) in
                                          ("errors", "course", "model", "ocp", "live")))
def test_core_never_imports_an_edge(module: str) -> None:
    edges = sorted(name for name in _imports(MODULES[module])
                   if name.split(".")[0] in EDGE_PACKAGES)
    assert not edges, f"{module} imports an edge package: {edges}"


def test_no_import_cycle() -> None:
    graph = {m: {n for n in _imports(p) if n in MODULES and n != m and not
                 (m.startswith(n + ".") and MODULES[n].name == "__init__.py")}
             for m, p in MODULES.items()}
    # A package's __init__ re-exports its modules: an edge into it stands for them.
    state: dict[str, int] = {}

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                raise AssertionError("import cycle: " + " -> ".join([*trail, node, nxt]))
            if nxt not in state:
                visit(nxt, [*trail, node])
        state[node] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module, [])


@pytest.mark.parametrize("module", sorted(MODULES))
def test_module_is_small_and_says_what_it_is_for(module: str) -> None:
    source = MODULES[module].read_text()
    lines = source.count("\n")
    assert lines <= MAX_LINES, f"{module}: {lines} lines (limit {MAX_LINES})"
    docstring = ast.get_docstring(ast.parse(source))
    assert docstring and docstring.strip(), f"{module}: no module docstring"


def _bound_and_exported(tree: ast.Module) -> tuple[set[str], list[str] | None]:
    """Names a module binds at top level, and its `__all__` (None if it has none)."""
    bound: set[str] = set()
    exported: list[str] | None = None
    for node in tree.body:
        if isinstance(node, ast.Import | ast.ImportFrom):
            bound.update((alias.asname or alias.name).split(".")[0] for alias in node.names)
        elif isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            bound.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names = {t.id for t in targets if isinstance(t, ast.Name)}
            if "__all__" in names and node.value is not None:
                exported = list(ast.literal_eval(node.value))
            bound.update(names)
    return bound, exported


PACKAGES = sorted(m for m, p in MODULES.items() if p.name == "__init__.py")


@pytest.mark.parametrize("package", PACKAGES)
def test_package_exports_its_public_names(package: str) -> None:
    """Each (sub)package's `__init__` (its stub, when lazy) lists its public names in
    `__all__`, once each, and every one of them is bound there; a lazy package binds
    exactly those (lazy_loader exports every name its stub imports), and each one loads
    as the object its stub names, not a same-named module (a name that moved away fails
    here, not at first use)."""
    bound, exported = _bound_and_exported(ast.parse(_source(MODULES[package]).read_text()))
    assert exported, f"{package}: no __all__"
    assert len(set(exported)) == len(exported), f"{package}: __all__ repeats a name"
    missing = sorted(set(exported) - bound)
    assert not missing, f"{package}: __all__ names what it does not bind: {missing}"
    if _source(MODULES[package]) != MODULES[package]:
        module = importlib.import_module(package)
        assert sorted(module.__all__) == sorted(exported), package
        for name, origin in _stub_origins(MODULES[package]).items():
            importlib.import_module(origin)  # as another module would, before the name
            value = getattr(module, name)
            assert not isinstance(value, types.ModuleType), f"{package}.{name} is a module"


def _frozen_dataclasses(path: Path) -> set[str]:
    """Classes of a module decorated `@dataclass(frozen=True)`."""
    out = set()
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.ClassDef):
            for deco in node.decorator_list:
                if (isinstance(deco, ast.Call) and getattr(deco.func, "id", None) == "dataclass"
                        and any(k.arg == "frozen" and getattr(k.value, "value", False)
                                for k in deco.keywords)):
                    out.add(node.name)
    return out


def test_immutable_defaults_in_the_lint_config_are_frozen_dataclasses() -> None:
    """ruff lets these be built once as argument defaults (bugbear's immutable calls): each
    must still exist at that path and be frozen (a class that moved or thawed fails here)."""
    config = tomllib.loads((PKG.parent / "pyproject.toml").read_text())
    calls = config["tool"]["ruff"]["lint"]["flake8-bugbear"]["extend-immutable-calls"]
    ours = [c for c in calls if c.startswith("itt_planner.")]
    assert ours
    wrong = [c for c in ours if c.rpartition(".")[0] not in MODULES
             or c.rpartition(".")[2] not in _frozen_dataclasses(MODULES[c.rpartition(".")[0]])]
    assert not wrong, f"not a frozen dataclass at that path: {wrong}"
