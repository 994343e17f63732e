"""The Python blocks of a Markdown page (the README, the pages of docs/), run as a reader would
paste them into one session: in order, in one namespace per page.

A block is a fenced block whose info string is ``python``. A block that must not run here (it
needs a cluster or a display) is marked by the line ``<!-- no-run -->`` right before its fence;
use the marker sparingly.
"""

from __future__ import annotations

import re
from pathlib import Path

NO_RUN = "<!-- no-run -->"
_BLOCK = re.compile(r"(?:^(<!-- no-run -->)\n)?^```python\n(.*?)^```", flags=re.S | re.M)


def python_blocks(path: Path) -> list[str]:
    """The page's Python blocks to run, in order (those marked ``NO_RUN`` left out)."""
    return [code for marker, code in _BLOCK.findall(path.read_text()) if not marker]


def run_python_blocks(path: Path, label: str) -> int:
    """Run the page's Python blocks in order in one namespace; the number run. A failure names
    the page and the block."""
    namespace: dict = {"__name__": label}
    blocks = python_blocks(path)
    for i, block in enumerate(blocks):
        try:
            exec(compile(block, f"{label} python block {i + 1}", "exec"), namespace)
        except Exception as err:  # say which block failed
            raise AssertionError(f"{label} python block {i + 1} failed: {err!r}") from err
    return len(blocks)
