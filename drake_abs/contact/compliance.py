"""Soft contact as MuJoCo defines it (``solref``, ``solimp``, ``margin``), written as a
regularised complementarity problem in this package's impulse and velocity form: the contact
compliance option of the rigid-body step (:func:`drake_abs.contact.contact_lcp.contact_step`).

Which way is softer: a larger time constant ``timeconst`` (solref, s), a smaller impedance d
(solimp, between 0 and 1) and so a larger regulariser R are softer. The hard step is the limit
d -> 1 (R -> 0) with ``h b = 1`` and ``h^2 k = 1`` (see below); MuJoCo itself never reaches it
(d <= 0.9999, and ``timeconst >= 2 h`` unless ``refsafe`` is off).

MuJoCo's model, per constraint row (its documentation, "Computation" and "Modeling: solver
parameters"), in our words. A row has a residual ``r`` (m): the contact's signed distance minus
its margin (the row exists only while ``r < 0``, within the margin), its velocity ``J v`` (m/s,
at the start of the step) and an approximation ``A_hat`` of its diagonal of ``J M^-1 J^T``
(1/kg: MuJoCo takes it from the bodies' inverse weights at the model's reference pose, not from
the current state). From ``solimp = (d0, dwidth, width, midpoint, power)`` the impedance::

    d(r) = d0 + y(|r| / width) (dwidth - d0),   y(x) = x^p / m^(p-1)               (x <= m)
                                                 y(x) = 1 - (1 - x)^p / (1 - m)^(p-1) (x > m)

(y = x for power 1; d = dwidth past the width; d = (d0 + dwidth) / 2 when d0 = dwidth or the
width is 0; d0, dwidth and the midpoint m clamped to [1e-4, 0.9999], the power to >= 1). From
``solref = (timeconst, dampratio)`` (both > 0; ``timeconst`` raised to ``2 h`` when
``refsafe``) a damping and a stiffness

    b = 2 / (dwidth timeconst),   k(r) = d(r) / (dwidth^2 timeconst^2 dampratio^2)

or, for the direct form ``solref = (-stiffness, -damping)``, ``b = damping / dwidth`` and
``k(r) = stiffness d(r) / dwidth^2``. The row's reference acceleration is
``a_ref = -b J v - k(r) r`` and its regulariser ``R = (1 - d) / d A_hat`` (1/kg). MuJoCo's
forces f (N) solve the convex problem ``min 1/2 f^T (A + R) f + f^T (a_u - a_ref)`` over its
cone, whose optimality conditions, for a pyramidal cone (one row per cone edge, f >= 0), are the
complementarity problem ``(A + R) f + a_u - a_ref >= 0  perp  f >= 0`` (a_u: the unconstrained
row acceleration).

In this package's step (impulses lam = h f, N s; semi-implicit Euler, ``v+ = v_free + W J^T
lam`` with ``J v_free = J v + h a_u``), multiplied by h like the hard normal row
``phi + h J v+ >= 0``, that row reads

    h J v+ + h R lam + c >= 0   perp   lam >= 0,     c = h^2 k(r) r + h (h b - 1) J v   (m)

so the LCP's matrix gains ``h R`` on the row's diagonal and its constant ``phi`` becomes ``c``
(:meth:`SoftRows.terms`). The hard row is the case R = 0, c = phi; with ``h b = 1`` and
``h^2 k = 1``, c = r. Everything else (friction rows, smoothing: the per-contact central-path
value mu is applied to the regularised LCP as to the hard one, and its implicit Jacobians) is
unchanged.

MuJoCo's pyramidal cone has ``n_e = 2 (condim - 1)`` edge rows ``J_n +- mu J_t`` per contact
(mu the friction coefficient), each with the same residual and the regulariser
``R_e = 2 mu^2 / impratio (1 - d) / d A_hat (1 + mu^2)`` (MuJoCo's choice that matches its
elliptic cone's friction). The Anitescu formulation's generator rows are these edges: each of
its k generators gets ``R_e n_e / k`` (exactly MuJoCo's when k = n_e; with fewer directions, as
in a planar scene's k = 2, the contact's normal compliance ``R_e / n_e`` is kept). Under
Stewart-Trinkle (hard friction rows) the normal row gets that normal compliance,
``R_n = R_e / n_e``. A frictionless contact has ``R = (1 - d) / d A_hat``.

Derivatives (R and c depend on the state through r = phi(q) - margin and J v): with
``d' = dd/dr``,

    dc/dr = h^2 k_0 (d + d' r),   dc/d(J v) = h (h b - 1),   dR/dr = -A_hat' d' / d^2

(k_0 = k / d; A_hat' the row's weight; R's floor 1e-15 has zero derivative). The chain rule adds
``(dc/dr - 1) dphi + dc/d(Jv) d(Jv) + h (dR/dr) lam dphi`` to the hard row's derivative of the
LCP's constant (:meth:`RowTerms.extra_derivative`); ``A_hat`` is a model constant, as in MuJoCo.
A frictional row's weight grows with its friction coefficient mu (``2 mu^2 (1 + mu^2)``), so a
model parameter that moves mu adds ``h (1 - d) / d (dweight/dmu) lam dmu``
(:meth:`RowTerms.friction_derivative`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: MuJoCo's bounds on the impedance (and the midpoint), and its smallest positive value
MIN_IMPEDANCE, MAX_IMPEDANCE, MIN_VALUE = 1e-4, 0.9999, 1e-15

#: MuJoCo's default solref (timeconst in s, dampratio) and solimp (d0, dwidth, width in m,
#: midpoint, power)
DEFAULT_SOLREF = (0.02, 1.0)
DEFAULT_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)


def _rows(value, n: int, width: int, name: str) -> np.ndarray:
    """``value`` (width,) or (n, width) as (n, width) floats; ValueError otherwise."""
    a = np.asarray(value, dtype=float)
    if a.shape == (width,):
        a = np.broadcast_to(a, (n, width)).copy()
    if a.shape != (n, width) or not np.all(np.isfinite(a)):
        raise ValueError(
            f"{name} must be {width} finite numbers, or one such row per contact ({n}, {width}); "
            f"got shape {a.shape}"
        )
    return a


def check_solref(solref: np.ndarray, name: str = "solref") -> None:
    """ValueError unless every row is ``(timeconst > 0, dampratio > 0)`` or the direct form
    ``(-stiffness <= 0, -damping <= 0)`` (not both 0)."""
    positive = (solref[:, 0] > 0) & (solref[:, 1] > 0)
    direct = (solref[:, 0] <= 0) & (solref[:, 1] <= 0) & (solref.any(axis=1))
    if not np.all(positive | direct):
        bad = solref[~(positive | direct)][0].tolist()
        raise ValueError(
            f"{name} must be (timeconst > 0, dampratio > 0) in s, or the direct form "
            f"(-stiffness, -damping) with both <= 0 and not both 0; got {bad}"
        )


def check_solimp(solimp: np.ndarray, name: str = "solimp") -> None:
    """ValueError unless every row is ``(d0, dwidth, width, midpoint, power)`` with d0, dwidth
    and midpoint in [0, 1], width >= 0 (m) and power >= 1."""
    d = solimp[:, [0, 1, 3]]
    ok = np.all((d >= 0) & (d <= 1), axis=1) & (solimp[:, 2] >= 0) & (solimp[:, 4] >= 1)
    if not np.all(ok):
        bad = solimp[~ok][0].tolist()
        raise ValueError(
            f"{name} must be (d0, dwidth, width, midpoint, power) with d0, dwidth, midpoint in "
            f"[0, 1], width >= 0 (m) and power >= 1; got {bad}"
        )


def impedance(r: np.ndarray, solimp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's impedance d(r) and its derivative dd/dr (1/m) at residuals r (..., n) (m), for
    per-row ``solimp`` (n, 5) (the module docstring's formula, with MuJoCo's clamps)."""
    r = np.asarray(r, dtype=float)
    d0 = np.clip(solimp[:, 0], MIN_IMPEDANCE, MAX_IMPEDANCE)
    dw = np.clip(solimp[:, 1], MIN_IMPEDANCE, MAX_IMPEDANCE)
    width = np.maximum(solimp[:, 2], 0.0)
    mid = np.clip(solimp[:, 3], MIN_IMPEDANCE, MAX_IMPEDANCE)
    p = np.maximum(solimp[:, 4], 1.0)
    flat = (d0 == dw) | (width <= MIN_VALUE)
    safe_width = np.where(flat, 1.0, width)
    x = np.abs(r) / safe_width
    sign = np.where(r < 0, -1.0, 1.0)
    inside = (x > 0) & (x < 1) & ~flat
    xi = np.clip(x, 0.0, 1.0)
    low = xi <= mid
    a = 1.0 / mid ** (p - 1)
    b = 1.0 / (1 - mid) ** (p - 1)
    y = np.where(low, a * xi**p, 1 - b * (1 - xi) ** p)
    dy = np.where(low, p * a * xi ** (p - 1), p * b * (1 - xi) ** (p - 1))
    y = np.where(p == 1, xi, y)
    dy = np.where(p == 1, 1.0, dy)
    y = np.where(x >= 1, 1.0, y)
    d = np.where(flat, 0.5 * (d0 + dw), d0 + y * (dw - d0))
    dd = np.where(inside, dy * sign * (dw - d0) / safe_width, 0.0)
    return d, dd


