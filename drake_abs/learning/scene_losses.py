"""The three losses of Bianchini et al. (2022) on any multibody scene with friction, and the
prediction loss of Zhang et al. (2023, eq. 6.1), with their gradients in the model parameters
theta (a stepper's ``parameter_names``: ground height, friction coefficients, masses, contact
geometry, joint damping, inertias).

Data are transitions ``(x, u, x+)``: states x (N, nq + nv), inputs u (N, nu), observed next
states x+ (N, nq + nv). A state-weight vector ``w`` (nq + nv,) (default all ones) weights the
squared errors: ``||a||_w^2 = sum_i w_i a_i^2``.

- **Explicit** (eq. 6.1 of Zhang et al.; eq. 2 of Bianchini et al.): the mean over the data of
  ``1/2 ||f(x, u; theta) - x+||_w^2``, with f the stepper's step (at its smoothing: **a larger mu
  smooths the landscape more**). Its gradient chains the step's ``dx_dtheta`` (implicit function
  theorem through the interior point).
- **Naive implicit** (their eq. 3): the prediction through the impulse that minimises the
  complementarity violation alone. That minimiser is the exact LCP solution, so this loss is
  the explicit loss under exact contact (mu = 0), whatever the stepper's smoothing.
- **Violation implicit** (their eq. 4): the mean over the data of ::

      min_lam  1/2 ||x+ - g(lam)||_w^2 + (1 / eps) h(phi, lam),
      g(lam) = (q + h N (v_free + W G^T lam),  v_free + W G^T lam),
      phi_j  = phi_c(j) + h G_j v+          (the gap at the step's end, at the OBSERVED v+),

  with h the complementarity violation of :mod:`drake_abs.learning.violation`. The impulses are
  those of the friction cone's generators ``G_j = n_c + alpha_c t_j`` (Anitescu's form, one per
  edge of the linearised cone; joint-limit rows and frictionless contacts: their normal only),
  whatever friction formulation the stepper steps with: with the generators, every partner is a
  function of the observed velocity alone, which keeps the inner problem convex and the loss
  the paper's. (In the Stewart-Trinkle form the friction rows' partners involve an unknown
  slack, and the inner problem is no longer convex.) **A larger eps relaxes the complementarity**
  (the loss trusts the data's prediction more); as eps -> 0 it tends to the prediction error of
  the exact model. The gradient is the envelope theorem's (lam held at the minimiser).

Units: SI; the loss is in the units of the weighted squared state.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from drake_abs.contact.smoothing import Exact
from drake_abs.learning.violation import violation_loss

#: the loss kinds :class:`ModelLoss` computes
KINDS = ("explicit", "naive_implicit", "violation_implicit")


@dataclass(frozen=True)
class LossValue:
    """A loss over a data set and its gradient.

    Attributes:
        loss: the mean over the transitions.
        grad: (T,) its gradient in the parameters ``names``.
        per_transition: (N,) each transition's term.
        converged: (N,) the step's solve (explicit) or the inner minimisation (violation
            implicit) met its tolerance; a loss with unconverged terms is reported, not hidden.
        names: the parameters of ``grad``.
    """

    loss: float
    grad: np.ndarray
    per_transition: np.ndarray
    converged: np.ndarray
    names: tuple[str, ...]

    @property
    def all_converged(self) -> bool:
        return bool(self.converged.all())


def _data(stepper, x, u, x_next) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    nq, nv, nu, _ = stepper.sizes
    nx = nq + nv
    arrays = []
    for name, a in (("x", x), ("u", u), ("x_next", x_next)):
        raw = np.asarray(a)
        if raw.dtype.kind not in "iuf":
            raise ValueError(f"{name} must be an array of real numbers; got dtype {raw.dtype}")
        arrays.append(raw.astype(float))
    x, u, x_next = arrays
    if x.ndim != 2 or x.shape[1] != nx:
        raise ValueError(f"x must have shape (N, nq + nv) = (N, {nx}); got {x.shape}")
    N = x.shape[0]
    if N == 0:
        raise ValueError(
            f"x must hold at least one transition (shape (N, {nx}) with N >= 1); got no rows: "
            "a loss over no data is undefined"
        )
    if x_next.shape != x.shape:
        raise ValueError(f"x_next must have the shape of x, (N, {nx}) = {x.shape}; got "
                         f"{x_next.shape}")  # fmt: skip
    if u.shape != (N, nu):
        raise ValueError(f"u must have shape (N, nu) = ({N}, {nu}); got {u.shape}")
    for name, a in (("x", x), ("u", u), ("x_next", x_next)):
        if not np.isfinite(a).all():
            raise ValueError(f"{name} must be finite")
    return x, u, x_next


def _weights(weights, nx: int) -> np.ndarray:
    if weights is None:
        return np.ones(nx)
    w = np.asarray(weights, dtype=float)
    if w.shape != (nx,) or not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ValueError(f"weights must be ({nx},) finite numbers >= 0; got {weights!r}")
    return w


def _columns(all_names: Sequence[str], names: Sequence[str] | None) -> tuple[list, tuple]:
    """The stepper columns of each learned parameter: a name, or a pattern with ``*`` (any
    text) that ties every matching column to one value (``"friction[*]"``: one coefficient
    for all contacts). A column may belong to one learned parameter only: a name given twice,
    or two patterns matching one column, is a ``ValueError`` naming both (the column would
    take the last one's value, and the first one's gradient would be wrong)."""
    all_names = tuple(all_names)
    if names is None:
        return [[i] for i in range(len(all_names))], all_names
    if isinstance(names, str):
        raise ValueError(f"names must be a sequence of parameter names; got the string {names!r}")
    names = list(names)
    groups = []
    for name in names:
        pattern = re.compile(".*".join(re.escape(part) for part in str(name).split("*")))
        cols = [i for i, n in enumerate(all_names) if pattern.fullmatch(n)]
        if not cols:
            raise ValueError(
                f"names must be among the stepper's parameter_names (or patterns with * "
                f"matching some); {name!r} matches none (known: {list(all_names)})"
            )
        for earlier, taken in zip(names, groups, strict=False):
            shared = sorted(set(cols) & set(taken))
            if shared:
                raise ValueError(
                    f"names must name each parameter once; {name!r} and {earlier!r} both set "
                    f"{all_names[shared[0]]!r}"
                    + (" (the same name given twice)" if str(name) == str(earlier) else "")
                )
        groups.append(cols)
    return groups, tuple(str(n) for n in names)


def learned_values(stepper, names: Sequence[str]) -> np.ndarray:
    """The stepper's current values (len(names),) of the learned parameters ``names`` (names
    of ``stepper.parameter_names`` or ``*`` patterns; a pattern's value is its first matching
    column's)."""
    groups, _ = _columns(stepper.parameter_names, names)
    values = stepper.parameter_values()
    return np.array([values[cols[0]] for cols in groups], dtype=float)


