"""Drake's model-file parser warnings, reported once per file per process, with what drake-abs
does about each.

Drake's parsers warn, through the Python logger ``drake``, about every part of a model file they
ignore: for gymnasium's MuJoCo files the solver options (``<option timestep integrator>``),
visual elements (``<visual>``, ``<light>``, ``<texture>``, ``<camera>``), joint ``stiffness``,
the geoms' ``condim=1``, ``contype``/``conaffinity`` filters and torsional and rolling friction.
They do so at every parse, and a run parses the same file many times (a plant per task, per
worker, per visualisation): a test-size ``drake-abs experiment locomotion`` printed 430 such
lines through its progress bars, 13 to 30 per parse of the Hopper and HalfCheetah files.

:func:`drake_parser_messages` holds Drake's warnings back while a file is parsed (a filter on
the ``drake`` logger: the records are kept, not printed), and :func:`report_parser_messages`
logs them as one summary per file (``logging.getLogger("drake_abs.multibody.parser_messages")``,
level WARNING), grouped by kind and stating for each whether drake-abs models the part itself
(MJCF joint springs and ``frictionloss``), leaves it out as Drake does (torsional and rolling
friction, URDF joint friction), or does not need it (the solver options: the step is the
scene's; visual elements; the geoms' contact settings, since the scene declares its contact
candidates and their friction). A later parse of the same file reports only what it adds (none,
usually). Set :data:`REPORT_ONCE` to False to let Drake's own messages through instead.

Only records of the ``drake`` logger at level WARNING are held; errors pass (and Drake raises
for them). Drake's C++ messages reach Python only under pydrake's default logging (not after
``pydrake.common.use_native_cpp_logging()``), and only if the ``drake`` logger's level lets
warnings through.
"""

from __future__ import annotations

import contextlib
import logging
import re
from collections.abc import Iterator, Sequence
from pathlib import Path

#: Summarise Drake's parser warnings once per file per process; False lets Drake's own messages
#: through.
REPORT_ONCE = True

LOGGER = logging.getLogger(__name__)

#: The messages already reported in this process, by model file (resolved path).
_REPORTED: dict[str, set[str]] = {}

_PREFIX = re.compile(r"^.*?:\d+: warning: ", re.DOTALL)

#: The MJCF elements and attributes that only change how a model looks.
VISUAL = frozenset({"visual", "light", "texture", "camera", "material", "skybox", "texturedir",
                    "rgba", "headlight", "map", "quality", "global"})  # fmt: skip

#: Notes on Drake's messages by kind: (pattern of the message, kind, what drake-abs does).
_KINDS = (
    (
        r"The attribute '(?P<item>\w+)' found in a 'option' tag",
        "<option> attributes",
        "not used by drake-abs either: the step is the scene's (its time_step), not MuJoCo's "
        "solver",
    ),
    (
        r"The attribute '(?P<item>stiffness|springref)' found in a 'joint' tag",
        "joint attributes",
        "read by drake-abs: hinge and slide joint springs, built as Drake spring force "
        "elements{springs}",
    ),
    (
        r"The attribute '(?P<item>frictionloss)' found in a 'joint' tag",
        "joint attributes",
        "read by drake-abs: dry joint friction, complementarity rows of the step{friction}",
    ),
    (
        r"geom (?P<item>\S+) specified condim=(?P<n>\d+), which is not supported",
        "geoms with condim={n} (Drake uses condim=3)",
        "not used by drake-abs's hard contact: its contacts are the scene's declared candidates, "
        "with the scene's friction (the soft-contact option reads the geoms' condim)",
    ),
    (
        r"geom (?P<item>\S+) specified contype=\d+ and conaffinity=\d+; but collision filter",
        "geoms with contype/conaffinity filters (Drake has no collision filter groups for MJCF)",
        "not needed by drake-abs: the scene declares which candidates touch what",
    ),
    (
        r"The torsional and rolling friction specified in the friction attribute of geom",
        "geoms' torsional and rolling friction",
        "not modelled by drake-abs either: its friction is sliding friction only",
    ),
    (
        r"A joint has specified a non-zero value for the 'friction' attribute of a joint/dynamics",
        "URDF joints' <dynamics friction>",
        "not modelled by drake-abs either (MJCF frictionloss is; a URDF's joint friction is not)",
    ),
)

#: Drake's messages about an element or attribute it ignores, with its name.
_IGNORED = (
    re.compile(
        r"The attribute '(?P<item>\w+)' found in a '(?P<tag>\w+)' tag is currently "
        r"unsupported"
    ),  # fmt: skip
    re.compile(r"The tag '(?P<item>\w+)' found as a child of '\w+' is currently unsupported"),
    re.compile(r"The (?P<item>\w+) element is not supported"),
    re.compile(r"(?P<item>camera) element ignored"),
)


