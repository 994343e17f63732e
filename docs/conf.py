"""Sphinx configuration: the drake-abs documentation site, with the API reference built from the
docstrings.

Build with ``make docs`` (``sphinx-build -E -W --keep-going -b html -n docs docs/_build/html``):
warnings are errors, and the build is nitpicky (``-n``), so every cross-reference into
drake-abs itself must resolve. References to *external* types (numpy, scipy, pydrake, numba,
the standard library beyond the builtins) cannot resolve, since the build has no network and so
no intersphinx inventories; ``nitpick_ignore_regex`` below ignores those targets only, never a
``drake_abs`` one.

Layout (``index.md`` has the table of contents): ``tutorials/`` (the notebooks, rendered by
myst-nb without executing them: ``make test`` runs them), ``howto/``, ``reference/`` (with
``api/``, where ``sphinx.ext.autosummary`` generates one page per public module, recursively,
from ``_templates/autosummary/module.rst``; modules whose names start with an underscore are left
out), ``explanations/`` and, at the top, ``math.md``, ``architecture.md``, ``policy_files.md`` and
``drake_users.md``. Pages are MyST Markdown; ``tests/test_docs.py`` runs every ``python`` block of
every page, as ``tests/test_readme.py`` does the README's.

Each object is documented once, at the module that defines it: autodoc ignores ``__all__`` and
imported names, so a package page lists what it re-exports without describing it twice, and
``_ext/drake_abs_sphinx.py`` resolves a reference to a re-exported name (``drake_abs.LCS``) to
the defining module's entry. The same extension renders Drake's ``.. pydrake_system::`` port
blocks and documents ``TemplateSystem.define`` LeafSystems (``LcsPlant`` = ``LcsPlant_[float]``)
with their constructor's real signature. ``_ext/drake_abs_reference.py`` generates the command
line's help and the scene schema's tables from the code, and copies the notebooks in.
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "_ext"))

project = "drake-abs"
author = "drake-abs contributors"
copyright = "drake-abs contributors, BSD-3-Clause"  # noqa: A001 (Sphinx's name)
try:
    from importlib.metadata import version as _version

    release = _version("drake-abs")
except Exception:  # pragma: no cover - the package is installed editable in .venv
    release = "0.2.0"
version = release

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "myst_nb",  # MyST Markdown pages (it includes myst_parser) and the notebooks
    "drake_abs_sphinx",
    "drake_abs_reference",
]

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**/.ipynb_checkpoints"]
templates_path = ["_templates"]

# -- autodoc / autosummary / napoleon ---------------------------------------------------------
autosummary_generate = True
autosummary_generate_overwrite = True
autosummary_imported_members = False
autosummary_ignore_module_all = True  # modules from the package tree, not from __all__

autodoc_default_options = {
    "members": True,
    "show-inheritance": True,
    # Document a name at the module that defines it, never again where it is re-exported.
    "ignore-module-all": True,
}
autodoc_member_order = "bysource"
# the optional baselines' libraries (the ``baselines`` extra) are not installed for the docs
autodoc_mock_imports = ["stable_baselines3", "sb3_contrib", "torch"]
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autoclass_content = "class"
python_use_unqualified_type_names = True  # "LCS", not "drake_abs.contact.lcs.LCS", in signatures

napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_include_init_with_doc = False
napoleon_use_rtype = False
napoleon_attr_annotations = True

# -- nitpicky mode (-n) ------------------------------------------------------------------------
# Only targets outside drake_abs are ignored: third-party and standard-library types that have
# no inventory here (no intersphinx: the build runs without network). A drake_abs target that
# does not resolve stays an error.
nitpick_ignore_regex = [
    (
        r"py:.*",
        r"(numpy|np|npt|scipy|sp|pydrake|numba|nb|osqp|pinocchio|pin"
        r"|mujoco|gymnasium|stable_baselines3|sb3_contrib|torch|matplotlib|yaml|meshcat|collections|typing|typing_extensions"
        r"|pathlib|os|io|enum|dataclasses|abc|functools|types|concurrent|multiprocessing"
        r"|warnings|argparse|json|contextlib)(\..*)?",
    ),
    # Private names (a leading underscore) are not part of the reference, so a public
    # signature's type hint or a docstring naming one cannot link to it.
    (r"py:.*", r"(drake_abs\.)?([\w.]+\.)?_\w+(\.\w+)*"),
]

# -- MyST and myst-nb (the pages and the notebooks) --------------------------------------------
myst_heading_anchors = 3
suppress_warnings = []
# The notebooks are rendered as stored (outputs cleared), never executed here: ``make test`` runs
# them (nbmake), and executing them would make the docs build take as long as the tests.
nb_execution_mode = "off"
nb_merge_streams = True

# -- HTML ---------------------------------------------------------------------------------------
html_theme = "alabaster"
html_title = f"drake-abs {release}"
html_static_path = ["_static"]
html_css_files = ["drake_abs.css"]  # tables wrap to the page width
html_theme_options = {
    "description": "Adaptive barrier smoothing: first-order gradients through contact, "
    "as Drake systems",
    "fixed_sidebar": True,
    "page_width": "1200px",
    "sidebar_width": "260px",
}
html_sidebars = {"**": ["about.html", "navigation.html", "relations.html", "searchbox.html"]}
