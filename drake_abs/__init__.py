"""drake-abs: adaptive barrier smoothing for first-order gradients through contact.

The numerical core (this package's top level) needs no Drake: numpy/scipy, batched over a leading
dimension. Drake systems live in :mod:`drake_abs.systems`, diagram builders in
:mod:`drake_abs.diagrams`, experiments and the CLI in :mod:`drake_abs.experiments`.

Direction of smoothing, everywhere in this package: **a larger mu means more smoothing**;
``mu = 0`` is hard contact.

Threads: the core solves many small dense systems, where a multi-threaded BLAS only adds
overhead and, on a machine whose cores are busy, stalls badly (measured here: a 128 x 128
inverse took 150 ms with two OpenBLAS threads on two shared cores, 1 ms with one). Importing
this package before numpy therefore defaults ``OPENBLAS_NUM_THREADS`` to 1; a value you set
yourself is kept. Batches are where the core's parallelism lives.
"""

import os
import sys

if "numpy" not in sys.modules:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from drake_abs.closed_form import softened_lcp_1d
from drake_abs.ipm import (
    LCPConvergenceError,
    LCPConvergenceWarning,
    LCPRegularizationWarning,
    LCPResult,
    LCPStatus,
    solve_lcp,
)
from drake_abs.lcs import LCS, StepResult
from drake_abs.matrix_class import MatrixClass
from drake_abs.point_mass import point_mass_lcs
from drake_abs.rollout import Rollout, rollout
from drake_abs.smoothing import ContactAware, Exact, Fixed, GaussianMatched, SmoothingPolicy

__all__ = [
    "LCS",
    "ContactAware",
    "Exact",
    "Fixed",
    "GaussianMatched",
    "LCPConvergenceError",
    "LCPConvergenceWarning",
    "LCPRegularizationWarning",
    "LCPResult",
    "LCPStatus",
    "MatrixClass",
    "Rollout",
    "SmoothingPolicy",
    "StepResult",
    "point_mass_lcs",
    "rollout",
    "softened_lcp_1d",
    "solve_lcp",
]
