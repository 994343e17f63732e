"""Observation normalisation: running statistics of the observations seen in training, and the
affine map ``z = (o - mean) / std`` they define, put in front of a policy.

- :class:`RunningMeanStd`: the mean and (population) standard deviation of every row pushed so
  far, updated by batches (Chan, Golub and LeVeque's pairwise combination of counts, means and
  sums of squared deviations): numpy's ``mean`` and ``std`` of all pushed rows, to rounding. ARS
  V2 (:mod:`drake_abs.policy.ars_v2`) and SHAC (:mod:`drake_abs.policy.shac`) keep one.
- :class:`NormalizedPolicy`: ``u = pi((o - mean) / std; theta)`` for an inner policy ``pi`` of
  the normalised input; mean and std (n,) are frozen in it (a training loop builds the next one
  when its statistics change). The parameters are the inner policy's, so an exported linear
  policy is ``action = W (obs - mean) / std + b`` with (W, b) the inner policy's.

Units: mean in the units of each observation entry, std likewise (> 0); z is dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_count, as_finite_array
from drake_abs.engine.protocols import Policy, check_protocol

__all__ = ["NormalizedPolicy", "RunningMeanStd"]


class RunningMeanStd:
    """Mean and population standard deviation of every row pushed so far (see the module
    docstring). Before the first push: mean 0, std 1.

    Args:
        nx: the number of entries of a row (a state's or an observation's size).
    """

    def __init__(self, nx: int):
        if isinstance(nx, bool) or not isinstance(nx, int | np.integer) or nx < 1:
            raise ValueError(f"nx must be a whole number >= 1; got {nx!r}")
        self.nx = int(nx)
        self.count = 0
        self._mean = np.zeros(self.nx)
        self._m2 = np.zeros(self.nx)

    def push(self, states) -> None:
        """Add rows (n, nx)."""
        x = as_finite_array(states, "states", ndim=(2,))
        if x.shape[1] != self.nx:
            raise ValueError(f"states must have shape (n, nx) = (n, {self.nx}); got {x.shape}")
        n = x.shape[0]
        if n == 0:
            return
        b_mean = x.mean(axis=0)
        b_m2 = ((x - b_mean) ** 2).sum(axis=0)
        total = self.count + n
        delta = b_mean - self._mean
        self._mean = self._mean + delta * (n / total)
        self._m2 = self._m2 + b_m2 + delta**2 * (self.count * n / total)
        self.count = total

    @property
    def mean(self) -> np.ndarray:
        """(nx,) the mean of the rows pushed (0 before the first)."""
        return self._mean.copy()

    @property
    def std(self) -> np.ndarray:
        """(nx,) the population standard deviation of the rows pushed (1 before the first)."""
        if self.count == 0:
            return np.ones(self.nx)
        return np.sqrt(self._m2 / self.count)

    def floored_std(self, min_std: float) -> np.ndarray:
        """(nx,) ``max(std, min_std)``: a divisor that never comes near 0 (a coordinate that
        barely varied so far is scaled by 1 / min_std, not by its own tiny spread)."""
        if not (np.isfinite(min_std) and min_std > 0):
            raise ValueError(f"min_std must be a finite number > 0; got {min_std!r}")
        return np.maximum(self.std, min_std)

    def state(self) -> dict[str, np.ndarray | int]:
        """Everything that defines the statistics (for a checkpoint): ``count``, ``mean``,
        ``m2`` (the sums of squared deviations)."""
        return {"count": self.count, "mean": self._mean.copy(), "m2": self._m2.copy()}

    @classmethod
    def from_state(cls, state: dict) -> RunningMeanStd:
        """The statistics :meth:`state` described, bit for bit."""
        mean = as_finite_array(state["mean"], "state['mean']", ndim=(1,))
        m2 = as_finite_array(state["m2"], "state['m2']", ndim=(1,))
        if m2.shape != mean.shape:
            raise ValueError(f"state['m2'] must have shape {mean.shape}; got {m2.shape}")
        out = cls(mean.size)
        out.count = as_count(state["count"], "state['count']")
        out._mean, out._m2 = mean.copy(), m2.copy()
        return out


@dataclass(frozen=True, eq=False)
class NormalizedPolicy:
    """``u = inner((o - mean) / std; theta)``: a :class:`~drake_abs.engine.protocols.Policy` of
    o (M, n) whose input is normalised by frozen statistics.

    Args:
        inner: a policy of the normalised input (``inner.nx == n``).
        mean: (n,) subtracted from o (units of o).
        std: (n,) divides o - mean (units of o), every entry finite and > 0.
    """

    inner: Policy
    mean: np.ndarray
    std: np.ndarray

    def __post_init__(self):
        check_protocol(self.inner, Policy, "inner", "nx, nu, n_params, act, jacobians, vjp")
        n = self.inner.nx
        for name in ("mean", "std"):
            arr = as_finite_array(getattr(self, name), name, ndim=(1,))
            if arr.shape != (n,):
                raise ValueError(
                    f"{name} must have shape (n,) = ({n},) (inner.nx); got {arr.shape}"
                )
            object.__setattr__(self, name, arr.copy())
        if np.any(self.std <= 0):
            raise ValueError("std must be > 0 in every entry")

    @property
    def nx(self) -> int:
        return self.inner.nx

    @property
    def nu(self) -> int:
        return self.inner.nu

    @property
    def n_params(self) -> int:
        return self.inner.n_params

    def normalize(self, o) -> np.ndarray:
        """z = (o - mean) / std (M, n)."""
        o = as_finite_array(o, "o", ndim=(2,))
        if o.shape[1] != self.nx:
            raise ValueError(f"o must have shape (M, n) = (M, {self.nx}); got {o.shape}")
        return (o - self.mean) / self.std

    def act(self, theta, x) -> np.ndarray:
        """u (M, nu) at inputs x (M, n) (the un-normalised observations)."""
        return self.inner.act(theta, self.normalize(x))

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        """(du/dx (M, nu, n), du/dtheta (M, nu, P))."""
        du_dz, du_dth = self.inner.jacobians(theta, self.normalize(x))
        return du_dz / self.std, du_dth

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        """(g_u du/dx (M, n), g_u du/dtheta (M, P)) for g_u (M, nu)."""
        g_z, g_th = self.inner.vjp(theta, self.normalize(x), g_u)
        return g_z / self.std, g_th
