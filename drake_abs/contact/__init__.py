"""Contact as a softened complementarity system: smoothing policies (how much mu per contact),
the linear complementarity system (LCS) and its open-loop rollout, and the rigid-body
time-stepping LCP assembled from a model's mass matrix and contact Jacobians.

Drake-free; builds on :mod:`drake_abs.lcp`.
"""

from drake_abs.contact.lcs import LCS, StepResult
from drake_abs.contact.rollout import Rollout, rollout
from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, GaussianMatched, SmoothingPolicy

__all__ = [
    "LCS",
    "ContactAware",
    "Exact",
    "Fixed",
    "GaussianMatched",
    "Rollout",
    "SmoothingPolicy",
    "StepResult",
    "rollout",
]
