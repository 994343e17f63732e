"""Deterministic policies ``u = pi(x; theta)`` batched over states, with the products the
policy-gradient engine needs (docs/math.md section 7; Zhang et al. 2023, eq. 4.1).

Exploration noise is not part of a policy: rollouts add ``sigma xi_t`` to its output
(reparameterisation), so first-order gradients flow through the same ``pi``.

Every policy follows :class:`drake_abs.engine.Policy`: for states x (M, nx) and a flat parameter
vector theta (P,):

- ``act(theta, x)`` -> u (M, nu);
- ``jacobians(theta, x)`` -> (du/dx (M, nu, nx), du/dtheta (M, nu, P));
- ``vjp(theta, x, g_u)`` -> (g_u du/dx (M, nx), g_u du/dtheta (M, P)): the reverse products of
  the adjoint pass, without forming du/dtheta (an MLP's can be large).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.engine.protocols import Policy

__all__ = ["LinearPolicy", "MLPPolicy", "Policy"]


def _check(theta, x, n_params: int, nx: int) -> tuple[np.ndarray, np.ndarray]:
    theta = as_finite_array(theta, "theta", ndim=(1,))
    if theta.shape != (n_params,):
        raise ValueError(f"theta must have shape (P,) = ({n_params},); got {theta.shape}")
    x = as_finite_array(x, "x", ndim=(2,))
    if x.shape[1] != nx:
        raise ValueError(f"x must have shape (M, nx) = (M, {nx}); got {x.shape}")
    return theta, x


@dataclass(frozen=True)
class LinearPolicy:
    """``u = K (x - x_ref) + k``; theta = (K row-major (nu nx), k (nu)) when ``bias``, else K."""

    nx: int
    nu: int
    bias: bool = True
    x_ref: tuple[float, ...] | None = None

    def __post_init__(self):
        if self.nx < 1 or self.nu < 1:
            raise ValueError(f"nx and nu must be >= 1; got {self.nx}, {self.nu}")
        if self.x_ref is not None and len(self.x_ref) != self.nx:
            raise ValueError(f"x_ref must have nx = {self.nx} entries; got {len(self.x_ref)}")

    @property
    def n_params(self) -> int:
        return self.nu * self.nx + (self.nu if self.bias else 0)

    def _split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        K = theta[: self.nu * self.nx].reshape(self.nu, self.nx)
        k = theta[self.nu * self.nx :] if self.bias else np.zeros(self.nu)
        return K, k

    def _dx(self, x: np.ndarray) -> np.ndarray:
        return x if self.x_ref is None else x - np.asarray(self.x_ref, float)

    def act(self, theta, x) -> np.ndarray:
        theta, x = _check(theta, x, self.n_params, self.nx)
        K, k = self._split(theta)
        return self._dx(x) @ K.T + k

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        theta, x = _check(theta, x, self.n_params, self.nx)
        K, _ = self._split(theta)
        M = x.shape[0]
        du_dx = np.broadcast_to(K, (M, self.nu, self.nx)).copy()
        du_dth = np.zeros((M, self.nu, self.n_params))
        dx = self._dx(x)
        for i in range(self.nu):
            du_dth[:, i, i * self.nx : (i + 1) * self.nx] = dx
            if self.bias:
                du_dth[:, i, self.nu * self.nx + i] = 1.0
        return du_dx, du_dth

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        theta, x = _check(theta, x, self.n_params, self.nx)
        K, _ = self._split(theta)
        g_u = np.asarray(g_u, float)
        g_th = np.einsum("mi,mj->mij", g_u, self._dx(x)).reshape(x.shape[0], -1)
        if self.bias:
            g_th = np.concatenate([g_th, g_u], axis=1)
        return g_u @ K, g_th


@dataclass(frozen=True)
class MLPPolicy:
    """A multilayer perceptron ``u = W_L tanh(... tanh(W_1 x + b_1) ...) + b_L``, scaled by
    ``output_scale``. theta stacks each layer's (W row-major, b).

    Args:
        nx, nu: state and input sizes.
        hidden: widths of the hidden layers.
        output_scale: multiplies the output (units of u).
    """

    nx: int
    nu: int
    hidden: tuple[int, ...] = (32,)
    output_scale: float = 1.0

    def __post_init__(self):
        if self.nx < 1 or self.nu < 1 or any(h < 1 for h in self.hidden):
            raise ValueError("nx, nu and every hidden width must be >= 1")

    @property
    def sizes(self) -> list[int]:
        return [self.nx, *self.hidden, self.nu]

    @property
    def n_params(self) -> int:
        s = self.sizes
        return sum(s[i + 1] * s[i] + s[i + 1] for i in range(len(s) - 1))

    def init(self, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
        """Glorot-style random weights (zero biases), from the given generator."""
        parts = []
        s = self.sizes
        for i in range(len(s) - 1):
            std = scale * np.sqrt(2.0 / (s[i] + s[i + 1]))
            parts += [std * rng.standard_normal(s[i + 1] * s[i]), np.zeros(s[i + 1])]
        return np.concatenate(parts)

    def _layers(self, theta: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        out, o, s = [], 0, self.sizes
        for i in range(len(s) - 1):
            W = theta[o : o + s[i + 1] * s[i]].reshape(s[i + 1], s[i])
            o += s[i + 1] * s[i]
            b = theta[o : o + s[i + 1]]
            o += s[i + 1]
            out.append((W, b))
        return out

    def _forward(self, theta, x):
        layers = self._layers(theta)
        acts = [x]
        for W, b in layers[:-1]:
            acts.append(np.tanh(acts[-1] @ W.T + b))
        W, b = layers[-1]
        return layers, acts, self.output_scale * (acts[-1] @ W.T + b)

    def act(self, theta, x) -> np.ndarray:
        theta, x = _check(theta, x, self.n_params, self.nx)
        return self._forward(theta, x)[2]

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        return self._backward(theta, x, g_u, summed=False)

    def vjp_sum(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        """(g_u du/dx (M, nx), sum_m g_u[m] du/dtheta[m] (P,)): ``vjp`` with the parameter part
        summed over the batch, without forming one product per row (the gradient of a
        loss summed over samples, e.g. a critic's fit)."""
        return self._backward(theta, x, g_u, summed=True)

    def _backward(self, theta, x, g_u, summed: bool) -> tuple[np.ndarray, np.ndarray]:
        theta, x = _check(theta, x, self.n_params, self.nx)
        layers, acts, _ = self._forward(theta, x)
        g = self.output_scale * np.asarray(g_u, float)  # (M, n_out)
        grads = []
        for layer in range(len(layers) - 1, -1, -1):
            W, _ = layers[layer]
            a_in = acts[layer]
            if summed:
                grads.append(np.concatenate([(g.T @ a_in).reshape(-1), g.sum(axis=0)]))
            else:
                outer = np.einsum("mi,mj->mij", g, a_in).reshape(len(x), -1)
                grads.append(np.concatenate([outer, g], 1))
            g = g @ W
            if layer > 0:
                g = g * (1.0 - acts[layer] ** 2)  # tanh'
        return g, np.concatenate(grads[::-1], axis=-1)

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        theta, x = _check(theta, x, self.n_params, self.nx)
        rows = [self.vjp(theta, x, np.broadcast_to(e, (len(x), self.nu))) for e in np.eye(self.nu)]
        return np.stack([r[0] for r in rows], 1), np.stack([r[1] for r in rows], 1)
