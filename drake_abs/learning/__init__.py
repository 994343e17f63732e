"""Learning contact models from data (Bianchini et al. 2022; Zhang et al. 2023, section 6).

- :mod:`~drake_abs.learning.violation`: the violation-implicit loss for models affine in the
  impulses, batched, with its gradient in the parameters;
- :mod:`~drake_abs.learning.ground_toy`: the 1-D point mass whose ground height is learned, with
  its explicit, naive-implicit and violation-implicit losses;
- :mod:`~drake_abs.learning.ground_height_fit`: the toy's height learned from data: near-ground
  data, mean losses and their landscapes, the fitted height and gradient descent;
- :mod:`~drake_abs.learning.generalization`: the losses' Lipschitz constants and the
  generalisation bound of Bianchini et al.'s Theorem 1;
- :mod:`~drake_abs.learning.scene_losses`: the explicit (eq. 6.1 of Zhang et al.), naive-implicit
  and violation-implicit losses on any multibody scene, with their gradients in the model
  parameters;
- :mod:`~drake_abs.learning.fitting`: random search and L-BFGS-B fits of the parameters;
- :mod:`~drake_abs.learning.scene_fits`: which of a scene's parameters are learned, a fit's
  seeded start off the model file's values, and the fits by name;
- :mod:`~drake_abs.learning.transitions`: recorded transitions (from an engine run), split by
  episode, and a model's one-step errors on them;
- :mod:`~drake_abs.learning.prediction`: a model's open-loop (k-step) prediction error on them.
"""

from drake_abs.learning.fitting import FitResult, fit_gradient, fit_random_search
from drake_abs.learning.ground_toy import GroundToy
from drake_abs.learning.scene_losses import (
    LossValue,
    ModelLoss,
    explicit_loss,
    learned_values,
    naive_implicit_loss,
    stepper_at,
    violation_implicit_loss,
)
from drake_abs.learning.transitions import Transitions
from drake_abs.learning.violation import ViolationLoss, complementarity_violation, violation_loss

__all__ = [
    "FitResult", "GroundToy", "LossValue", "ModelLoss", "Transitions", "ViolationLoss",
    "complementarity_violation", "explicit_loss", "fit_gradient", "fit_random_search",
    "learned_values", "naive_implicit_loss", "stepper_at", "violation_implicit_loss",
    "violation_loss",
]  # fmt: skip
