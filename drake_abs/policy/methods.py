"""The methods of the experiments, one registry: each method's name (the key used in configs, the
command line, sweeps and saved policies), its display label (plots, tables, the README), the
contact smoothing of the model it differentiates, its gradient mode and its estimator.

Smoothing designs (:data:`SMOOTHINGS`) are named once too: ``exact`` (hard contact, mu = 0),
``bs`` (barrier smoothing: one fixed mu for every contact) and ``abs`` (adaptive barrier
smoothing: the contact-aware mu(x, u), large only near contact). **A larger mu means more
smoothing.** A method refers to a design by that name; its numbers (mu, mu_max, length) are the
experiment's settings, passed to :meth:`Method.make_smoothing`.

A method is either a gradient estimator (``estimator`` in :data:`ESTIMATORS`, run by
:meth:`Method.estimate`) or a trainer of its own (:data:`TRAINERS`: ``"ars"``, ``"mbpo"``,
``"shac"``, ``"fopg_episode"``, ``"sb3"``: they do not estimate a gradient of the same
objective, and the experiments call their training loops). ``"shac"`` is short differentiable
windows with a learned value tail (Xu et al. 2022) and ``"fopg_episode"`` plain FOPG over whole
episodes from the reset noise, both run by :class:`drake_abs.policy.shac.ShacTrainer`
(:meth:`drake_abs.policy.shac.ShacConfig.for_method` gives a method's settings). ``"sb3"``
names the library baselines (``sb3_ppo``, ``sb3_sac``: stable-baselines3's PPO and SAC;
``sb3_ars``: sb3-contrib's ARS), run by :class:`drake_abs.tasks.sb3_baselines.Sb3Trainer`
(the ``baselines`` extra).

``fopg_bs_<mu>`` names FOPG through barrier smoothing at that mu (e.g. ``fopg_bs_1e-2``);
:func:`method` parses it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from drake_abs.contact.lcs import GradientMode, check_gradient_mode
from drake_abs.contact.smoothing import ContactAware, Exact, Fixed, Smoothing
from drake_abs.policy.estimators import (
    GradientEstimate,
    PolicyObjective,
    alpha_order,
    first_order,
    zeroth_order,
)
from drake_abs.policy.pipps import pipps

__all__ = [
    "ESTIMATORS",
    "METHODS",
    "SMOOTHINGS",
    "TRAINERS",
    "Method",
    "method",
    "make_smoothing",
]

#: smoothing design -> its display label
SMOOTHINGS = {
    "exact": "exact (hard contact)",
    "bs": "barrier smoothing (BS, fixed mu)",
    "abs": "adaptive barrier smoothing (ABS, contact-aware mu)",
}
#: the gradient estimators a method can name (the trainers are not among them)
ESTIMATORS = ("first_order", "zeroth_order", "alpha_order", "pipps")
#: the methods with a training loop of their own
TRAINERS = ("ars", "mbpo", "shac", "fopg_episode", "sb3")


def make_smoothing(
    design: str,
    *,
    mu: float | None = None,
    contact_aware: tuple[float, float] | None = None,
) -> Smoothing:
    """The :class:`~drake_abs.contact.smoothing.Smoothing` of a design of
    :data:`SMOOTHINGS`: ``exact``; ``bs`` at ``mu`` (N s m, the central-path value of every
    contact); ``abs`` with ``contact_aware = (mu_max, length)`` (N s m, m). Larger mu is more
    smoothing."""
    if design == "exact":
        return Exact()
    if design == "bs":
        if mu is None:
            raise ValueError("smoothing 'bs' needs mu (the fixed central-path value)")
        return Fixed(float(mu))
    if design == "abs":
        if contact_aware is None:
            raise ValueError("smoothing 'abs' needs contact_aware = (mu_max, length)")
        return ContactAware(*contact_aware)
    raise ValueError(f"smoothing must be one of {list(SMOOTHINGS)}; got {design!r}")


@dataclass(frozen=True)
class Method:
    """One method.

    Attributes:
        name: the key (``"fopg_abs"``): configs, the command line, sweeps, file names.
        label: the display name (``"FOPG-ABS"``).
        smoothing: the design of the model the method trains through (:data:`SMOOTHINGS`); the
            true system every method is scored on is exact.
        estimator: one of :data:`ESTIMATORS`, or one of :data:`TRAINERS` (a training loop of
            its own).
        gradient: ``"total"`` (mu's dependence on the state differentiated) or ``"frozen"``
            (mu held, Zhang et al. 2023, Algorithm 1), where the model has a pathwise gradient.
        mu: the fixed mu of a ``bs`` method named with its value (``fopg_bs_1e-2``); None takes
            the experiment's.
        description: one line for reports.
    """

    name: str
    label: str
    smoothing: str
    estimator: str
    gradient: GradientMode = "total"
    mu: float | None = None
    description: str = ""

    def __post_init__(self):
        if self.smoothing not in SMOOTHINGS:
            raise ValueError(f"smoothing must be one of {list(SMOOTHINGS)}; got {self.smoothing!r}")
        if self.estimator not in (*ESTIMATORS, *TRAINERS):
            raise ValueError(
                f"estimator must be one of {ESTIMATORS} or {TRAINERS}; got {self.estimator!r}"
            )
        check_gradient_mode(self.gradient)

    @property
    def estimates_gradient(self) -> bool:
        """Whether :meth:`estimate` applies (False for the :data:`TRAINERS`)."""
        return self.estimator in ESTIMATORS

    def make_smoothing(
        self, *, mu: float | None = None, contact_aware: tuple[float, float] | None = None
    ) -> Smoothing:
        """The model's smoothing with the experiment's numbers (the method's own mu first)."""
        return make_smoothing(
            self.smoothing, mu=self.mu if self.mu is not None else mu, contact_aware=contact_aware
        )

    def estimate(
        self,
        obj: PolicyObjective,
        theta,
        rng: np.random.Generator,
        M: int,
        *,
        alpha: float = 0.5,
        runner=None,
    ) -> GradientEstimate:
        """The method's gradient estimate from M rollouts of ``obj`` (``alpha``: the
        alpha-order mix; ``runner``: where the rollouts run, as the estimators take it)."""
        if self.estimator == "first_order":
            return first_order(obj, theta, rng, M, runner=runner)
        if self.estimator == "zeroth_order":
            return zeroth_order(obj, theta, rng, M, runner=runner)
        if self.estimator == "alpha_order":
            return alpha_order(obj, theta, rng, M, alpha, runner=runner)
        if self.estimator == "pipps":
            return pipps(obj, theta, rng, M)
        raise ValueError(f"method {self.name!r} is a trainer ({self.estimator}), not an estimator")


#: Every method, by name.
METHODS: dict[str, Method] = {
    m.name: m
    for m in (
        Method("fopg_abs", "FOPG-ABS", "abs", "first_order",
               description="first-order gradient through adaptive barrier smoothing (ours)"),
        Method("fopg_exact", "FOPG", "exact", "first_order",
               description="first-order gradient through exact contact"),
        Method("fopg_bs", "FOPG-BS", "bs", "first_order",
               description="first-order gradient through barrier smoothing at a fixed mu"),
        Method("zopg", "ZOPG", "exact", "zeroth_order",
               description="likelihood-ratio gradient, leave-one-out baseline"),
        Method("aobg", "AoBG", "exact", "alpha_order",
               description="alpha-order gradient: alpha FOPG + (1 - alpha) ZOPG"),
        Method("pipps", "PIPPS", "exact", "pipps",
               description="PIPPS total propagation (Parmas et al. 2018)"),
        Method("ars", "ARS V2-t", "exact", "ars",
               description="augmented random search V2-t (Mania et al. 2018)"),
        Method("mbpo", "MBPO-style", "exact", "mbpo",
               description="learned ensemble model, first-order policy updates inside it"),
        Method("shac_abs", "SHAC-ABS", "abs", "shac",
               description="short differentiable windows through adaptive barrier smoothing, "
                           "learned value tail (SHAC, Xu et al. 2022)"),
        Method("shac_exact", "SHAC", "exact", "shac",
               description="short differentiable windows through exact contact, learned value "
                           "tail (SHAC, Xu et al. 2022)"),
        Method("fopg_episode_abs", "FOPG-ABS (episodes)", "abs", "fopg_episode",
               description="first-order gradient of whole episodes from the reset noise, "
                           "through adaptive barrier smoothing"),
        Method("fopg_episode_exact", "FOPG (episodes)", "exact", "fopg_episode",
               description="first-order gradient of whole episodes from the reset noise, "
                           "through exact contact"),
        Method("sb3_ppo", "PPO (SB3)", "exact", "sb3",
               description="stable-baselines3's PPO with the RL Zoo's settings"),
        Method("sb3_sac", "SAC (SB3)", "exact", "sb3",
               description="stable-baselines3's SAC with the RL Zoo's settings"),
        Method("sb3_ars", "ARS (sb3-contrib)", "exact", "sb3",
               description="sb3-contrib's ARS with the RL Zoo's settings"),
    )
}  # fmt: skip


def method(name: str) -> Method:
    """The method called ``name``: a key of :data:`METHODS`, or ``fopg_bs_<mu>`` (FOPG through
    barrier smoothing at that mu, labelled ``FOPG mu = <mu>``). ``ValueError`` lists the known
    names."""
    if name in METHODS:
        return METHODS[name]
    if isinstance(name, str) and name.startswith("fopg_bs_"):
        text = name.removeprefix("fopg_bs_")
        try:
            mu = float(text)
        except ValueError:
            mu = float("nan")
        if np.isfinite(mu) and mu >= 0:
            return replace(METHODS["fopg_bs"], name=name, label=f"FOPG mu = {text}", mu=mu)
    raise ValueError(
        f"unknown method {name!r}; known: {sorted(METHODS)} or fopg_bs_<mu> (e.g. fopg_bs_1e-2)"
    )
