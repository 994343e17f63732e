"""What every experiment shares: its results folder, its list of written files (absolute paths),
progress bars, readable names for smoothing designs in plots, and the writers of its figures,
tables, CSV and JSON files.

Every experiment's entry point is ``run(config: Config | None = None, out: str | Path | None =
None) -> dict``; ``out=None`` means :func:`default_out` of the experiment's name, that is
``results/<name>`` under the current directory.

Progress bars (tqdm, on stderr) are on by default; :func:`set_progress` turns them off for the
process, and so does the environment variable ``DRAKE_ABS_PROGRESS=0``. They never change a
number.
"""

from __future__ import annotations

import csv
import json
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

#: The folder (relative to the current directory) that holds every experiment's default output.
RESULTS = Path("results")

_progress_enabled = os.environ.get("DRAKE_ABS_PROGRESS", "1").strip().lower() not in (
    "0",
    "false",
    "no",
    "off",
)


def default_out(name: str) -> Path:
    """The default results folder of experiment ``name`` (e.g. ``"gradient-variance"``), as an
    absolute path: ``results/<name>`` under the current directory."""
    return (RESULTS / name).resolve()


def results_dir(name: str, out: str | Path | None) -> Path:
    """``out`` (or, when None, :func:`default_out` of ``name``) as an absolute folder, created."""
    folder = default_out(name) if out is None else Path(out).expanduser().resolve()
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def file_list(files: Mapping[str, str | Path]) -> dict[str, str]:
    """Name -> absolute path string of each written file."""
    return {key: str(Path(path).resolve()) for key, path in files.items()}


def set_progress(enabled: bool) -> None:
    """Turn the experiments' progress bars on or off for this process."""
    global _progress_enabled
    _progress_enabled = bool(enabled)


def progress_enabled() -> bool:
    return _progress_enabled


def progress(iterable: Iterable | None = None, *, total: int | None = None, desc: str = ""):
    """A tqdm progress bar on stderr (shown after a second, removed when done), or a silent one
    when progress is off. Use as an iterable wrapper or call ``update()`` on it."""
    from tqdm.std import tqdm

    return tqdm(
        iterable,
        total=total,
        desc=desc,
        file=sys.stderr,
        leave=False,
        delay=1.0,
        mininterval=0.5,
        dynamic_ncols=True,
        disable=not _progress_enabled,
    )


def readable(name: str) -> str:
    """A readable legend entry for the case names the experiments use as keys (``"BS mu=1e-2"``,
    ``"ABS contact-aware (total)"``, ``"bs_mu=0.001"``, ``"gamma=0.5"``...)."""
    text = name
    for prefix in ("BS mu=", "bs_mu=", "BS mu ="):
        if text.startswith(prefix):
            return f"barrier smoothing, mu = {text[len(prefix) :].strip()}"
    replacements = (
        ("ABS contact-aware", "adaptive (ABS), contact-aware"),
        ("ABS Gaussian-matched", "adaptive (ABS), Gaussian-matched"),
        ("abs_contact_aware", "adaptive (ABS), contact-aware"),
        ("abs_gaussian", "adaptive (ABS), Gaussian-matched"),
    )
    for old, new in replacements:
        if text.startswith(old):
            text = new + text[len(old) :]
            break
    text = text.replace(" (frozen)", ", frozen-mu gradient").replace(" (total)", ", total gradient")
    return text


# ------------------------------------------------------------------------------------------------
# Figures, tables and files the experiments write (matplotlib on the Agg backend: files only)


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend (no window; figures are written to files)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | Path, dpi: int = 120) -> Path:
    """Lay ``fig`` out tightly, write it to ``path`` at ``dpi`` dots per inch, close it; returns
    the path."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return Path(path)


def write_csv(path: str | Path, rows: Iterable, header: Sequence[str] | None = None) -> Path:
    """Write ``rows`` to the CSV file ``path``; returns the path. Rows are dicts (the columns:
    ``header``, or the first row's keys) or sequences under ``header``."""
    rows = list(rows)
    if header is None:
        if not rows or not isinstance(rows[0], Mapping):
            raise ValueError("header must be given unless rows are dicts (at least one)")
        header = list(rows[0])
    with Path(path).open("w", newline="") as f:
        if rows and isinstance(rows[0], Mapping):
            writer = csv.DictWriter(f, fieldnames=list(header))
            writer.writeheader()
        else:
            writer = csv.writer(f)
            writer.writerow(header)
        writer.writerows(rows)
    return Path(path)


def markdown_table(header: Sequence[str], rows: Iterable[Sequence]) -> list[str]:
    """The lines of a markdown table: ``header``, then one line per row (cells as ``str``)."""
    lines = ["| " + " | ".join(map(str, header)) + " |", "|" + " --- |" * len(header)]
    return lines + ["| " + " | ".join(map(str, row)) + " |" for row in rows]


def write_json(path: str | Path, data, indent: int = 2, finite: bool = False) -> Path:
    """Write ``data`` as JSON to ``path`` (numpy scalars as floats); ``finite``: NaN and inf as
    null. Returns the path."""
    text = json.dumps(data, indent=indent, default=float)
    if finite:
        text = json.dumps(json.loads(text, parse_constant=lambda _: None), indent=indent)
    Path(path).write_text(text)
    return Path(path)


def write_provenance(folder: str | Path, command: str, config: Any = None) -> Path:
    """Write ``provenance.json`` to ``folder``: what produced the results there. ``command``
    (e.g. ``"experiment gradient-variance"``), the whole resolved ``config`` (a dataclass,
    every default included) and :func:`drake_abs.parallel.provenance.provenance` (the drake-abs
    version, the git commit and whether the tree had uncommitted changes, the versions of the
    libraries that compute the numbers). Returns the path."""
    import dataclasses

    from drake_abs.parallel.provenance import provenance

    resolved = dataclasses.asdict(config) if dataclasses.is_dataclass(config) else config
    record = {"command": command, "config": json.loads(json.dumps(resolved, default=str))}
    return write_json(Path(folder) / "provenance.json", record | provenance())
