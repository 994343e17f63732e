"""The mu-softened linear complementarity problem: the batched primal-dual interior-point solver,
its implicit-function-theorem Jacobians, the one-contact closed form and matrix classes; and
named hard LCPs for the tests and benchmarks (:mod:`drake_abs.lcp.problems`).

Numbers only (numpy, scipy, numba); every other layer builds on this one.
"""

from drake_abs.lcp.closed_form import softened_lcp_1d
from drake_abs.lcp.ipm import (
    LCPConvergenceError,
    LCPConvergenceWarning,
    LCPRegularizationWarning,
    LCPResult,
    LCPStatus,
    solve_lcp,
)
from drake_abs.lcp.matrix_class import MatrixClass

__all__ = [
    "LCPConvergenceError",
    "LCPConvergenceWarning",
    "LCPRegularizationWarning",
    "LCPResult",
    "LCPStatus",
    "MatrixClass",
    "softened_lcp_1d",
    "solve_lcp",
]
