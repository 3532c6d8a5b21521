"""The package's shape (docs/architecture.md): imports flow one way, the model's modules stay small."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parent.parent / "contactdyn"
#: the model and the loop, one concept per module (docs/architecture.md's module map)
CORE = [f"model/{m}" for m in ("chain", "contact", "phases", "chain_forces", "friction", "constraints",
                               "impact", "evaluation", "system", "paths", "limits")] + \
    [f"model/pipeline/{m}" for m in ("pack", "pipeline", "robot_terms", "contacts", "kkt", "actuation",
                                     "force_fold", "control_laws", "drives", "launch", "energy", "joint_friction")] + \
    [f"hybrid/{m}" for m in ("events", "transitions", "loop", "pipeline_mode", "steps", "sampling", "sampled_law")] + \
    ["output/samples", "output/channels", "output/physics_checks", "simulate", "numerics/integrators",
     "numerics/dop853", "laws/stage_laws", "laws/friction_laws"]
MAX_CLASS, MAX_FUNCTION = 300, 80  #: [lines]


def _module_name(path: Path) -> str:
    parts = path.relative_to(PKG.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


#: deliberate imports inside a function against the flow, left out of the graph: Result.show() (a notebook's
#: player) imports the viewer when called; the viewer imports result at load, so no cycle exists at import
LAZY_UPWARD = {("contactdyn.output.result", "contactdyn.viewer.notebook")}


def _import_graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports (module level or inside functions; not TYPE_CHECKING)."""
    paths = {_module_name(p): p for p in PKG.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        tree = ast.parse(path.read_text())
        typing_only = {id(n) for block in ast.walk(tree)
                       if isinstance(block, ast.If) and "TYPE_CHECKING" in ast.unparse(block.test)
                       for n in ast.walk(block)}
        package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        edges: set[str] = set()
        for node in ast.walk(tree):
            if id(node) in typing_only or not isinstance(node, ast.ImportFrom):
                continue
            base = package[:len(package) - node.level + 1] if node.level else []
            target = ".".join(base + ([node.module] if node.module else [])) if node.level else node.module or ""
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                edges.add(sub if sub in paths else target)
        graph[name] = {e for e in edges if e in paths and e != name and (name, e) not in LAZY_UPWARD}
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str]:
    """One import cycle as a list of modules, or []."""
    state: dict[str, int] = {}  # 1: on the path, 2: done
    path: list[str] = []

    def visit(v: str) -> list[str]:
        state[v] = 1
        path.append(v)
        for w in sorted(graph[v]):
            if state.get(w) == 1:
                return path[path.index(w):] + [w]
            if w not in state and (found := visit(w)):
                return found
        state[v] = 2
        path.pop()
        return []

    for v in sorted(graph):
        if v not in state and (found := visit(v)):
            return found
    return []


def test_the_package_has_no_import_cycle():
    assert _cycle(_import_graph()) == []


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert set(_cycle(graph)) == {"a", "b", "c"}
    assert _cycle({"a": {"b"}, "b": set()}) == []


def _too_long(path: Path) -> list[str]:
    """The classes over MAX_CLASS lines and the functions over MAX_FUNCTION lines in one file."""
    tree = ast.parse(path.read_text())
    return [f"{path.name}: {node.name}: {node.end_lineno - node.lineno + 1} lines" for node in ast.walk(tree)
            if isinstance(node, ast.ClassDef) and node.end_lineno - node.lineno + 1 > MAX_CLASS
            or isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
            and node.end_lineno - node.lineno + 1 > MAX_FUNCTION]


@pytest.mark.parametrize("module", CORE)
def test_core_module_is_documented_and_small(module):
    tree = ast.parse((PKG / f"{module}.py").read_text())
    doc = ast.get_docstring(tree)
    assert doc and len(doc.splitlines()) >= 3, f"{module}: a module docstring stating its concept"
    assert _too_long(PKG / f"{module}.py") == []


