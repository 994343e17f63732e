"""Package discovery for setuptools (the rest of the configuration is in pyproject.toml).

Every package is found rather than listed: the packages under ``drake_abs/`` (namespace packages
included, so the data folders ``drake_abs/models`` and ``drake_abs/scenes`` are packages whose
files pyproject.toml's package-data installs), and the folders that pyproject.toml's
``package-dir`` maps into ``drake_abs`` (``systems/`` -> ``drake_abs.systems``, ...) with the
packages under them. pyproject.toml's ``[tool.setuptools]`` cannot say this itself: its ``find``
directive does not follow a ``package-dir`` mapping.
"""

import tomllib
from pathlib import Path

from setuptools import find_namespace_packages, setup

ROOT = Path(__file__).resolve().parent
#: never packages: byte-code caches
EXCLUDE = ["*__pycache__*"]


def discover_packages() -> list[str]:
    """Every package of the distribution: ``drake_abs`` and everything below it, then each
    folder pyproject.toml's ``package-dir`` maps to another package name, with its
    subpackages."""
    package_dir = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-dir"
    ]
    packages = find_namespace_packages(
        str(ROOT), include=["drake_abs", "drake_abs.*"], exclude=EXCLUDE
    )
    for name, folder in package_dir.items():
        if name == folder.replace("/", "."):  # the package where its name says: found above
            continue
        below = find_namespace_packages(str(ROOT / folder), exclude=EXCLUDE)
        packages += [name] + [f"{name}.{sub}" for sub in below]
    return sorted(set(packages))


setup(packages=discover_packages())