def stepper_at(stepper, names: Sequence[str], theta) -> object:
    """The stepper with the learned parameters ``names`` set to ``theta`` (len(names),): every
    column a pattern matches takes its value (``stepper.with_parameters``)."""
    groups, names = _columns(stepper.parameter_names, names)
    theta = np.asarray(theta, dtype=float)
    if theta.shape != (len(names),):
        raise ValueError(f"theta must have shape ({len(names)},) for {names}; got {theta.shape}")
    all_names = stepper.parameter_names
    return stepper.with_parameters(
        {all_names[c]: value for cols, value in zip(groups, theta, strict=True) for c in cols}
    )


def _grouped(d: np.ndarray, groups: list) -> np.ndarray:
    """Columns (last axis) summed per group: the derivative in a tied parameter."""
    return np.stack([d[..., cols].sum(axis=-1) for cols in groups], axis=-1)


def _needed(all_names, groups) -> tuple[list[str], list[list[int]]]:
    """The stepper columns the groups use (sorted), and each group's positions among them."""
    cols = sorted({c for g in groups for c in g})
    return [all_names[c] for c in cols], [[cols.index(c) for c in g] for g in groups]


def explicit_loss(
    stepper, x, u, x_next, *, names=None, weights=None, gradient: bool = True
) -> LossValue:
    """Eq. 6.1 (module docstring) at the stepper's parameters, through its step at its
    smoothing, with the gradient in ``names`` (default: all of ``stepper.parameter_names``);
    ``gradient=False``: the loss alone (``grad`` is NaN), at the cost of plain steps."""
    x, u, x_next = _data(stepper, x, u, x_next)
    groups, names = _columns(stepper.parameter_names, names)
    w = _weights(weights, x.shape[1])
    if not gradient:
        step = stepper.step(x, u, jacobians=False)
        r = step.x_next - x_next
        per = 0.5 * np.einsum("ni,i,ni->n", r, w, r)
        grad = np.full(len(groups), np.nan)
        return LossValue(float(per.mean()), grad, per, np.asarray(step.converged, bool), names)
    needed, local = _needed(stepper.parameter_names, groups)
    step = stepper.step(x, u, parameters=needed)
    r = step.x_next - x_next
    per = 0.5 * np.einsum("ni,i,ni->n", r, w, r)
    grad = np.einsum("ni,i,nit->t", r, w, _grouped(step.dx_dtheta, local)) / x.shape[0]
    return LossValue(float(per.mean()), grad, per, np.asarray(step.converged, bool), names)


