"""Reference pages generated from the code at build time, so that they cannot go stale
(``docs/conf.py``).

1. ``drake-abs-help``: the ``--help`` text of the ``drake-abs`` command or of one of its
   subcommands, from :func:`drake_abs.experiments.cli.build_parser` (``docs/reference/cli.md``).
   The argument is the subcommand (none: the command itself).
2. ``scene-keys``: the keys of one scene dataclass (:class:`drake_abs.multibody.scene.Scene`, its
   entries, the kinds of smoothing and of contact law) as a table of key, form, default and
   meaning, from the fields :func:`drake_abs.multibody.scene_entries.key` made
   (``docs/reference/scene_schema.md``). The argument is the class's dotted path. The table is
   reStructuredText (the fields' explanations use roles), so the directive is used inside an
   ``eval-rst`` block.
3. ``copy_notebooks``: ``notebooks/*.ipynb`` copied into ``docs/tutorials/notebooks/`` (ignored
   by git; a cell without an id, which nbformat 4.5 requires, is given one), where Sphinx
   (myst-nb, not executing them) renders them as the tutorials.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import math
import os
import shutil
from pathlib import Path
from typing import Any

from docutils import nodes
from docutils.parsers.rst import Directive
from docutils.statemachine import StringList
from sphinx.application import Sphinx
from sphinx.util.docutils import switch_source_input

ROOT = Path(__file__).resolve().parents[2]
HELP_COLUMNS = 90  # the help text's width, whatever the terminal building the docs


# -- 1. drake-abs --help ----------------------------------------------------------------------
def subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The subcommands of ``parser`` by name (empty when it has none)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def help_text(command: str = "") -> str:
    """``drake-abs [COMMAND] --help``, formatted ``HELP_COLUMNS`` wide."""
    from drake_abs.experiments.cli import build_parser

    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(HELP_COLUMNS)
    try:
        parser = build_parser()
        if command:
            parser = subcommands(parser)[command]
        return parser.format_help()
    finally:
        if saved is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = saved


class DrakeAbsHelpDirective(Directive):
    """``drake-abs-help`` with an optional argument, the subcommand."""

    optional_arguments = 1

    def run(self) -> list[nodes.Node]:
        command = self.arguments[0] if self.arguments else ""
        try:
            text = help_text(command)
        except KeyError as exc:
            raise self.error(f"drake-abs-help: no subcommand {command!r}") from exc
        block = nodes.literal_block(text, text)
        block["language"] = "none"
        return [block]


# -- 2. scene keys --------------------------------------------------------------------------------
def _yaml_value(value: Any) -> str:
    """A default as a scene file would write it."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and math.isinf(value):
        return ".inf" if value > 0 else "-.inf"
    if isinstance(value, tuple | list):
        return "[" + ", ".join(_yaml_value(v) for v in value) + "]"
    if isinstance(value, str):
        return value
    if dataclasses.is_dataclass(value):
        kind = getattr(value, "kind", None)
        given = {
            f.name: getattr(value, f.name)
            for f in dataclasses.fields(value)
            if getattr(value, f.name) != f.default
        }
        items = ([f"kind: {kind}"] if kind else []) + [
            f"{k}: {_yaml_value(v)}" for k, v in given.items()
        ]
        return "{" + ", ".join(items) + "}"
    return repr(value)


def key_rows(cls: type) -> list[tuple[str, str, str, str]]:
    """(key, form, default, meaning) of every key of the scene dataclass ``cls``."""
    rows = []
    for f in dataclasses.fields(cls):
        if "form" not in f.metadata:
            continue
        if f.default is not dataclasses.MISSING:
            default = f"``{_yaml_value(f.default)}``"
        elif f.default_factory is not dataclasses.MISSING:
            default = f"``{_yaml_value(f.default_factory())}``"
        else:
            default = "required"
        rows.append((f"``{f.name}``", f.metadata["form"], default, f.metadata["doc"] or ""))
    return rows


class SceneKeysDirective(Directive):
    """``scene-keys`` with one argument, the dataclass's dotted path."""

    required_arguments = 1

    def run(self) -> list[nodes.Node]:
        module, _, name = self.arguments[0].rpartition(".")
        try:
            cls = getattr(importlib.import_module(module), name)
        except (ImportError, AttributeError) as exc:
            raise self.error(f"scene-keys: cannot import {self.arguments[0]}") from exc
        rows = key_rows(cls)
        if not rows:
            kind = getattr(cls, "kind", "")
            text = f"``kind: {kind}`` takes no other key." if kind else "No keys."
            lines = [text]
        else:
            lines = [
                ".. list-table::",
                "   :header-rows: 1",
                "   :widths: 14 30 14 42",
                "",
                "   * - key",
                "     - value",
                "     - default",
                "     - meaning",
            ]
            for key, form, default, doc in rows:
                lines += [
                    f"   * - {key}",
                    f"     - {form}",
                    f"     - {default}",
                    f"     - {doc}",
                ]
        content = StringList(lines, source=f"scene-keys {self.arguments[0]}")
        container = nodes.container()
        # the explanations' roles are relative to the class (``:class:`InitialState```,
        # ``:meth:`make_smoothing```), as in its docstring
        context = self.state.document.settings.env.ref_context
        saved = {k: context.get(k) for k in ("py:module", "py:class")}
        context.update({"py:module": module, "py:class": name})
        try:
            with switch_source_input(self.state, content):
                self.state.nested_parse(content, 0, container)
        finally:
            for k, v in saved.items():
                if v is None:
                    context.pop(k, None)
                else:
                    context[k] = v
        return container.children


# -- 3. the notebooks -----------------------------------------------------------------------------
def copy_notebooks(app: Sphinx) -> None:
    """``notebooks/*.ipynb`` into ``docs/tutorials/notebooks/``, replacing what was there."""
    target = Path(app.srcdir) / "tutorials" / "notebooks"
    if target.exists():
        shutil.rmtree(target)
    target.mkdir(parents=True)
    for notebook in sorted((ROOT / "notebooks").glob("*.ipynb")):
        nb = json.loads(notebook.read_text())
        for i, cell in enumerate(nb["cells"]):  # the cell ids nbformat 4.5 requires
            cell.setdefault("id", f"cell-{i}")
        nb["nbformat_minor"] = max(nb["nbformat_minor"], 5)
        (target / notebook.name).write_text(json.dumps(nb, indent=1) + "\n")


def setup(app: Sphinx) -> dict[str, Any]:
    app.add_directive("drake-abs-help", DrakeAbsHelpDirective)
    app.add_directive("scene-keys", SceneKeysDirective)
    app.connect("builder-inited", copy_notebooks)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