#: the modules at the package's top: the package, its errors, and the entry points (no mechanism; ``__main__``:
#: ``python -m contactdyn``)
TOP_LEVEL = {"__init__", "__main__", "errors", "simulate", "cli", "starter", "first_run"}
MAX_FOLDER = 12  #: modules in one concept folder, its __init__ not counted


def test_the_package_is_folders_named_after_concepts():
    assert {p.stem for p in PKG.glob("*.py")} == TOP_LEVEL
    for folder in (p for p in PKG.rglob("*") if p.is_dir() and (p / "__init__.py").is_file()):
        modules = [p.stem for p in folder.glob("*.py") if p.stem != "__init__"]
        assert len(modules) <= MAX_FOLDER, f"{folder.name}: {len(modules)} modules"
        doc = ast.get_docstring(ast.parse((folder / "__init__.py").read_text()))
        assert doc, f"{folder.name}/__init__.py: a docstring stating the folder's concept"


def test_no_class_or_function_in_the_package_is_too_long():
    assert [line for path in sorted(PKG.rglob("*.py")) for line in _too_long(path)] == []


def test_the_size_rule_finds_a_long_function(tmp_path):
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION))
    (tmp_path / "m.py").write_text(f"def short():\n    pass\n\n\ndef long():\n{body}\n")
    assert _too_long(tmp_path / "m.py") == [f"m.py: long: {MAX_FUNCTION + 1} lines"]


#: the data flow of one run (docs/architecture.md), upstream first; a module imports only from its own
#: layer or those before it. A folder stands for its modules; a longer prefix decides first. Every module
#: of the package is in one layer.
LAYERS = [
    ["", "errors", "scene.reader", "scene.keyfields", "numerics"],  # shared below all ("": the package's lazy names)
    ["laws"],  # stage laws, friction laws, drives, controllers, references: no model
    ["robot", "scene"],  # Pinocchio's robot; a scene file read and checked (it reads the laws' declarations)
    ["model"],  # the physics (the one pipeline's call compiled by numba: no second description)
    ["output"],  # channels, samples, Result, checks
    ["hybrid"],  # the loop: nothing below imports it
    ["simulate", "starter", "analysis"],
    ["cli", "first_run", "viewer", "sweep", "identify"],
    ["__main__"],
]


def _layer(module: str) -> tuple[str, int] | None:
    name = module.removeprefix("contactdyn").removeprefix(".")
    found = [(prefix, i) for i, names in enumerate(LAYERS) for prefix in names
             if name == prefix or prefix and name.startswith(prefix + ".")]
    return max(found, key=lambda f: len(f[0])) if found else None


def _against_the_flow(graph: dict[str, set[str]]) -> list[str]:
    """Imports from a module to one in a later layer."""
    found = []
    for module, targets in graph.items():
        for target in targets:
            src, dst = _layer(module), _layer(target)
            if src and dst and dst[1] > src[1]:
                found.append(f"{module} imports {target}")
    return sorted(found)


def test_every_module_has_a_layer():
    assert [m for m in _import_graph() if _layer(m) is None] == []


def test_imports_follow_the_data_flow():
    assert _against_the_flow(_import_graph()) == []


def test_the_flow_rule_finds_an_import_against_the_flow():
    graph = {"contactdyn.model.system": {"contactdyn.hybrid.loop"},
             "contactdyn.hybrid.loop": {"contactdyn.model.system"},
             "contactdyn.laws.drives": {"contactdyn.scene.reader", "contactdyn.model.chain"},
             "contactdyn.scene.scene_file": {"contactdyn.numerics.integrators"},
             "contactdyn.output.result": {"contactdyn.output.plots"}}
    assert _against_the_flow(graph) == ["contactdyn.laws.drives imports contactdyn.model.chain",
                                        "contactdyn.model.system imports contactdyn.hybrid.loop"]
