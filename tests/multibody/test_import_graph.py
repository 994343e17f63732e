"""The modules of ``drake_abs.multibody`` import each other without a circle: the graph of their
imports, counting those inside functions (an import moved into a function to dodge a circle
still closes it), has no cycle."""

from __future__ import annotations

import ast
from pathlib import Path

import drake_abs.multibody

PACKAGE = "drake_abs.multibody"
FOLDER = Path(drake_abs.multibody.__file__).parent


def _module_of(path: Path) -> str:
    return "__init__" if path.stem == "__init__" else path.stem


def _targets(node: ast.AST, modules: set[str]) -> list[str]:
    """The package's modules an import statement imports (``__init__`` for the package)."""
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
    elif isinstance(node, ast.ImportFrom):
        if node.level > 1:  # above the package
            return []
        base = node.module or ""
        if node.level == 1:  # relative to the package
            base = f"{PACKAGE}.{base}" if base else PACKAGE
        # ``from drake_abs.multibody import scene`` imports a module; ``import Scene``, a name
        names = [f"{base}.{a.name}" if a.name in modules else base for a in node.names]
    else:
        return []
    out = []
    for name in names:
        if name == PACKAGE:
            out.append("__init__")
        elif name.startswith(PACKAGE + "."):
            out.append(name.removeprefix(PACKAGE + ".").split(".")[0])
    return [t for t in out if t in modules or t == "__init__"]


def import_graph(folder: Path = FOLDER) -> dict[str, set[str]]:
    """Module -> the package's modules it imports anywhere in its source (module level,
    functions, methods, ``if`` blocks)."""
    files = {_module_of(p): p for p in sorted(folder.glob("*.py"))}
    modules = set(files) - {"__init__"}
    graph = {}
    for name, path in files.items():
        tree = ast.parse(path.read_text(), filename=str(path))
        graph[name] = {t for node in ast.walk(tree) for t in _targets(node, modules)} - {name}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a path ``[a, b, ..., a]``, or None when it has none."""
    state: dict[str, str] = {}  # "open" while on the DFS path, "done" after
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = "open"
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                return path[path.index(nxt) :] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        path.pop()
        state[node] = "done"
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_the_multibody_modules_import_each_other_without_a_cycle():
    graph = import_graph()
    assert {"scene", "builder", "stepper", "model_files", "packages"} <= set(graph)
    cycle = find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_the_scene_modules_are_layered_bottom_up():
    """Package resolution at the bottom, the builder at the top."""
    graph = import_graph()
    assert not graph["packages"]  # imports none of the package's modules
    assert "packages" in graph["scene"] and "packages" in graph["parsing"]
    for module in ("packages", "model_files", "scene_entries", "parsing", "contacts", "scene",
                   "stepper"):  # fmt: skip
        assert "builder" not in graph[module], module


def test_the_cycle_finder_finds_a_function_level_import_cycle(tmp_path):
    (tmp_path / "a.py").write_text("from drake_abs.multibody.b import f\n")
    (tmp_path / "b.py").write_text("def f():\n    from drake_abs.multibody import a\n")
    (tmp_path / "c.py").write_text("import drake_abs.multibody.a\n")
    graph = import_graph(tmp_path)
    assert graph == {"a": {"b"}, "b": {"a"}, "c": {"a"}}
    assert find_cycle(graph) == ["a", "b", "a"]
    assert find_cycle({"a": {"b"}, "b": set()}) is None
