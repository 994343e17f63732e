"""The documentation site's pages (docs/, built by ``make docs``, which CI runs) hold what they
show: every Python block of every page runs as written, every relative link of the pages and of
the README points at a file (and a heading) that exists, the command line reference names only
commands and options the parser has, and every notebook is a tutorial."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from markdown_blocks import python_blocks, run_python_blocks

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
README = ROOT / "README.md"
_GENERATED = ("_build", "api/generated", "tutorials/notebooks")


def _pages() -> list[Path]:
    return sorted(
        p
        for p in DOCS.rglob("*.md")
        if not any(p.relative_to(DOCS).as_posix().startswith(g) for g in _GENERATED)
    )


PAGES = _pages()
PAGES_WITH_CODE = [p for p in PAGES if python_blocks(p)]


def _name(page: Path) -> str:
    return page.relative_to(ROOT).as_posix()


def test_the_site_has_its_four_sections():
    index = (DOCS / "index.md").read_text()
    for caption in ("Tutorials", "How-to guides", "Reference", "Explanations"):
        assert f":caption: {caption}" in index, caption
    assert len(PAGES_WITH_CODE) >= 8, [_name(p) for p in PAGES_WITH_CODE]


@pytest.mark.parametrize("page", PAGES_WITH_CODE, ids=_name)
def test_page_python_blocks_run(page):
    assert run_python_blocks(page, _name(page)) >= 1


# -- links -----------------------------------------------------------------------------------
_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
_FENCE = re.compile(r"^```.*?^```", flags=re.S | re.M)


def slug(heading: str) -> str:
    """A heading's anchor, as GitHub and MyST (``myst_heading_anchors``) make it."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower().replace(" ", "-"))


def _anchors(page: Path) -> set[str]:
    text = _FENCE.sub("", page.read_text())
    return {slug(h) for h in re.findall(r"^#{1,6} (.+)$", text, flags=re.M)}


def _relative_links(page: Path) -> list[str]:
    text = _FENCE.sub("", page.read_text())
    text = re.sub(r"`[^`\n]*`", "", text)  # code spans are not links
    return [t for t in _LINK.findall(text) if not re.match(r"[a-z][a-z0-9+.-]*:", t)]


@pytest.mark.parametrize("page", [README, *PAGES], ids=_name)
def test_relative_links_resolve(page):
    bad = []
    for target in _relative_links(page):
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if path.startswith("notebooks/") and page.parent == DOCS / "tutorials":
            file = ROOT / path  # the tutorials' notebooks are copied in at build time
        if not file.exists():
            bad.append(f"{target}: no file {file}")
        elif anchor and file.suffix == ".md" and anchor not in _anchors(file):
            bad.append(f"{target}: no heading #{anchor} in {file.name}")
    assert not bad, bad


def test_readme_links_to_every_section_of_the_site():
    linked = {(README.parent / t.partition("#")[0]).resolve() for t in _relative_links(README)}
    for page in ("tutorials/getting_started.md", "drake_users.md", "howto/own_robot.md"):
        assert (DOCS / page).resolve() in linked, page
    for folder in ("howto", "explanations", "reference"):
        assert any(p.parent == DOCS / folder for p in linked), folder


# -- the command line reference --------------------------------------------------------------
def _cli():
    from drake_abs.experiments.catalog import EXPERIMENTS
    from drake_abs.experiments.cli import build_parser

    parser = build_parser()
    for action in parser._actions:
        if hasattr(action, "choices") and isinstance(action.choices, dict):
            return parser, action.choices, EXPERIMENTS
    raise AssertionError("drake-abs has no subcommands")


def test_cli_reference_shows_every_subcommands_help():
    _, commands, _ = _cli()
    text = (DOCS / "reference" / "cli.md").read_text()
    shown = set(re.findall(r"^```\{drake-abs-help\} ?(\S*)$", text, flags=re.M))
    assert shown == {"", *commands}, shown ^ {"", *commands}


def test_cli_reference_names_only_existing_commands_and_options():
    parser, commands, experiments = _cli()
    text = (DOCS / "reference" / "cli.md").read_text()
    glance = re.search(r"## Commands at a glance\n+```bash\n(.*?)```", text, flags=re.S).group(1)
    lines = [ln.split("#")[0].split() for ln in glance.splitlines() if ln.strip()]
    assert len(lines) >= 20
    names = {n.replace("_", "-") for n in experiments}
    for words in lines:
        assert words[0].endswith("drake-abs"), words
        if words[1].startswith("--"):
            assert words[1] in parser._option_string_actions, words
            continue
        assert words[1] in commands, words
        sub = commands[words[1]]
        options = [w.strip("[]|") for w in words[2:] if w.strip("[]|").startswith("--")]
        for option in options:
            assert option.split("=")[0] in sub._option_string_actions, (words, option)
        if words[1] in ("experiment", "sweep") and len(words) > 2 and not words[2].isupper():
            if not words[2].startswith("-"):
                assert words[2] in names, words


def test_every_notebook_is_a_tutorial():
    toc = (DOCS / "tutorials" / "index.md").read_text()
    for notebook in sorted((ROOT / "notebooks").glob("*.ipynb")):
        assert f"notebooks/{notebook.stem}\n" in toc, notebook.name
