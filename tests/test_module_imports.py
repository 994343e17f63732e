"""The import graph of the package and the experiments: no cycle between modules (imports inside
functions counted: a lazy import is still an arrow), no experiment importing another experiment,
and no private name imported from another module.

``tests/test_layers.py`` checks that no layer imports upward; this file checks the modules within
and across layers."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: folder -> the import name of its package
PACKAGES = {
    "drake_abs": "drake_abs",
    "systems": "drake_abs.systems",
    "diagrams": "drake_abs.diagrams",
    "experiments": "drake_abs.experiments",
}
#: experiments/ modules that are not experiments: the command line, sweeps, the output folder
#: helpers, the kernel warm-up and the training command. The CLI and the sweep load experiments
#: by name (importlib).
EXPERIMENT_SUPPORT = {"cli", "sweep", "outputs", "precompile", "train", "__init__"}


def _modules() -> dict[str, Path]:
    out = {}
    for folder, package in PACKAGES.items():
        base = ROOT / folder
        for path in base.rglob("*.py"):
            rel = path.relative_to(base).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            out[".".join([package, *parts])] = path
    return out


def _imports(path: Path) -> list[tuple[int, str, list[str]]]:
    """(line, module, names) of every absolute import in the file, wherever it is."""
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.append((node.lineno, node.module, [a.name for a in node.names]))
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for _, module, names in _imports(path):
            targets = [f"{module}.{n}" for n in names if f"{module}.{n}" in modules]
            if module in modules and len(targets) < max(len(names), 1):
                targets.append(module)  # a name defined in the module (or `import module`)
            graph[name] |= {t for t in targets if t != name}
    return graph


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of the graph (a list of modules, first = last), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_the_cycle_finder_finds_a_cycle():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def test_no_module_imports_a_module_that_imports_it_back():
    graph = _graph()
    # a package's __init__ re-exports its modules; a module importing its own package's name
    # (`from drake_abs.contact import X` inside drake_abs/contact) would close a loop
    cycle = _cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_no_experiment_imports_another_experiment():
    bad = []
    for path in sorted((ROOT / "experiments").glob("*.py")):
        if path.stem in EXPERIMENT_SUPPORT:
            continue
        for line, module, names in _imports(path):
            targets = [module] + [f"{module}.{n}" for n in names]
            for target in targets:
                stem = target.removeprefix("drake_abs.experiments.").split(".")[0]
                if target.startswith("drake_abs.experiments.") and stem not in {"outputs"}:
                    bad.append(f"experiments/{path.name}:{line}: {target}")
    assert not bad, "experiments importing experiments:\n" + "\n".join(bad)


def test_no_private_name_is_imported_from_another_module():
    bad = []
    for path in sorted(_modules().values()):
        for line, module, names in _imports(path):
            if not module.startswith("drake_abs"):  # the project's own modules only
                continue
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            hidden = any(p.startswith("_") and not p.startswith("__") for p in module.split("."))
            allowed_module = module == "drake_abs._validation"  # the core's shared checks
            if (private or hidden) and not allowed_module:
                bad.append(f"{path.relative_to(ROOT)}:{line}: from {module} import {names}")
    assert not bad, "private names imported across modules:\n" + "\n".join(bad)
