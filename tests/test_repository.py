"""The repository stands alone: its licence, citation and formula document are present and
consistent, every formula section the code cites exists, and nothing points outside the
repository."""

from __future__ import annotations

import re
import subprocess
import tomllib
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
MATH = ROOT / "docs" / "math.md"


def _tracked(*suffixes: str) -> list[Path]:
    out = subprocess.run(
        ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    return [ROOT / f for f in out if f.endswith(suffixes) and (ROOT / f).is_file()]


def test_licence_matches_pyproject_and_is_bsd3():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "BSD-3-Clause"
    text = (ROOT / "LICENSE").read_text()
    assert "Redistribution and use in source and binary forms" in text
    assert "Neither the name of the copyright holder" in text  # the third clause


def test_citation_lists_the_software_and_the_four_papers():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert cff["cff-version"] and cff["type"] == "software" and cff["license"] == "BSD-3-Clause"
    titles = [r["title"] for r in cff["references"]]
    assert len(titles) == 4
    for ref in cff["references"]:
        assert ref["authors"] and all(a.get("family-names") for a in ref["authors"])
    math = MATH.read_text()
    for title in titles:  # the formula document names the same papers
        assert title in " ".join(math.split()), title


def test_every_cited_math_section_exists():
    headings = set(re.findall(r"^#{2,3} (\d+b?)\.", MATH.read_text(), flags=re.M))
    cited = set()
    for path in _tracked(".py", ".md", ".ipynb"):
        text = path.read_text()
        for m in re.finditer(r"docs/math\.md,? sections? (\d+b?)(?: and (\d+b?))?", text):
            cited.update(g for g in m.groups() if g)
    assert cited, "no docstring cites docs/math.md"
    assert cited <= headings, f"cited but missing in docs/math.md: {sorted(cited - headings)}"


def test_nothing_points_outside_the_repository():
    outside = re.compile(r"\.\./shared|shared/(design|papers)|\bMATH\.md|\bFACTS\.md|STYLE\.md")
    bad = [
        f"{p.relative_to(ROOT)}:{i}"
        for p in _tracked(".py", ".md", ".ipynb", ".yaml", ".toml", ".cff", "Makefile", "run")
        if p.name != "test_repository.py"
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if outside.search(line)
    ]
    assert not bad, bad


def test_test_module_names_are_unique():
    """pytest imports test modules by basename (no __init__.py in tests/): two folders with the
    same test file name break collection."""
    from collections import Counter

    root = Path(__file__).resolve().parent
    names = Counter(p.name for p in root.rglob("test_*.py"))
    assert not [n for n, c in names.items() if c > 1], names.most_common(3)
