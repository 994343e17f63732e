"""Central finite differences, the reference every analytic Jacobian is checked against."""

import numpy as np


def central_difference(f, x, eps=1e-6):
    """Jacobian of f at x by central differences: f(x) (m,) -> (m, n) for x (n,)."""
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(x.size):
        e = np.zeros_like(x)
        e.flat[i] = eps
        cols.append((np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * eps))
    return np.stack(cols, axis=-1)


def random_p_matrix(rng, d, *, skew=0.3, shift=0.1):
    """A random P-matrix: positive definite symmetric part plus a skew-symmetric part."""
    A = rng.normal(size=(d, d))
    W = rng.normal(size=(d, d))
    return A @ A.T / d + shift * np.eye(d) + skew * (W - W.T)
