"""Training checkpoints: one pickle file holding a trainer's whole state, written atomically and
read back with its format name and version checked; and the one loop that runs a resumable
trainer (``iterate()``, ``save(path)``, ``state.iteration``, ``state.env_steps``, ``state.rows``)
to a budget with periodic checkpoints (:func:`~drake_abs.policy.checkpoints.train_resumable`).

A checkpoint is for this library's own use (it is not a published format: a policy ships as a
policy file, :mod:`drake_abs.policy.policy_files`), and like any pickle it should only be loaded
from a trusted source.
"""

from __future__ import annotations

import os
import pickle
import time
from pathlib import Path

from drake_abs._validation import as_count

__all__ = ["read_checkpoint", "train_resumable", "write_checkpoint"]


def write_checkpoint(path: str | Path, payload: dict, *, kind: str, version: int) -> Path:
    """Write ``payload`` (a dict of picklable values) to ``path`` as a checkpoint of format
    ``kind`` (e.g. ``"drake-abs ars checkpoint"``) and ``version``: a temporary file beside it,
    renamed over ``path`` (a reader never sees half a file). Returns the path."""
    if not isinstance(payload, dict) or {"format", "version"} & set(payload):
        raise ValueError("payload must be a dict without the keys 'format' and 'version'")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("wb") as f:
        pickle.dump({"format": kind, "version": int(version)} | payload, f,
                    protocol=pickle.HIGHEST_PROTOCOL)  # fmt: skip
    os.replace(tmp, path)
    return path


def read_checkpoint(path: str | Path, *, kind: str, version: int) -> dict:
    """The payload of the checkpoint at ``path``: ``ValueError`` if the file is not a checkpoint
    of format ``kind``, or was written by a newer ``version`` of that format."""
    try:
        with Path(path).open("rb") as f:
            payload = pickle.load(f)  # noqa: S301 (the library's own checkpoint)
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, OSError) as err:
        raise ValueError(f"path must be a {kind!r} file; got {path} ({err})") from err
    if not (isinstance(payload, dict) and payload.get("format") == kind):
        raise ValueError(f"path must be a {kind!r} file; got {path}")
    if payload.get("version", 0) > version:
        raise ValueError(
            f"path holds a {kind!r} of version {payload['version']}, newer than this library's "
            f"({version})"
        )
    return {k: v for k, v in payload.items() if k not in ("format", "version")}


def train_resumable(
    trainer,
    iterations: int,
    *,
    checkpoint: str | Path | None = None,
    checkpoint_every: int = 10,
    max_seconds: float | None = None,
    max_env_steps: int | None = None,
    callback=None,
) -> list[dict]:
    """Run ``trainer.iterate()`` until ``trainer.state.iteration == iterations`` (a resumed run
    continues to the same total), or ``max_seconds`` of wall time in this call have passed, or
    ``trainer.state.env_steps`` has reached ``max_env_steps`` (each checked after a whole
    iteration); ``trainer.save(checkpoint)`` every ``checkpoint_every`` iterations and at the
    end (with ``checkpoint``); ``callback(row)`` after each iteration. Returns the whole log,
    ``trainer.state.rows``."""
    iterations = as_count(iterations, "iterations")
    every = as_count(checkpoint_every, "checkpoint_every", minimum=1)
    if max_env_steps is not None:
        max_env_steps = as_count(max_env_steps, "max_env_steps", minimum=1)
    began = time.perf_counter()
    while trainer.state.iteration < iterations:
        if max_env_steps is not None and trainer.state.env_steps >= max_env_steps:
            break
        row = trainer.iterate()
        if callback is not None:
            callback(row)
        if checkpoint is not None and trainer.state.iteration % every == 0:
            trainer.save(checkpoint)
        if max_seconds is not None and time.perf_counter() - began >= max_seconds:
            break
    if checkpoint is not None:
        trainer.save(checkpoint)
    return trainer.state.rows