@dataclass(frozen=True)
class RowTerms:
    """What compliance changes in one step's normal rows, for B states and n rows: the
    regulariser ``R`` (B, n) (1/kg; 0 on hard rows), the constant ``c`` (B, n) (m; phi on hard
    rows) and their derivatives ``dR_dr``, ``dc_dr`` (B, n) and ``dc_dJv`` (B, n) (s)."""

    R: np.ndarray
    c: np.ndarray
    dR_dr: np.ndarray
    dc_dr: np.ndarray
    dc_dJv: np.ndarray
    dR_dmu: np.ndarray | None = None

    def friction_derivative(self, dmu: np.ndarray, lam_n: np.ndarray, h: float) -> np.ndarray:
        """What the friction coefficients' derivatives ``dmu`` (n, T) (per normal row: its
        contact's coefficient) add to the derivative of the LCP's constant (with F's derivative
        applied to lam), (B, n, T): ``h dR/dmu lam dmu`` (the pyramid's R grows with mu)."""
        return (h * self.dR_dmu * lam_n)[..., None] * dmu[None]

    def apply(self, F: np.ndarray, z: np.ndarray, phi: np.ndarray, h: float) -> None:
        """Turn the hard LCP ``(F, z)`` of
        :func:`~drake_abs.contact.stewart_trinkle.assemble_lcp` (normal rows first,
        ``z_n = phi + h J_n v_free``) into the regularised one, in place: ``F_ii += h R_i``,
        ``z_i += c_i - phi_i``."""
        n = self.R.shape[1]
        rows = np.arange(n)
        F[:, rows, rows] += h * self.R
        z[:, :n] += self.c - phi

    def extra_derivative(
        self, dphi: np.ndarray, dJv: np.ndarray, lam_n: np.ndarray | None, h: float
    ) -> np.ndarray:
        """What compliance adds to the hard rows' derivative of the LCP's constant (with F's
        derivative applied to lam), (B, n, P): ``(dc/dr - 1) dphi + dc/d(Jv) dJv`` and, with
        the normal impulses ``lam_n`` (B, n), ``h dR/dr lam dphi`` (leave lam_n None for the
        derivative of the constant alone, as the smoothing's total mode needs). ``dphi``,
        ``dJv``: (B, n, P)."""
        a = self.dc_dr - 1.0
        if lam_n is not None:
            a = a + h * self.dR_dr * lam_n
        return a[..., None] * dphi + self.dc_dJv[..., None] * dJv


