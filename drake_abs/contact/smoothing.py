"""Smoothing designs: how much to soften each contact (docs/math.md section 5; Zhang et al. 2023,
section 5).

A smoothing maps a batch of contact distances ``z`` (B, d) (the distances before any impulse acts,
``z = D x + E u + d``) and the LCP matrix F to a per-contact central-path value ``mu`` (B, d).

**Direction: a larger mu means more smoothing** (contact forces act at a larger distance and the
dynamics are less stiff); ``mu = 0`` is hard contact.

- :class:`Exact`: ``mu = 0`` (hard contact, solved to the solver's exact floor).
- :class:`Fixed`: barrier smoothing (BS), one constant mu everywhere.
- :class:`ContactAware`: adaptive barrier smoothing (ABS), ``mu = g(dist)`` with ``dist`` the
  distance of the nearest *inactive* contact (``z_i > 0``) and g non-increasing.
- :class:`GaussianMatched`: per-contact ABS whose softened solution equals the Gaussian-smoothed
  exact solution (Zhang et al. (2023) Prop. 5.3 / Zhang et al. (model-based FOPG) Prop. 4.2,
  corrected as in docs/math.md
  section 5b).

Each smoothing also gives ``dmu_dz`` (B, d, d) for the ``total`` gradient mode; the ``frozen`` mode
(Zhang et al. 2023, Algorithm 1) treats mu as a constant.

**Units and the time step.** In a contact problem a normal row reads ``gamma * s = mu`` with
``gamma`` the normal impulse of the step (N s) and ``s`` the gap after it (m), so mu is in
m N s. A body of weight ``m g`` resting on one barrier contact needs ``gamma = m g h`` per step,
so it floats at the gap ``s* = mu / (m g h)``, and the barrier's force at a gap s is
``mu / (h s)``: at a fixed mu, halving h doubles both. A value of mu (``Fixed``, ``ContactAware``'s
``mu_min`` and ``mu_max``) is therefore tied to the time step it was chosen at. Measured on the
1-D point mass (``drake_abs.tasks.point_mass``, 1 kg) dropped from 5 cm under
``ContactAware(1e-2, 0.05)`` tuned at h = 10 ms: it settles about 4 cm up at h = 10 ms, but at
h = 0.1 ms the same mu throws it to 2.3 m (``Fixed(1e-3)``: to 4.5 m). :class:`TimeStepScaled`
restates a smoothing given at a reference step ``h_ref`` for the step h actually used, multiplying
mu by ``h / h_ref``: the rest gap and the force law ``mu / (h s)`` are then the reference's at
every h (a scene does this when its smoothing names ``reference_time_step``).
:class:`GaussianMatched` is built from F (which carries h) and cannot be rescaled this way (see
its docstring).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.special import ndtr

_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)


def _diag(F: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    return np.broadcast_to(np.diagonal(F, axis1=-2, axis2=-1), shape)


def _check_positive(value: float, name: str, *, allow_zero: bool = False) -> float:
    value = float(value)
    ok = value >= 0 if allow_zero else value > 0
    if not (np.isfinite(value) and ok):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite number {bound}; got {value!r}")
    return value


class Smoothing(ABC):
    """Maps contact distances z (B, d) and F ((d, d) or (B, d, d)) to mu (B, d)."""

    @abstractmethod
    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        """Per-contact central-path value (B, d), >= 0; larger is smoother."""

    def dmu_dz(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        """Derivative of :meth:`mu` with respect to z, (B, d, d). Zero for constant smoothings."""
        return np.zeros(z.shape + z.shape[-1:])

    @property
    def is_constant(self) -> bool:
        """True when mu does not depend on the state, where ``frozen`` and ``total`` gradients
        coincide."""
        return False

    @property
    def is_exact(self) -> bool:
        """True when mu = 0 for every state (hard contact)."""
        return False

    # The smoothing's numeric parameters (S of them), so that a Drake Context can hold them and
    # AutoDiffXd can differentiate with respect to them. A smoothing with none (``Exact``, or one
    # with a custom function) names none.

    #: The names of the numeric parameters, in the order of :meth:`parameter_values`.
    parameter_names: tuple[str, ...] = ()

    def parameter_values(self) -> np.ndarray:
        """The numeric parameters (S,), in the order of :attr:`parameter_names`."""
        return np.array([float(getattr(self, n)) for n in self.parameter_names])

    def with_parameters(self, values) -> Smoothing:
        """The same smoothing with the numeric parameters ``values`` (S,) (checked as at
        construction)."""
        values = np.asarray(values, dtype=float).reshape(-1)
        if values.shape != (len(self.parameter_names),):
            raise ValueError(
                f"{type(self).__name__}.with_parameters: values must have shape "
                f"({len(self.parameter_names)},) for {self.parameter_names}; got {values.shape}"
            )
        if not values.size:
            return self
        return replace(self, **dict(zip(self.parameter_names, map(float, values), strict=True)))

    def dmu_dparameters(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        """Derivative of :meth:`mu` with respect to the numeric parameters at fixed z and F,
        (B, d, S)."""
        return np.zeros(z.shape + (len(self.parameter_names),))

    def dmu_dF_diagonal(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        """Derivative of mu with respect to the diagonal of F at fixed z, (B, d, d): entry
        ``[b, i, j]`` is ``d mu_i / d F_jj``. Zero for smoothings that do not read F (of this
        module's, only :class:`~drake_abs.contact.smoothing.GaussianMatched` does)."""
        return np.zeros(z.shape + z.shape[-1:])


class WrappedSmoothing(Smoothing):
    """A smoothing built on another one, held in the dataclass field named ``inner_field``:
    whether it is constant or exact, and its numeric parameters, are the inner smoothing's."""

    inner_field = "smoothing"

    @property
    def inner(self) -> Smoothing:
        return getattr(self, self.inner_field)

    @property
    def is_constant(self) -> bool:
        return self.inner.is_constant

    @property
    def is_exact(self) -> bool:
        return self.inner.is_exact

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.inner.parameter_names

    def parameter_values(self) -> np.ndarray:
        return self.inner.parameter_values()

    def with_parameters(self, values) -> Smoothing:
        return replace(self, **{self.inner_field: self.inner.with_parameters(values)})


@dataclass(frozen=True)
class Exact(Smoothing):
    """Hard contact: ``mu = 0`` (the solver stops at its exact floor, see ``solve_lcp``)."""

    is_constant = True
    is_exact = True

    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return np.zeros_like(z)


@dataclass(frozen=True)
class Fixed(Smoothing):
    """Barrier smoothing (BS): the same ``mu`` for every contact and state. Larger is smoother.

    Units: those of ``lam * z``: impulse times distance for contact problems, m N s. The value
    holds for one time step h only: a body of weight ``m g`` resting on a barrier contact sits
    at the gap ``mu / (m g h)``, so the same value at a 100 times smaller step floats it 100
    times higher (module docstring). To state mu at a reference step and run at another, wrap
    it: ``TimeStepScaled.between(Fixed(mu), h, h_ref)``.
    """

    value: float

    def __post_init__(self):
        _check_positive(self.value, "Fixed.value", allow_zero=True)

    is_constant = True
    parameter_names = ("value",)

    @property
    def is_exact(self) -> bool:
        return self.value == 0

    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return np.full_like(z, self.value)

    def dmu_dparameters(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return np.ones(z.shape + (1,))


def exponential_decay(mu_min: float, mu_max: float, length: float) -> Callable:
    """``g(dist) = mu_min + (mu_max - mu_min) exp(-dist / length)`` and its derivative."""

    def g(dist):
        e = np.exp(-dist / length)
        return mu_min + (mu_max - mu_min) * e, -(mu_max - mu_min) / length * e

    return g


@dataclass(frozen=True)
class ContactAware(Smoothing):
    """Adaptive barrier smoothing (ABS), contact-aware (Zhang et al. 2023, section 5.1, Algorithm
    1).

    ``mu = g(dist)`` for every contact of a problem, where ``dist = min {z_i : z_i > 0}`` is the
    distance of the nearest inactive contact and ``g`` is non-increasing:
    ``g(dist) = mu_min + (mu_max - mu_min) exp(-dist / length)`` by default. Far from contact
    (or with every contact active) mu = mu_min (accurate physics); an inactive contact closing in
    on an obstacle raises mu towards mu_max (more smoothing).

    Note: as in the paper, mu jumps from about mu_max to mu_min when the nearest contact turns
    active (z crosses 0); the ``total`` gradient mode differentiates g but not that jump.

    Args:
        mu_max: mu at zero distance (the most smoothing), > mu_min (m N s in a contact problem;
            like :class:`Fixed`'s value it holds for one time step, see the module docstring
            and :class:`TimeStepScaled`).
        length: decay length of g, in the units of z (> 0; a distance: independent of h).
        mu_min: mu far from contact, >= 0 (0 is exact).
        g: optional custom non-increasing ``g(dist) -> (mu, dmu_ddist)`` replacing the default.
    """

    mu_max: float
    length: float
    mu_min: float = 0.0
    g: Callable | None = None

    def __post_init__(self):
        _check_positive(self.mu_max, "ContactAware.mu_max")
        _check_positive(self.length, "ContactAware.length")
        _check_positive(self.mu_min, "ContactAware.mu_min", allow_zero=True)
        if self.mu_min > self.mu_max:
            raise ValueError(
                f"ContactAware needs mu_min <= mu_max; got mu_min={self.mu_min}, "
                f"mu_max={self.mu_max}"
            )

    def _g(self, dist):
        g = self.g or exponential_decay(self.mu_min, self.mu_max, self.length)
        return g(dist)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """``("mu_max", "length", "mu_min")``; none with a custom ``g``."""
        return () if self.g is not None else ("mu_max", "length", "mu_min")

    def dmu_dparameters(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        out = np.zeros(z.shape + (len(self.parameter_names),))
        if self.g is not None:
            return out
        dist, _, any_inactive = self._nearest_inactive(z)
        dist = np.where(any_inactive, dist, 0.0)
        e = np.where(any_inactive, np.exp(-dist / self.length), 0.0)  # (B,)
        d_length = (self.mu_max - self.mu_min) * e * dist / self.length**2
        out[..., 0] = e[..., None]
        out[..., 1] = d_length[..., None]
        out[..., 2] = (1.0 - e)[..., None]
        return out

    def _nearest_inactive(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        inactive = z > 0
        masked = np.where(inactive, z, np.inf)
        arg = np.argmin(masked, axis=-1)
        dist = np.take_along_axis(masked, arg[..., None], axis=-1)[..., 0]
        return dist, arg, inactive.any(axis=-1)

    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        dist, _, any_inactive = self._nearest_inactive(z)
        val, _ = self._g(np.where(any_inactive, dist, 0.0))
        val = np.where(any_inactive, val, self.mu_min)
        return np.repeat(np.asarray(val, dtype=float)[..., None], z.shape[-1], axis=-1)

    def dmu_dz(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        dist, arg, any_inactive = self._nearest_inactive(z)
        _, dg = self._g(np.where(any_inactive, dist, 0.0))
        dg = np.where(any_inactive, dg, 0.0)
        out = np.zeros(z.shape + z.shape[-1:])
        # every contact's mu depends on the nearest inactive contact's z
        onehot = np.zeros_like(z)
        np.put_along_axis(onehot, arg[..., None], 1.0, axis=-1)
        out[...] = (dg[..., None] * onehot)[..., None, :]
        return out


@dataclass(frozen=True)
class GaussianMatched(Smoothing):
    """Per-contact ABS matched to Gaussian randomised smoothing (docs/math.md section 5b).

    With ``kappa(z) = (sigma phi(z/sigma) - z Phi(-z/sigma)) / F_ii + c1 z + c2`` and
    ``mu(z) = kappa (z + F_ii kappa)``, the softened one-contact solution with c1 = c2 = 0 equals
    ``E_w[max(0, -(z + w) / F)]`` for ``w ~ N(0, sigma^2)``: barrier smoothing that reproduces
    randomised smoothing in closed form. mu is large only near z = 0 and vanishes far from contact
    on both sides. **A larger sigma means more smoothing.** With several contacts each uses its own
    diagonal entry F_ii > 0 (exact when F is diagonal). Where kappa or the matched slack
    ``z + F_ii kappa`` is not positive (possible with c1, c2 != 0), mu = 0.

    Time step: the matched solution resolves a Gaussian spread of the pre-step distance z
    within one step, so its impulse near contact is about ``0.4 sigma / F``, with F ~ h / m:
    the launch speed grows like sigma / h. On the 1 kg point mass, ``sigma = 2 mm`` resting on
    the ground throws it 0.8 mm up at h = 10 ms but 6.4 m at h = 0.1 ms. Multiplying mu by
    ``h / h_ref`` does not repair this (the impulse scales like the square root), so
    :class:`TimeStepScaled` refuses this smoothing; choose sigma for the step it runs at.

    Args:
        sigma: width of the matched Gaussian, in the units of z (> 0).
        c1, c2: the paper's tunable constants (0 for the exact match).
    """

    sigma: float
    c1: float = 0.0
    c2: float = 0.0

    def __post_init__(self):
        _check_positive(self.sigma, "GaussianMatched.sigma")
        for name in ("c1", "c2"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"GaussianMatched.{name} must be finite")

    def _parts(self, z: np.ndarray, F: np.ndarray):
        Fd = _diag(F, z.shape)
        if np.any(Fd <= 0):
            raise ValueError(
                "GaussianMatched needs every diagonal entry F_ii > 0 (the contact's own "
                f"compliance); got min F_ii = {float(np.min(Fd)):.3e}"
            )
        t = z / self.sigma
        pdf = _INV_SQRT_2PI * np.exp(-0.5 * t * t)
        # E[max(0, -(z + w))] and E[max(0, z + w)], both without cancellation
        neg_part = self.sigma * pdf - z * ndtr(-t)
        pos_part = self.sigma * pdf + z * ndtr(t)
        kappa = neg_part / Fd + self.c1 * z + self.c2
        slack = pos_part + Fd * (self.c1 * z + self.c2)
        return Fd, t, kappa, slack

    parameter_names = ("sigma", "c1", "c2")

    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        _, _, kappa, slack = self._parts(z, F)
        return np.where((kappa > 0) & (slack > 0), kappa * slack, 0.0)

    def dmu_dparameters(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        """(B, d, 3) with respect to (sigma, c1, c2). Where mu is clipped to 0 (kappa or the
        matched slack not positive) the derivative is 0: at c1 = c2 = 0, far from contact
        (kappa ~ 0), that is the one-sided derivative of a kink in (c1, c2)."""
        # d/dsigma of E[max(0, -(z + w))] and of E[max(0, z + w)] are both phi(z / sigma)
        Fd, t, kappa, slack = self._parts(z, F)
        pdf = _INV_SQRT_2PI * np.exp(-0.5 * t * t)
        dkappa = np.stack([pdf / Fd, z, np.ones_like(z)], axis=-1)
        dslack = np.stack([pdf, Fd * z, Fd], axis=-1)
        d = dkappa * slack[..., None] + kappa[..., None] * dslack
        return np.where(((kappa > 0) & (slack > 0))[..., None], d, 0.0)

    def dmu_dF_diagonal(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        # each contact's mu reads its own F_ii only
        Fd, t, kappa, slack = self._parts(z, F)
        pdf = _INV_SQRT_2PI * np.exp(-0.5 * t * t)
        neg_part = self.sigma * pdf - z * ndtr(-t)
        d = -neg_part / Fd**2 * slack + kappa * (self.c1 * z + self.c2)
        out = np.zeros(z.shape + z.shape[-1:])
        idx = np.arange(z.shape[-1])
        out[..., idx, idx] = np.where((kappa > 0) & (slack > 0), d, 0.0)
        return out

    def dmu_dz(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        Fd, t, kappa, slack = self._parts(z, F)
        dkappa = -ndtr(-t) / Fd + self.c1
        dmu = dkappa * slack + kappa * (1.0 + Fd * dkappa)
        dmu = np.where((kappa > 0) & (slack > 0), dmu, 0.0)
        out = np.zeros(z.shape + z.shape[-1:])
        idx = np.arange(z.shape[-1])
        out[..., idx, idx] = dmu
        return out


@dataclass(frozen=True)
class TimeStepScaled(WrappedSmoothing):
    """``smoothing`` stated at a reference time step, run at another: mu (and dmu_dz) are the inner
    smoothing's times ``scale = h / h_ref``.

    A barrier contact's rest gap is ``mu / (m g h)`` and its force at a gap s is ``mu / (h s)``
    (module docstring); with mu proportional to h both are those of the reference step at every
    h, so a smoothing tuned at h_ref keeps its meaning when the step is refined. Distances inside
    the smoothing (``ContactAware.length``) are not scaled.

    Args:
        smoothing: the smoothing as stated at h_ref (:class:`Exact`, :class:`Fixed`,
            :class:`ContactAware` or a custom one; not :class:`GaussianMatched`, whose mu is
            not proportional to a parameter, see its docstring).
        scale: ``h / h_ref``, a finite number > 0.
    """

    smoothing: Smoothing
    scale: float

    def __post_init__(self):
        if not isinstance(self.smoothing, Smoothing):
            raise ValueError(
                f"TimeStepScaled.smoothing must be a Smoothing; got {type(self.smoothing).__name__}"
            )
        if isinstance(self.smoothing, GaussianMatched):
            raise ValueError(
                "TimeStepScaled.smoothing cannot be GaussianMatched: its impulse does not scale "
                "with mu (choose sigma for the time step it runs at)"
            )
        object.__setattr__(self, "scale", _check_positive(self.scale, "TimeStepScaled.scale"))

    @classmethod
    def between(
        cls, smoothing: Smoothing, time_step: float, reference_time_step: float
    ) -> Smoothing:
        """``smoothing`` (stated at ``reference_time_step``, s) for a step of ``time_step`` (s);
        the smoothing itself when the two are equal or it is exact."""
        h = _check_positive(time_step, "time_step")
        h_ref = _check_positive(reference_time_step, "reference_time_step")
        if h == h_ref or smoothing.is_exact:
            return smoothing
        return cls(smoothing, h / h_ref)

    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self.scale * self.smoothing.mu(z, F)

    def dmu_dz(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self.scale * self.smoothing.dmu_dz(z, F)

    # the numeric parameters are the inner smoothing's, as stated at the reference step (the
    # scale is not one)

    def dmu_dparameters(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self.scale * self.smoothing.dmu_dparameters(z, F)

    def dmu_dF_diagonal(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self.scale * self.smoothing.dmu_dF_diagonal(z, F)
