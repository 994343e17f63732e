"""The friction cone of a rigid-body contact step (docs/math.md sections 6 and 6b).

- :class:`FrictionCone`: which contacts have friction (a coefficient per contact, NaN for none),
  the k tangent directions that linearise each cone, the tangential regularization and the
  friction formulation (:data:`FORMULATIONS`). It fixes the layout of the step's LCP, d = nc +
  nt + nf rows: nc normal rows (m), k tangent rows per frictional contact (nt in all, m/s), one
  cone row per frictional contact (nf in all, N s). A *pinned* contact's normal impulse is
  given, not solved for: the rows of a dry friction of known bound (a joint's ``frictionloss``,
  :mod:`drake_abs.multibody.joint_friction`).
- :class:`GeneratorMap`: the rows of the Anitescu formulation of a cone, one per generator
  ``n + alpha t_j``, and the maps between them and the Stewart-Trinkle layout.
- :class:`GeneratorSmoothing`: a contact-level smoothing seen from those generator rows.
- :func:`expand_mu`: per-contact values (mu, m N s) as per-row values (mu / h on the friction
  and cone rows: one central-path value kappa = mu / h for every velocity-level pair of a
  contact; see :mod:`drake_abs.contact.contact_lcp`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from drake_abs.contact.smoothing import Smoothing

#: the friction formulations a :class:`FrictionCone` offers
FORMULATIONS = ("stewart_trinkle", "anitescu")

#: kappa, the diagonal (1 / (N s)^2 in a central path's units) of a pinned contact's normal
#: row (``FrictionCone.pinned``): large, so that a smoothing's mu on that row (needed: with
#: the rows around it smoothed and this one exact the interior point converges slowly, measured
#: up to 1200 iterations on a dry-friction slider) moves its given impulse by no more than
#: ``sqrt(mu / kappa)`` (3e-5 N s at mu = 1e-3).
PINNED_STIFFNESS = 1e6


@dataclass(frozen=True)
class FrictionCone:
    """Which contacts have friction and how the cone is linearised.

    Attributes:
        coefficients: (nc,) friction coefficient per contact; NaN for a frictionless contact.
        directions: k, the number of tangent directions of each frictional contact's cone.
        regularization: epsilon, a tangential compliance relative to the mean diagonal of
            ``Jt W Jt^T``: the friction rows' slack becomes ``Jt v+ + E omega + eps_abs beta``.
            It makes the friction impulses unique at a sticking contact (without it opposite
            directions can carry equal, cancelling impulses: a continuum of solutions that
            interior points converge to slowly or not at all). Its effect is a slip velocity
            of at most eps times the tangential velocity change the impulse causes; measured on
            the resting box it took failures at rest from 16 of 100 steps to 0 and left the
            trajectory unchanged to 1e-6 m. Its weight is held constant when differentiating.
            Under ``"anitescu"`` it applies to every generator row, relative to that row's own
            diagonal (it makes the generator split unique at a sticking contact; being local,
            it lets pruning leave an exact step unchanged).
        formulation: how the friction cone enters the LCP (docs/math.md section 6b):

            - ``"stewart_trinkle"`` (default; the papers' eqs.): normal, tangent and cone rows as
              in :mod:`drake_abs.contact.contact_lcp`. Exact Coulomb friction on the linearised
              cone, but the LCP is not monotone (not P, not PSD), so the interior point may fail
              on it, mostly under smoothing at sticking contacts (measured: benchmarks/
              bench_convergence.py).
            - ``"anitescu"``: one row per cone generator ``n + alpha t_j`` (the convex
              relaxation): the LCP matrix is ``h D W D^T`` (positive semidefinite), a monotone
              LCP that the interior point solves at every mu. Its artefact: a *sliding* contact
              separates at ``alpha |v_t|`` (a lift of about ``alpha |v_t| h`` per step, where
              Stewart-Trinkle keeps it on the ground); sticking, rolling and the sliding
              deceleration are Coulomb's. Step outputs keep the Stewart-Trinkle layout
              (gamma, beta, omega) with omega = 0; there ``beta_j = alpha b_j`` are the
              generators' tangential parts, so ``sum_j beta_j = alpha gamma`` always (a sticking
              contact carries cancelling pairs): only the net ``sum_j beta_j t_j`` (the step's
              ``friction_impulse``) is physical, not the sum of the betas.
        pinned: (nc,) which contacts are pinned (None: none): a pinned contact's normal impulse
            is given, ``g = -phi / kappa`` with ``kappa =`` :data:`PINNED_STIFFNESS`: its
            normal row is ``kappa gamma + phi >= 0 perp gamma >= 0`` (no velocity: its ``Jn``
            row must be 0), so ``gamma = g`` in the exact problem. Its rows take the contact's
            mu as every contact's do (mu / h on its friction and cone rows); on the normal row
            a central-path value mu moves gamma by ``mu / (kappa g)`` (at most ``sqrt(mu /
            kappa)``), which kappa keeps negligible. With coefficient 1 its cone row reads
            ``g - E^T beta >= 0``: a dry friction of bound g (N s) along its tangent rows.
            Stewart-Trinkle only (the Anitescu generators have no such row).
    """

    coefficients: np.ndarray
    directions: int = 4
    regularization: float = 1e-8
    formulation: str = "stewart_trinkle"
    pinned: np.ndarray | None = None
    _frictional: np.ndarray = field(init=False, repr=False, compare=False)
    _row_contact: np.ndarray = field(init=False, repr=False, compare=False)
    _mu_f: np.ndarray = field(init=False, repr=False, compare=False)
    _generators: GeneratorMap | None = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        coeff = np.asarray(self.coefficients, dtype=float).reshape(-1)
        frictional = ~np.isnan(coeff)
        if np.any(coeff[frictional] < 0) or np.any(np.isinf(coeff)):
            raise ValueError(f"friction coefficients must be >= 0 or NaN; got {coeff}")
        if not (np.isfinite(self.regularization) and self.regularization >= 0):
            raise ValueError(f"regularization must be >= 0; got {self.regularization!r}")
        if self.formulation not in FORMULATIONS:
            raise ValueError(f"formulation must be one of {FORMULATIONS}; got {self.formulation!r}")
        if int(self.directions) < 2 and frictional.any():
            raise ValueError(
                f"directions must be >= 2 for frictional contacts; got {self.directions}"
            )
        pinned = np.zeros(coeff.size, dtype=bool) if self.pinned is None else self.pinned
        pinned = np.asarray(pinned)
        if pinned.shape != coeff.shape or pinned.dtype != bool:
            raise ValueError(
                f"pinned must be None or {coeff.size} booleans (one per contact); got {pinned!r}"
            )
        if pinned.any() and self.formulation != "stewart_trinkle":
            raise ValueError(
                "pinned contacts (a given normal impulse: joint dry friction) need the "
                f"stewart_trinkle formulation; got formulation {self.formulation!r}"
            )
        object.__setattr__(self, "pinned", pinned)
        object.__setattr__(self, "coefficients", coeff)
        object.__setattr__(self, "directions", int(self.directions))
        fr = np.flatnonzero(frictional)
        object.__setattr__(self, "_frictional", fr)
        rows = np.concatenate([np.arange(coeff.size), np.repeat(fr, int(self.directions)), fr])
        object.__setattr__(self, "_row_contact", rows.astype(np.int64))
        object.__setattr__(self, "_mu_f", coeff[fr])
        object.__setattr__(self, "_generators", None)

    @property
    def frictional(self) -> np.ndarray:
        """Indices of the frictional contacts (nf,)."""
        return self._frictional

    @property
    def friction_coefficients(self) -> np.ndarray:
        """The coefficients of the frictional contacts (nf,), in the order of ``frictional``."""
        return self._mu_f

    @property
    def row_contact(self) -> np.ndarray:
        """The contact each LCP row belongs to, shape (d,); normal rows, then k tangent rows per
        frictional contact, then one cone row per frictional contact."""
        return self._row_contact

    def sizes(self) -> tuple[int, int, int]:
        """``(nc, nt, nf)``: contacts, tangent rows (k per frictional contact), cone rows."""
        nc = self.coefficients.size
        nf = self._frictional.size
        return nc, nf * self.directions, nf

    def with_formulation(self, formulation: str) -> FrictionCone:
        """The same cone under another friction formulation."""
        if formulation == self.formulation:
            return self
        return FrictionCone(
            self.coefficients, self.directions, self.regularization, formulation, self.pinned
        )

    @property
    def generators(self) -> GeneratorMap:
        """The Anitescu generator rows of this cone (built once)."""
        if self._generators is None:
            object.__setattr__(self, "_generators", GeneratorMap.of(self))
        return self._generators


@dataclass(frozen=True)
class GeneratorMap:
    """The rows of the Anitescu formulation (docs/math.md section 6b) of a cone with nc
    contacts: one generator per frictionless contact (its normal) and k per frictional contact
    (``n + alpha t_j``, j = 1..k), in contact order; ng generators in all.

    Attributes:
        contact: (ng,) the contact of each generator.
        tangent: (ng,) its row among the cone's tangent rows (-1 for a normal).
        alpha: (ng,) its friction coefficient (0 for a normal).
        friction: (ng,) the index of its contact among the frictional ones (-1 for a normal).
        to_lam: (d, ng) maps generator impulses to the Stewart-Trinkle layout
            (gamma_c = sum of the contact's generator impulses; beta_j = alpha x the impulse of
            generator j; omega = 0).
        average: (nc, ng) each contact's mean over its generators (z_n = average z_g when the
            contact's tangent directions sum to zero, as evenly spread ones do).
        share: (ng, nc) 1/k_c: a contact's mu split evenly over its k_c generators, so that
            summed over them the complementarity products equal the contact's mu.
        rows_cone: the generator rows as a frictionless cone (with this cone's regularization).
    """

    contact: np.ndarray
    tangent: np.ndarray
    alpha: np.ndarray
    friction: np.ndarray
    to_lam: np.ndarray
    average: np.ndarray
    share: np.ndarray
    rows_cone: FrictionCone

    @classmethod
    def of(cls, cone: FrictionCone) -> GeneratorMap:
        """The generator rows of ``cone``; a ValueError for a cone with pinned contacts (a
        given normal impulse has no generators: ``FrictionCone.pinned``)."""
        if cone.pinned.any():
            raise ValueError(
                "cone has pinned contacts (dry joint friction): they have no Anitescu "
                "generator rows; use the Stewart-Trinkle rows"
            )
        nc, nt, nf = cone.sizes()
        k = cone.directions
        order = {c: f for f, c in enumerate(cone.frictional)}
        contact, tangent, alpha, friction = [], [], [], []
        for c in range(nc):
            if c in order:
                f = order[c]
                contact += [c] * k
                tangent += list(range(f * k, (f + 1) * k))
                alpha += [cone.friction_coefficients[f]] * k
                friction += [f] * k
            else:
                contact.append(c)
                tangent.append(-1)
                alpha.append(0.0)
                friction.append(-1)
        contact, tangent = np.array(contact), np.array(tangent)
        alpha, friction = np.array(alpha, dtype=float), np.array(friction)
        ng = contact.size
        to_lam = np.zeros((nc + nt + nf, ng))
        to_lam[contact, np.arange(ng)] = 1.0
        fr = tangent >= 0
        to_lam[nc + tangent[fr], np.flatnonzero(fr)] = alpha[fr]
        member = np.zeros((nc, ng))
        member[contact, np.arange(ng)] = 1.0
        count = member.sum(axis=1)
        rows_cone = FrictionCone(np.full(ng, np.nan), k, cone.regularization)
        return cls(
            contact, tangent, alpha, friction, to_lam, member / count[:, None], member.T / count,
            rows_cone,
        )  # fmt: skip

    @property
    def size(self) -> int:
        return self.contact.size


class GeneratorSmoothing(Smoothing):
    """A contact-level smoothing seen from the generator rows: each contact's mu comes
    from its mean generator distance and compliance (``average``), and is shared evenly by its
    generators (``share``)."""

    def __init__(self, inner: Smoothing, generators: GeneratorMap) -> None:
        self.inner = inner
        self.g = generators

    @property
    def is_constant(self) -> bool:
        return self.inner.is_constant

    @property
    def is_exact(self) -> bool:
        return self.inner.is_exact

    def _contact_level(self, z, F):
        A = self.g.average
        return z @ A.T, A @ F @ A.T

    def mu(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        return self.inner.mu(*self._contact_level(z, F)) @ self.g.share.T

    def dmu_dz(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        dmu = self.inner.dmu_dz(*self._contact_level(z, F))  # (B, nc, nc)
        return self.g.share @ dmu @ self.g.average

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.inner.parameter_names

    def dmu_dparameters(self, z: np.ndarray, F: np.ndarray) -> np.ndarray:
        dmu = self.inner.dmu_dparameters(*self._contact_level(z, F))  # (B, nc, S)
        return np.einsum("gc,bcs->bgs", self.g.share, dmu)


def expand_mu(mu_n: np.ndarray, cone: FrictionCone, h: float) -> np.ndarray:
    """Per-row values (B, d, ...) from per-contact values (B, nc, ...): each row takes its
    contact's value, divided by h on friction and cone rows. For mu (B, nc) and for its
    derivative d mu_n / d z_n (B, nc, nc), giving d mu_rows / d z_n (B, d, nc)."""
    rows = mu_n[:, cone.row_contact]
    rows[:, cone.sizes()[0] :] /= h
    return rows
