"""Learning contact models from data (Bianchini et al. 2022; Zhang et al. 2023, section 6).

- :mod:`~drake_abs.learning.violation`: the violation-implicit loss for models affine in the
  impulses, batched, with its gradient in the parameters;
- :mod:`~drake_abs.learning.ground_toy`: the 1-D point mass whose ground height is learned, with
  its explicit, naive-implicit and violation-implicit losses;
- :mod:`~drake_abs.learning.generalization`: the losses' Lipschitz constants and the
  generalisation bound of Bianchini et al.'s Theorem 1.
"""

from drake_abs.learning.ground_toy import GroundToy
from drake_abs.learning.violation import ViolationLoss, complementarity_violation, violation_loss

__all__ = ["GroundToy", "ViolationLoss", "complementarity_violation", "violation_loss"]