def naive_implicit_loss(
    stepper, x, u, x_next, *, names=None, weights=None, gradient: bool = True
) -> LossValue:
    """Their eq. 3: the explicit loss under exact contact (module docstring)."""
    return explicit_loss(stepper.with_smoothing(Exact()), x, u, x_next, names=names,
                         weights=weights, gradient=gradient)  # fmt: skip


def violation_implicit_loss(
    stepper, x, u, x_next, eps: float, *, names=None, weights=None
) -> LossValue:
    """Their eq. 4 on the scene (module docstring), with its gradient in ``names``.

    Args:
        eps: > 0; the violation term's weight is 1 / eps (larger: looser complementarity).
    """
    if not (np.isfinite(eps) and eps > 0):
        raise ValueError(f"eps must be a finite number > 0; got {eps!r}")
    x, u, x_next = _data(stepper, x, u, x_next)
    nq, nv, _, _ = stepper.sizes
    w = _weights(weights, nq + nv)
    groups, names = _columns(stepper.parameter_names, names)
    needed, local = _needed(stepper.parameter_names, groups)  # summed per group at the end
    prob = stepper.contact_problem(x, u, parameters=needed)
    Q, cone, h, par = prob.quantities, prob.cone, prob.h, prob.parameters
    g = cone.generators
    fr = g.tangent >= 0
    a = (g.alpha * fr)[None, :, None]
    N = x.shape[0]

    def tangents(Jt):  # each generator's tangent row (zero for a normal-only generator)
        out = np.zeros((N, g.size) + Jt.shape[2:])
        out[:, fr] = Jt[:, g.tangent[fr]]
        return out

    Jt_g = tangents(Q.Jt)
    G = Q.Jn[:, g.contact] + a * Jt_g  # (N, ng, nv)
    v_obs = x_next[:, nq:]
    phi = Q.phi[:, g.contact] + h * np.einsum("ngj,nj->ng", G, v_obs)
    Dv = np.einsum("nij,ngj->nig", Q.W, G)  # (N, nv, ng)
    hN = h * Q.N
    g0 = np.concatenate([Q.q + np.einsum("nqj,nj->nq", hN, Q.v_free), Q.v_free], axis=1)
    D = np.concatenate([np.einsum("nqj,njg->nqg", hN, Dv), Dv], axis=1)
    # the theta columns kept
    T = len(needed)
    dphi_rows = par.dphi
    ng = g.size
    dalpha = np.zeros((ng, T))
    dalpha[fr] = par.dfriction[g.friction[fr]]
    dG = Jt_g[..., None] * dalpha[None, :, None, :]
    if par.dJn is not None:
        dG = dG + par.dJn[:, g.contact]
    if par.dJt is not None:
        dG = dG + a[..., None] * tangents(par.dJt)
    dphi = dphi_rows[:, g.contact] + h * np.einsum("ngjt,nj->ngt", dG, v_obs)
    dDv = np.einsum("nij,ngjt->nigt", Q.W, dG)
    if par.dW is not None:
        dDv = dDv + np.einsum("nijt,ngj->nigt", par.dW, G)
    dvf = np.zeros((N, nv, T)) if par.dv_free is None else par.dv_free
    dg0 = np.concatenate([np.einsum("nqj,njt->nqt", hN, dvf), dvf], axis=1)
    dD = np.concatenate([np.einsum("nqj,njgt->nqgt", hN, dDv), dDv], axis=1)
    s = np.sqrt(0.5 * w)  # 1/2 ||.||_w^2 = ||s .||^2
    r = violation_loss(
        s * x_next, s * g0, s[:, None] * D, phi, eps,
        dg0=s[:, None] * dg0, dD=s[:, None, None] * dD, dphi=dphi,
    )  # fmt: skip
    grad = _grouped(r.grad, local).mean(axis=0)
    return LossValue(float(r.loss.mean()), grad, r.loss, r.converged, names)