class _Held(logging.Filter):
    """A filter on the ``drake`` logger that keeps its WARNING records' messages and stops
    them (other levels pass)."""

    def __init__(self) -> None:
        super().__init__()
        self.messages: list[str] = []

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno != logging.WARNING:
            return True
        self.messages.append(record.getMessage())
        return False


@contextlib.contextmanager
def drake_parser_messages() -> Iterator[list[str]]:
    """Hold back the ``drake`` logger's warnings inside the ``with`` block (a parse): yields
    the list that receives their messages. Does nothing (an empty list) when
    :data:`REPORT_ONCE` is False."""
    if not REPORT_ONCE:
        yield []
        return
    held = _Held()
    logger = logging.getLogger("drake")
    logger.addFilter(held)
    try:
        yield held.messages
    finally:
        logger.removeFilter(held)


def _text(message: str) -> str:
    """A message without its ``file:line: warning:`` prefix (the parsed file may be a temporary
    copy), first line only (an inertia warning runs over several)."""
    lines = _PREFIX.sub("", message, count=1).strip().splitlines()
    return lines[0] if lines else ""


def _count(n: int | None, what: str, dropped: Sequence[str], attribute: str, key: str) -> str:
    """The parenthesis a note ends with: how many the file has (``" (6 with stiffness > 0 in
    this file)"``), or that the scene's ignore dropped them; empty when unknown."""
    if any(f"{attribute}=" in line for line in dropped):
        return f" (none here: the scene's ignore lists {key})"
    return "" if n is None else f" ({n} {what} in this file)"


def summarise_parser_messages(
    path: str | Path, messages: Sequence[str], *, springs: int | None = None,
    friction: int | None = None, dropped: Sequence[str] = (),
) -> str:  # fmt: skip
    """The report of Drake's parser ``messages`` about the model file ``path``: one line per
    kind of ignored part with how many and what drake-abs does about it (module docstring),
    visual elements on one line, other messages verbatim (without their ``file:line`` prefix),
    each once.

    Args:
        path: the model file (named in the report's first line).
        messages: Drake's warnings, as logged.
        springs: joint springs drake-abs built from the file (MJCF: stiffness > 0), or None
            (unknown).
        friction: dry joint friction rows it read (``frictionloss`` > 0), or None (unknown).
        dropped: what the scene's ``ignore`` dropped from the file
            (:attr:`drake_abs.multibody.model_files.MjcfInfo.dropped`), so that a note does
            not claim as modelled what was dropped.
    """
    counts = {
        "springs": _count(springs, "with stiffness > 0", dropped, "stiffness", "joint.stiffness"),
        "friction": _count(
            friction, "with frictionloss > 0", dropped, "frictionloss", "joint.frictionloss"
        ),
    }
    groups: dict[tuple[str, str], list[str]] = {}
    visual: list[str] = []
    other: list[str] = []
    for message in messages:
        text = _text(message)
        for pattern, kind, note in _KINDS:
            m = re.search(pattern, text)
            if m is not None:
                key = (kind.format(**m.groupdict()), note.format(**counts))
                groups.setdefault(key, []).append(m["item"] if "item" in m.groupdict() else "")
                break
        else:
            ignored = next((m for m in (p.search(text) for p in _IGNORED) if m is not None), None)
            if ignored is not None and ignored["item"] in VISUAL:
                visual.append(ignored["item"])
            elif text not in other:
                other.append(text)
    lines = [f"Drake's parser ignored parts of {path} ({_warnings(len(messages))}, summarised "
             "once per file and process):"]  # fmt: skip
    for (kind, note), items in groups.items():
        named = [i for i in dict.fromkeys(items) if i]
        what = f"{kind}: {', '.join(repr(i) for i in named)}" if named else kind
        lines.append(f"  - {what} ({_warnings(len(items))}): {note}")
    if visual:
        names = ", ".join(dict.fromkeys(visual))
        lines.append(f"  - visual only, no effect on the dynamics: {names}")
    lines += [f"  - {text}" for text in other]
    return "\n".join(lines)


def _warnings(n: int) -> str:
    return f"{n} warning" if n == 1 else f"{n} warnings"


def report_parser_messages(
    path: str | Path, messages: Sequence[str], *, springs: int | None = None,
    friction: int | None = None, dropped: Sequence[str] = (),
) -> str | None:  # fmt: skip
    """Log (WARNING) the :func:`summarise_parser_messages` report of those of ``messages``
    about ``path`` that this process has not reported yet (the other arguments as there);
    returns the report, or None when nothing is new."""
    key = str(Path(path).resolve())
    seen = _REPORTED.setdefault(key, set())
    new = [m for m in messages if _text(m) not in seen]
    if not new:
        return None
    seen.update(_text(m) for m in new)
    report = summarise_parser_messages(
        path, new, springs=springs, friction=friction, dropped=dropped
    )
    LOGGER.warning("%s", report)
    return report