@dataclass(frozen=True)
class SoftRows:
    """The compliance of one step's n normal LCP rows (contacts, then e.g. joint-limit rows),
    at time step ``h``: which rows are soft, and per row (n,) its margin (m), its stiffness
    ``k0`` (1/s^2, k = k0 d(r)) and damping ``b`` (1/s), its ``solimp`` (n, 5), its weight
    ``weight`` (1/kg, R = (1 - d) / d weight) and that weight's derivative in the row's friction
    coefficient ``dweight_dmu`` (1/kg). Hard rows' entries are unused. Made by
    :meth:`ContactCompliance.rows`; :meth:`take` selects rows (the Anitescu generators of a
    contact share its values)."""

    soft: np.ndarray
    margin: np.ndarray
    k0: np.ndarray
    b: np.ndarray
    solimp: np.ndarray
    weight: np.ndarray
    dweight_dmu: np.ndarray | None = None

    def take(self, index: np.ndarray, scale: np.ndarray | None = None) -> SoftRows:
        """The rows ``index`` (m,), their weights times ``scale`` (m,) where given."""
        weight = self.weight[index] if scale is None else self.weight[index] * scale
        dweight = None if self.dweight_dmu is None else self.dweight_dmu[index]
        if dweight is not None and scale is not None:
            dweight = dweight * scale
        return SoftRows(
            self.soft[index], self.margin[index], self.k0[index], self.b[index],
            self.solimp[index], weight, dweight,
        )  # fmt: skip

    def terms(self, phi: np.ndarray, Jv: np.ndarray, h: float) -> RowTerms:
        """The :class:`RowTerms` at distances ``phi`` (B, n) (m) and row velocities ``Jv``
        (B, n) (m/s, at the start of the step).

        Raises:
            ValueError: when a soft row lies beyond its margin (phi > margin): MuJoCo has no
                constraint there, so such a row must be left out of the step's LCP (as
                :class:`~drake_abs.multibody.stepper.ComplementarityStepper` does).
        """
        phi = np.asarray(phi, dtype=float)
        r = phi - self.margin
        soft = np.broadcast_to(self.soft, r.shape)
        beyond = soft & (r > 0)
        if beyond.any():
            raise ValueError(
                f"{int(beyond.sum())} soft contact row(s) lie beyond their margin (largest "
                f"phi - margin {float(r[beyond].max()):.3g} m): a soft row holds only within its "
                "margin; leave such rows out of the LCP"
            )
        d, dd = impedance(np.where(soft, r, 0.0), self.solimp)
        d = np.maximum(d, MIN_IMPEDANCE)
        R_raw = (1 - d) / d * self.weight
        floor = R_raw <= MIN_VALUE
        R = np.where(soft, np.maximum(R_raw, MIN_VALUE), 0.0)
        dR_dmu = np.zeros_like(R)
        if self.dweight_dmu is not None:
            dR_dmu = np.where(soft & ~floor, (1 - d) / d * self.dweight_dmu, 0.0)
        dR = np.where(soft & ~floor, -self.weight * dd / d**2, 0.0)
        c = np.where(soft, h * h * self.k0 * d * r + h * (h * self.b - 1) * Jv, phi)
        dc_dr = np.where(soft, h * h * self.k0 * (d + dd * r), 1.0)
        dc_dJv = np.where(soft, h * (h * self.b - 1), 0.0) + np.zeros_like(r)
        return RowTerms(R=R, c=c, dR_dr=dR, dc_dr=dc_dr, dc_dJv=dc_dJv, dR_dmu=dR_dmu)


