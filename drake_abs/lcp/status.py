"""The outcome codes of an LCP solve, defined once: the compiled kernel reports them as small
integers and :class:`LCPStatus` names them."""

from __future__ import annotations

from enum import IntEnum


class LCPStatus(IntEnum):
    """Outcome of one LCP solve."""

    CONVERGED = 0
    MAX_ITERATIONS = 1
    NUMERICAL_FAILURE = 2  # singular Newton matrix or a non-finite iterate; last finite kept
