"""Drawings of Drake diagrams (the block diagrams of Drake's course notes), rendered with
Graphviz through pygraphviz, whose wheels bundle Graphviz (no system package is needed)."""

from __future__ import annotations

from pathlib import Path

from pydrake.systems.framework import System


def diagram_svg(system: System, *, max_depth: int | None = 1) -> str:
    """The SVG drawing (text) of ``system``'s Graphviz description
    (``system.GetGraphvizString``), sub-diagrams expanded ``max_depth`` levels (None: all)."""
    import pygraphviz

    if not isinstance(system, System):
        raise ValueError(f"system must be a Drake System; got {type(system).__name__}")
    dot = system.GetGraphvizString(max_depth=-1 if max_depth is None else int(max_depth))
    return pygraphviz.AGraph(dot).draw(format="svg", prog="dot").decode()


def save_diagram_svg(system: System, path: str | Path, *, max_depth: int | None = 1) -> Path:
    """Write :func:`diagram_svg` to ``path`` (its folder is created); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(diagram_svg(system, max_depth=max_depth))
    return path


def show_diagram(system: System, *, max_depth: int | None = 1):
    """The drawing as an IPython SVG object (a notebook cell's last line displays it)."""
    from IPython.display import SVG

    return SVG(diagram_svg(system, max_depth=max_depth))
