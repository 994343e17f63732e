"""What every experiment shares: its results folder, its list of written files (absolute paths),
progress bars, and readable names for smoothing policies in plots.

Every experiment's entry point is ``run(config: Config | None = None, out: str | Path | None =
None) -> dict``; ``out=None`` means :func:`default_out` of the experiment's name, that is
``results/<name>`` under the current directory.

Progress bars (tqdm, on stderr) are on by default; :func:`set_progress` turns them off for the
process, and so does the environment variable ``DRAKE_ABS_PROGRESS=0``. They never change a
number.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path

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
