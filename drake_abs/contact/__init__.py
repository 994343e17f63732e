"""Contact as a softened complementarity system: smoothing designs (how much mu per contact),
the linear complementarity system (LCS) and its stepper, the rigid-body time-stepping LCP
assembled from a model's mass matrix and contact Jacobians, and the one step record (``Step``).

Drake-free; builds on :mod:`drake_abs.lcp`.
"""

from drake_abs.contact.lcs import LCS, LcsStepper
from drake_abs.contact.smoothing import (
    ContactAware,
    Exact,
    Fixed,
    GaussianMatched,
    Smoothing,
    TimeStepScaled,
)
from drake_abs.contact.step import Step

__all__ = [
    "LCS",
    "ContactAware",
    "Exact",
    "Fixed",
    "GaussianMatched",
    "LcsStepper",
    "Smoothing",
    "Step",
    "TimeStepScaled",
]