class ModelLoss:
    """One of the losses (``kind`` in :data:`KINDS`) of a data set as a function of the
    parameters ``names`` of a stepper: ``loss(theta)`` evaluates it at ``theta`` (len(names),)
    with the other parameters at the stepper's values (the stepper itself is not changed).

    Args:
        stepper: a multibody stepper (``parameter_names``, ``with_parameters``, ``step``,
            ``contact_problem``).
        x, u, x_next: the transitions (module docstring).
        names: the parameters to learn, among ``stepper.parameter_names``; a name with ``*``
            ties every matching column to one value (``"friction[*]"``).
        kind: ``"explicit"`` (eq. 6.1, through the stepper's smoothing), ``"naive_implicit"``
            or ``"violation_implicit"`` (needs ``eps``).
        eps: the violation weight's inverse (larger: looser complementarity).
        weights: (nq + nv,) state weights (default ones).
        gradient: compute the gradient (False: the loss alone, for random search).
    """

    def __init__(self, stepper, x, u, x_next, names: Sequence[str], kind: str = "explicit",
                 eps: float | None = None, weights=None, gradient: bool = True):  # fmt: skip
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}; got {kind!r}")
        if kind == "violation_implicit" and eps is None:
            raise ValueError("eps is needed for kind='violation_implicit' (a number > 0)")
        self.x, self.u, self.x_next = _data(stepper, x, u, x_next)
        self.groups, self.names = _columns(stepper.parameter_names, names)
        if not self.names:
            raise ValueError("names must name at least one parameter")
        self.stepper = stepper
        self.kind = kind
        self.eps = eps
        self.weights = _weights(weights, self.x.shape[1])
        self.gradient = bool(gradient)
        if not self.gradient and kind == "violation_implicit":
            raise ValueError(
                "gradient=False is for the explicit and naive-implicit losses (the violation "
                "loss's gradient costs little beyond its value)"
            )
        self.evaluations = 0

    def at(self, theta) -> object:
        """The stepper with the parameters ``names`` set to theta."""
        return stepper_at(self.stepper, self.names, theta)

    def __call__(self, theta) -> LossValue:
        stepper = self.at(theta)
        self.evaluations += 1
        args = (stepper, self.x, self.u, self.x_next)
        kw = dict(names=self.names, weights=self.weights)
        if self.kind == "explicit":
            return explicit_loss(*args, **kw, gradient=self.gradient)
        if self.kind == "naive_implicit":
            return naive_implicit_loss(*args, **kw, gradient=self.gradient)
        return violation_implicit_loss(*args, self.eps, **kw)
