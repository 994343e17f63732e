"""Hard LCPs, named: the problem families the solver's tests and ``benchmarks/bench_lcp.py``
(section 5) are run on (docs/math.md section 3b).

Each family gives LCPs ``w = F lam + q >= 0, lam >= 0, lam^T w = 0`` (dimensionless). The
classical ones are fixed matrices of any size d, with a known solution:

- :func:`csizmadia`: lower triangular P-matrices with an exponential handicap (the interior
  point alone diverges from d = 32);
- :func:`murty`: Murty's problem (1 on the diagonal, 2 below, q = -1);
- :func:`fathy`: Fathy's problem (``L L^T`` with L of Murty's problem, positive definite).

The random ones are batches of n problems drawn from a :class:`numpy.random.Generator`; the
same generator state gives the same problems, bit for bit, so a caller seeds them with
``numpy.random.default_rng(seed)``:

- :func:`random_p_matrices`: P-matrices with a positive definite symmetric part (the easy
  reference);
- :func:`scaled_p_matrices`, :func:`scaled_p_problems`: non-symmetric P-matrices whose symmetric
  part is indefinite (beyond the exact principal-minor check for d > 10);
- :func:`singular_psd_problems`: singular positive semidefinite matrices (rank d/2) with a
  strictly feasible q (the answer is not unique);
- :func:`ill_conditioned_problems`: symmetric positive definite with condition number 1e10;
- :func:`friction_problems`: Stewart-Trinkle frictional contact LCPs (copositive, not P).
"""

from __future__ import annotations

import numpy as np


def csizmadia(d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Csizmadia's matrix F (d, d): 1 on the diagonal, -1 below, 0 above (lower triangular, a
    P-matrix with every principal minor 1 and an exponential handicap), and the q (d,) whose
    solution is x = (1, 0, 1, 0, ...) (d,), with w = (0, 1, 0, 1, ...). Returns (F, q, x)."""
    F = 2.0 * np.eye(d) - np.tril(np.ones((d, d)))
    x = (np.arange(d) % 2 == 0).astype(float)
    q = 1.0 - x - F @ x
    return F, q, x


def murty(d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Murty's problem: F (d, d) with 1 on the diagonal and 2 below, q = -1 (d,); its solution
    is e_1 (d,). Returns (F, q, x)."""
    F = np.eye(d) + 2.0 * np.tril(np.ones((d, d)), -1)
    x = np.zeros(d)
    x[0] = 1.0
    return F, -np.ones(d), x


def fathy(d: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fathy's problem: F = L L^T (d, d) with L lower triangular (1 on the diagonal, 2 below:
    the F of :func:`murty`), positive definite; q = -1 (d,); its solution is e_1 (d,). Returns
    (F, q, x)."""
    L = murty(d)[0]
    x = np.zeros(d)
    x[0] = 1.0
    return L @ L.T, -np.ones(d), x


def random_p_matrices(rng: np.random.Generator, d: int, n: int) -> np.ndarray:
    """n random P-matrices (n, d, d): ``A A^T / d + 0.1 I + 0.3 (W - W^T)`` with A and W
    standard normal (d, d); the symmetric part is positive definite, so the LCP has a unique
    solution for every q."""
    A = rng.standard_normal((n, d, d))
    W = rng.standard_normal((n, d, d))
    return A @ A.transpose(0, 2, 1) / d + 0.1 * np.eye(d) + 0.3 * (W - W.transpose(0, 2, 1))


def scaled_p_matrices(rng: np.random.Generator, d: int, n: int) -> np.ndarray:
    """n non-symmetric P-matrices (n, d, d) whose symmetric part is indefinite: ``D1 P D2``
    with P of :func:`random_p_matrices` and positive diagonals D1, D2 over two decades
    (``10^U(-1, 1)``; a positive diagonal scaling keeps every principal minor's sign)."""
    P = random_p_matrices(rng, d, n)
    D1 = 10 ** rng.uniform(-1, 1, (n, d, 1))
    D2 = 10 ** rng.uniform(-1, 1, (n, 1, d))
    return D1 * P * D2


def scaled_p_problems(rng: np.random.Generator, d: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """n LCPs with the matrices F (n, d, d) of :func:`scaled_p_matrices` and q (n, d) standard
    normal."""
    return scaled_p_matrices(rng, d, n), rng.standard_normal((n, d))


def singular_psd_problems(
    rng: np.random.Generator, d: int, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """n LCPs with F = J J^T (n, d, d) of rank d/2 (J standard normal (d, max(1, d // 2))) and
    a strictly feasible q = s0 - F lam0 (n, d) (lam0, s0 uniform in [0.01, 1)): the central
    path exists, the solution's F lam is unique but lam is not."""
    J = rng.standard_normal((n, d, max(1, d // 2)))
    F = J @ J.transpose(0, 2, 1)
    lam0 = rng.uniform(0.01, 1.0, (n, d))
    s0 = rng.uniform(0.01, 1.0, (n, d))
    return F, s0 - np.einsum("bij,bj->bi", F, lam0)


def ill_conditioned_problems(
    rng: np.random.Generator, d: int, n: int
) -> tuple[np.ndarray, np.ndarray]:
    """n LCPs with F (n, d, d) symmetric positive definite, eigenvalues log-spaced over 1 ..
    1e-10 (condition number 1e10) in random orthonormal bases, and q (n, d) standard normal."""
    Qm, _ = np.linalg.qr(rng.standard_normal((n, d, d)))
    F = Qm @ (np.logspace(0, -10, d)[None, :, None] * Qm.transpose(0, 2, 1))
    return 0.5 * (F + F.transpose(0, 2, 1)), rng.standard_normal((n, d))


def friction_problems(
    rng: np.random.Generator, nc: int, n: int, k: int = 4
) -> tuple[np.ndarray, np.ndarray]:
    """n Stewart-Trinkle LCPs in ``lam = (gamma, beta, omega)``, d = nc (2 + k): F (n, d, d),
    q (n, d). Per problem: a random inverse mass matrix ``(A A^T / nv + I)^-1`` (nv = 2 nc +
    6), normal and tangent Jacobians (nc, nv) and (nc k, nv), velocity (nv,) standard normal,
    distances over the step in [-1, 1) (nc,), friction coefficient 0.5 and k tangent
    directions per contact. Copositive, not P: a solver must attempt it without the P-matrix
    check."""
    nv = 2 * nc + 6
    F = np.zeros((n, nc * (2 + k), nc * (2 + k)))
    q = np.zeros((n, nc * (2 + k)))
    E = np.kron(np.eye(nc), np.ones((k, 1)))  # (nc k, nc)
    for b in range(n):
        A = rng.standard_normal((nv, nv))
        Minv = np.linalg.inv(A @ A.T / nv + np.eye(nv))
        Jn = rng.standard_normal((nc, nv))
        Dt = rng.standard_normal((nc * k, nv))
        v = rng.standard_normal(nv)
        phi_h = rng.uniform(-1.0, 1.0, nc)
        G = np.vstack([Jn, Dt])
        W = G @ Minv @ G.T
        F[b, : nc * (1 + k), : nc * (1 + k)] = W
        F[b, nc : nc * (1 + k), nc * (1 + k) :] = E
        F[b, nc * (1 + k) :, :nc] = 0.5 * np.eye(nc)
        F[b, nc * (1 + k) :, nc : nc * (1 + k)] = -E.T
        q[b, :nc] = Jn @ v + phi_h
        q[b, nc : nc * (1 + k)] = Dt @ v
    return F, q