@dataclass(frozen=True, eq=False)
class ContactCompliance:
    """MuJoCo's soft contact for a model's nc contact candidates (the module docstring): per
    candidate its ``solref`` (nc, 2), ``solimp`` (nc, 5), ``margin`` (nc,) (m; the candidate's
    rows exist while its distance is below this), ``inverse_weight`` (nc,) (1/kg, A_hat: the
    sum of the two bodies' translational inverse weights at the reference pose) and ``condim``
    (nc,) (MuJoCo's contact dimension: 1 frictionless, 3 sliding friction); ``impratio`` (> 0,
    MuJoCo's frictional-to-normal impedance ratio) and ``refsafe`` (raise timeconst to 2 h).
    Single values are broadcast to every candidate by :meth:`uniform`. Larger timeconst and
    smaller impedance are softer.

    Joint-limit rows (and any other rows after the contacts) stay hard.
    """

    solref: np.ndarray
    solimp: np.ndarray
    margin: np.ndarray
    inverse_weight: np.ndarray
    condim: np.ndarray
    impratio: float = 1.0
    refsafe: bool = True
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self):
        n = np.asarray(self.margin).reshape(-1).shape[0]
        set_ = object.__setattr__
        set_(self, "solref", _rows(self.solref, n, 2, "solref"))
        set_(self, "solimp", _rows(self.solimp, n, 5, "solimp"))
        check_solref(self.solref)
        check_solimp(self.solimp)
        margin = np.asarray(self.margin, dtype=float).reshape(-1)
        if not np.all(np.isfinite(margin) & (margin >= 0)):
            raise ValueError(f"margin must be finite numbers >= 0 (m); got {margin.tolist()}")
        weight = np.asarray(self.inverse_weight, dtype=float).reshape(-1)
        if weight.shape != (n,) or not np.all(np.isfinite(weight) & (weight > 0)):
            raise ValueError(
                f"inverse_weight must be {n} finite numbers > 0 (1/kg); got {weight.tolist()}"
            )
        condim = np.asarray(self.condim).reshape(-1)
        if condim.shape != (n,) or not np.all(np.isin(condim, (1, 3))):
            raise ValueError(
                f"condim must be {n} values, each 1 or 3 (MuJoCo's contact dimension: "
                f"frictionless or sliding friction); got {condim.tolist()}"
            )
        if not (np.isfinite(self.impratio) and self.impratio > 0):
            raise ValueError(f"impratio must be a finite number > 0; got {self.impratio!r}")
        set_(self, "margin", margin)
        set_(self, "inverse_weight", weight)
        set_(self, "condim", condim.astype(np.int64))
        set_(self, "impratio", float(self.impratio))
        set_(self, "refsafe", bool(self.refsafe))

    @classmethod
    def uniform(
        cls,
        n: int,
        inverse_weight,
        *,
        solref=DEFAULT_SOLREF,
        solimp=DEFAULT_SOLIMP,
        margin: float = 0.0,
        condim: int = 3,
        impratio: float = 1.0,
        refsafe: bool = True,
    ) -> ContactCompliance:
        """The same solref, solimp, margin and condim for all n candidates; ``inverse_weight``
        one value or (n,)."""
        weight = np.broadcast_to(np.asarray(inverse_weight, dtype=float), (n,)).copy()
        return cls(solref, solimp, np.full(n, float(margin)), weight, np.full(n, condim),
                   impratio, refsafe)  # fmt: skip

    def __reduce__(self):
        return (
            type(self),
            (self.solref, self.solimp, self.margin, self.inverse_weight, self.condim,
             self.impratio, self.refsafe),
        )  # fmt: skip

    @property
    def size(self) -> int:
        """nc, the number of candidates."""
        return self.margin.shape[0]

    def active(self, phi: np.ndarray) -> np.ndarray:
        """Which candidates have rows at distances ``phi`` (B, nc) (m): phi < margin (strictly,
        as MuJoCo's collision detection: a body resting exactly at its margin has no contact
        and falls for a step)."""
        return np.asarray(phi) < self.margin

    def rows(
        self,
        idx: np.ndarray,
        n_other: int,
        friction: np.ndarray,
        formulation: str,
        directions: int,
        h: float,
    ) -> SoftRows:
        """The :class:`SoftRows` of a step whose normal rows are the candidates ``idx``, then
        ``n_other`` hard rows (joint limits), at time step h, under the friction formulation
        (``"stewart_trinkle"`` or ``"anitescu"`` with ``directions`` k). ``friction`` (len(idx),)
        is each candidate's coefficient in the step's cone (NaN: frictionless): a candidate is
        frictional when it has one and its condim is 3. Row weights: the module docstring's
        ``R_n = R_e / n_e`` (Stewart-Trinkle) or ``R_e n_e / k`` per generator (Anitescu)."""
        idx = np.asarray(idx, dtype=np.int64)
        key = (idx.tobytes(), n_other, np.asarray(friction, float).tobytes(), formulation,
               directions, float(h))  # fmt: skip
        if key in self._cache:
            return self._cache[key]
        ref, imp = self.solref[idx], self.solimp[idx]
        dwidth = np.clip(imp[:, 1], MIN_IMPEDANCE, MAX_IMPEDANCE)
        standard = ref[:, 0] > 0
        tc = np.maximum(ref[:, 0], 2 * h) if self.refsafe else ref[:, 0]
        safe_tc = np.where(standard, tc, 1.0)
        k0 = np.where(
            standard,
            1 / np.maximum(MIN_VALUE, dwidth**2 * safe_tc**2 * ref[:, 1] ** 2),
            -ref[:, 0] / np.maximum(MIN_VALUE, dwidth**2),
        )
        b = np.where(
            standard,
            2 / np.maximum(MIN_VALUE, dwidth * safe_tc),
            -ref[:, 1] / np.maximum(MIN_VALUE, dwidth),
        )
        mu = np.asarray(friction, dtype=float)
        frictional = np.isfinite(mu) & (self.condim[idx] == 3)
        mu = np.where(frictional, mu, 0.0)
        tran = self.inverse_weight[idx]
        edges = 4  # 2 (condim - 1) edges of a pyramid with sliding friction
        edge = 2 * mu**2 / self.impratio * tran * (1 + mu**2)  # R_e (1 - d) / d = edge
        dedge = 2 * tran * (2 * mu + 4 * mu**3) / self.impratio
        per_row = edges / directions if formulation == "anitescu" else 1.0 / edges
        weight = np.where(frictional & (mu > 0), edge * per_row, tran)
        dweight = np.where(frictional & (mu > 0), dedge * per_row, 0.0)
        pad = np.zeros(n_other)
        rows = SoftRows(
            soft=np.concatenate([np.ones(idx.size, dtype=bool), np.zeros(n_other, dtype=bool)]),
            margin=np.concatenate([self.margin[idx], pad]),
            k0=np.concatenate([k0, pad]),
            b=np.concatenate([b, pad]),
            solimp=np.concatenate([imp, np.zeros((n_other, 5))]),
            weight=np.concatenate([weight, np.ones(n_other)]),
            dweight_dmu=np.concatenate([dweight, pad]),
        )
        self._cache[key] = rows
        return rows
