"""The layering promise, as a table: each layer may import only the layers below it (and the
third-party libraries named for it). Data flows one way; a new upward import fails here."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# folder on disk -> (its import name, the project layers it may import, extra third-party roots)
LAYERS: dict[str, tuple[str, set[str], set[str]]] = {
    "drake_abs/lcp": ("drake_abs.lcp", set(), set()),
    "drake_abs/contact": ("drake_abs.contact", {"drake_abs.lcp"}, set()),
    "drake_abs/engine": ("drake_abs.engine", {"drake_abs.lcp", "drake_abs.contact"}, set()),
    "drake_abs/policy": (
        "drake_abs.policy",
        {"drake_abs.lcp", "drake_abs.contact", "drake_abs.engine"},
        {"tqdm"},
    ),
    "drake_abs/tasks": (
        "drake_abs.tasks",
        # multibody: tasks.locomotion builds gymnasium's scenes' steppers (imported when called,
        # so the package itself stays Drake-free)
        {
            "drake_abs.lcp",
            "drake_abs.contact",
            "drake_abs.engine",
            "drake_abs.policy",
            "drake_abs.multibody",
        },
        {"gymnasium"},  # tasks.gym_env: a task as a gymnasium.Env
    ),
    "drake_abs/learning": (
        "drake_abs.learning",
        {"drake_abs.lcp", "drake_abs.contact", "drake_abs.engine"},
        set(),
    ),
    "drake_abs/mpc": ("drake_abs.mpc", {"drake_abs.contact", "drake_abs.engine"}, {"osqp"}),
    "drake_abs/parallel": (
        "drake_abs.parallel",
        {"drake_abs.lcp", "drake_abs.contact", "drake_abs.engine", "drake_abs.policy"},
        {"tqdm", "matplotlib", "ray"},  # progress bars, the sweep's plot, the cluster
    ),
    "drake_abs/multibody": (
        "drake_abs.multibody",
        {"drake_abs.lcp", "drake_abs.contact"},
        {"pydrake", "pinocchio", "yaml"},  # the rigid-body dynamics libraries, scene files
    ),
    "drake_abs/reference": (
        "drake_abs.reference",
        {"drake_abs.lcp", "drake_abs.contact", "drake_abs.engine", "drake_abs.multibody"},
        {"pydrake", "mujoco", "gymnasium"},  # the reference simulators themselves
    ),
    "systems": (
        "drake_abs.systems",
        {
            "drake_abs.lcp",
            "drake_abs.contact",
            "drake_abs.engine",
            "drake_abs.policy",
            "drake_abs.tasks",
            "drake_abs.mpc",
            "drake_abs.multibody",
        },
        {"pydrake", "meshcat"},
    ),  # fmt: skip
    "diagrams": (
        "drake_abs.diagrams",
        {
            "drake_abs.lcp",
            "drake_abs.contact",
            "drake_abs.engine",
            "drake_abs.policy",
            "drake_abs.tasks",
            "drake_abs.mpc",
            "drake_abs.multibody",
            "drake_abs.systems",
        },
        {"pydrake", "meshcat", "matplotlib"},
    ),  # fmt: skip
    # the top: every layer below, and the libraries the experiments drive (no experiment
    # imports another: tests/test_module_imports.py)
    "experiments": (
        "drake_abs.experiments",
        {
            "drake_abs.lcp",
            "drake_abs.contact",
            "drake_abs.engine",
            "drake_abs.policy",
            "drake_abs.tasks",
            "drake_abs.learning",
            "drake_abs.mpc",
            "drake_abs.parallel",
            "drake_abs.multibody",
            "drake_abs.reference",
            "drake_abs.systems",
            "drake_abs.diagrams",
        },
        {"pydrake", "meshcat", "matplotlib", "tqdm", "yaml", "ray", "mujoco", "gymnasium"},
    ),  # fmt: skip
}
# Every layer may use these.
COMMON = {"numpy", "scipy", "numba", "drake_abs._validation", "__future__"}
THIRD_PARTY_GUARDED = {
    "pydrake", "pinocchio", "osqp", "meshcat", "matplotlib", "tqdm", "yaml", "ray", "mujoco",
    "gymnasium",
}  # fmt: skip
STDLIB = set(sys.stdlib_module_names)


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [f"{node.module}.{a.name}" for a in node.names]
            out += (
                [(node.lineno, n) for n in names]
                if node.module == "drake_abs"
                else [(node.lineno, node.module)]
            )
    return out


#: The layers the top-level package re-exports from (``drake_abs.solve_lcp`` is the lcp layer's):
#: a layer may import ``drake_abs.<name>`` when it may import all of them.
TOP_LEVEL_SOURCES = {"drake_abs.lcp", "drake_abs.contact", "drake_abs.engine", "drake_abs.tasks"}


def _allowed(name: str, own: str, layers: set[str], extra: set[str]) -> bool:
    root = name.split(".")[0]
    if name.count(".") == 1 and root == "drake_abs" and TOP_LEVEL_SOURCES <= layers:
        import drake_abs

        if name.split(".")[1] in drake_abs.__all__:
            return True
    if root in STDLIB and root != "drake_abs" or name.startswith(own):
        return True
    if any(name == c or name.startswith(c + ".") for c in COMMON | layers | extra):
        return True
    if root == "drake_abs":
        return False
    return root not in THIRD_PARTY_GUARDED  # other third-party libraries are not layers


@pytest.mark.parametrize("folder", sorted(LAYERS))
def test_no_layer_imports_upward(folder):
    own, layers, extra = LAYERS[folder]
    files = sorted((ROOT / folder).rglob("*.py"))
    assert files, folder
    bad = [
        f"{p.relative_to(ROOT)}:{line}: {name}"
        for p in files
        for line, name in _imports(p)
        if not _allowed(name, own, layers, extra)
    ]
    assert not bad, "imports outside the allowed layers:\n" + "\n".join(bad)


def test_every_core_subpackage_is_in_the_table():
    core = {
        p.parent.relative_to(ROOT).as_posix() for p in (ROOT / "drake_abs").glob("*/__init__.py")
    }
    assert core <= set(LAYERS), core - set(LAYERS)


def test_core_top_level_holds_only_the_package_and_private_helpers():
    loose = [p.name for p in (ROOT / "drake_abs").glob("*.py")]
    assert sorted(loose) == ["__init__.py", "_validation.py"], loose


def test_the_drake_free_core_imports_without_pydrake():
    code = (
        "import sys, drake_abs, drake_abs.lcp, drake_abs.contact, drake_abs.engine, "
        "drake_abs.policy, "
        "drake_abs.mpc, drake_abs.tasks; "
        "drake_abs.solve_lcp([[1.0]], [0.5]); "
        "bad = [m for m in sys.modules if m.startswith(('pydrake', 'pinocchio'))]; "
        "assert not bad, bad"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_each_subpackage_says_what_it_is():
    for init in (ROOT / "drake_abs").glob("*/__init__.py"):
        doc = ast.get_docstring(ast.parse(init.read_text()))
        assert doc and len(doc) > 40, init


def test_tests_mirror_the_layout():
    """Each test folder is named for the layer it tests (project-wide tests stay at the top)."""
    folders = {p.name for p in (ROOT / "tests").iterdir() if p.is_dir() and p.name[0] != "_"}
    folders.discard("__pycache__")
    layers = {name.rsplit("/", 1)[-1] for name in LAYERS} | {"experiments"}
    assert folders <= layers, folders - layers


def test_the_top_level_re_exports_exactly_its_subpackages_names():
    import drake_abs
    import drake_abs.contact
    import drake_abs.engine
    import drake_abs.lcp

    want = {
        *drake_abs.lcp.__all__,
        *drake_abs.contact.__all__,
        *drake_abs.engine.__all__,
        "point_mass_lcs",
    }
    assert set(drake_abs.__all__) == want
    assert all(hasattr(drake_abs, name) for name in want)
