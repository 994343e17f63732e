"""The layering promise: the numerical core imports no Drake."""

import subprocess
import sys


def test_core_imports_without_pydrake():
    code = (
        "import sys, drake_abs; "
        "drake_abs.solve_lcp([[1.0]], [0.5]); "
        "assert not any(m.startswith('pydrake') for m in sys.modules), 'pydrake imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_core_modules_do_not_import_upward():
    import pathlib

    core = pathlib.Path(__file__).resolve().parents[1] / "drake_abs"
    for path in core.glob("*.py"):
        text = path.read_text()
        for layer in (
            "pydrake",
            "drake_abs.systems",
            "drake_abs.diagrams",
            "drake_abs.experiments",
        ):
            assert f"import {layer}" not in text and f"from {layer}" not in text, (path, layer)
