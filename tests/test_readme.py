"""The README's Python blocks run as written, in order, in one namespace (as a reader would paste
them into one session); the README stays what a first visit needs (tests/test_docs.py checks its
links and the docs pages' blocks)."""

from __future__ import annotations

import re
from pathlib import Path

from markdown_blocks import python_blocks, run_python_blocks

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def test_readme_python_blocks_run():
    assert run_python_blocks(README, "README.md") >= 1


def test_readme_is_short_and_gives_the_two_commands():
    text = README.read_text()
    assert len(text.splitlines()) <= 300, "the README is a first visit's page: move detail to docs/"
    makefile = (ROOT / "Makefile").read_text()
    for target in ("demo", "test", "docs"):
        assert re.search(rf"^{target}:", makefile, flags=re.M), target
        assert f"make {target}" in text, target
    set_up = re.search(r"```bash\n(.*?)```", text, flags=re.S).group(1)
    assert re.search(r"^make demo\b", set_up, flags=re.M) and re.search(
        r"^make test\b", set_up, flags=re.M
    ), set_up
    # .ci/run runs the README's test command
    assert re.search(r"^make test$", (ROOT / ".ci" / "run").read_text(), flags=re.M)


def test_readme_example_is_a_drake_diagram_with_a_gradient():
    code = "\n".join(python_blocks(README))
    assert "AddComplementarityPlantSceneGraph" in code and "AutoDiffXd" in code
