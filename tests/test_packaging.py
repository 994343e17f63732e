"""The wheel built from the repository holds every package and the package data (issue 35,
item 8): packages are discovered (setup.py), not listed, so a new subpackage cannot be left out
of an install again; the build gives no setuptools warning about them. The build runs on a copy
of the tracked files in a temporary folder (a build writes build/ and *.egg-info beside the
sources), without build isolation (no download), in about 5 s."""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: What a build reads besides the package folders.
BUILD_FILES = ("pyproject.toml", "setup.py", "README.md", "LICENSE")


def _package_dir() -> dict[str, str]:
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]


def _tracked(folders: list[str]) -> list[str]:
    """The repository's files under ``folders`` (git's list: no caches, no results)."""
    out = subprocess.run(
        ["git", "ls-files", "-z", "--", *folders], cwd=ROOT, capture_output=True, check=True
    ).stdout.decode()
    return [f for f in out.split("\0") if f and (ROOT / f).is_file()]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> tuple[set[str], list[str], str]:
    """(the wheel's file names, the tracked source files, the build's output)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs a git checkout (the tracked files are what a wheel must hold)")
    src = tmp_path_factory.mktemp("source")
    files = _tracked(sorted(set(_package_dir().values())))
    for name in [*BUILD_FILES, *files]:
        (src / name).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / name, src / name)
    out = tmp_path_factory.mktemp("wheel")
    done = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "--no-build-isolation",
         "--no-cache-dir", "-v", "-w", str(out)],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    (built,) = out.glob("drake_abs-*.whl")
    with zipfile.ZipFile(built) as z:
        names = set(z.namelist())
    return names, files, done.stdout + done.stderr


def _installed_name(source: str) -> str:
    """Where a source file lands in the wheel (``systems/x.py`` -> ``drake_abs/systems/x.py``)."""
    for package, folder in sorted(_package_dir().items(), key=lambda kv: -len(kv[1])):
        if source.startswith(folder + "/"):
            return package.replace(".", "/") + source[len(folder) :]
    raise AssertionError(f"{source} is in no package folder")


def test_every_subpackage_and_module_is_in_the_wheel(wheel):
    names, files, _ = wheel
    folders = {str(Path(f).parent) for f in files if f.endswith(".py")}
    missing_packages = sorted(
        folder for folder in folders
        if not any(n.startswith(_installed_name(folder + "/__init__.py")) for n in names)
    )  # fmt: skip
    assert not missing_packages, missing_packages
    missing = sorted(_installed_name(f) for f in files if f.endswith(".py"))
    missing = [m for m in missing if m not in names]
    assert not missing, missing
    for package in ("learning", "engine", "systems", "diagrams", "experiments"):
        assert f"drake_abs/{package}/__init__.py" in names, package


def test_the_models_and_scenes_are_in_the_wheel(wheel):
    names, files, _ = wheel
    data = [f for f in files if f.startswith(("drake_abs/models/", "drake_abs/scenes/"))]
    assert any(f.endswith(".yaml") for f in data) and any(f.endswith(".sdf") for f in data)
    missing = [f for f in data if f not in names]
    assert not missing, missing


def test_the_build_warns_of_no_package_left_out(wheel):
    _, _, output = wheel
    assert "absent from the `packages` configuration" not in output
    assert "absent from setuptools' `packages` configuration" not in output


def test_the_dependencies_are_what_the_code_needs():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    core = [d.split(">")[0].split("[")[0].strip() for d in project["dependencies"]]
    assert "gymnasium" in core  # the shipped gym_* scenes read its model files
    assert "meshcat" not in core  # no module imports it (Drake's own Meshcat draws)
    assert "mujoco" not in core and "mujoco" in project["optional-dependencies"]
