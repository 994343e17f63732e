"""What kind of LCP matrix F is, which decides what the interior-point solver can promise.

- ``PSD``: the symmetric part of F is positive semidefinite (a monotone LCP; rigid-body contact
  without friction, F = J M^-1 J^T). The central path exists and is unique whenever the LCP has a
  strictly feasible point.
- ``P_MATRIX``: every principal minor is positive. The LCP has a unique solution for every q.
  Shown exactly for d <= 10 (all 2^d - 1 minors), and for any d by one of three cheap
  sufficient tests: strict diagonal dominance with a positive diagonal; a positive diagonal on a
  matrix that a symmetric permutation makes triangular (every principal minor is then a product
  of diagonal entries: Murty's and Csizmadia's matrices); or a positive diagonal with a
  certificate that F is an H-matrix (a vector x > 0 with ``C x > 0`` for the comparison matrix
  ``C_ii = |F_ii|, C_ij = -|F_ij|``, checked with a rounding-error margin).
- ``UNVERIFIED``: the symmetric part is indefinite and neither the P property nor its failure
  could be shown cheaply (d > 10). The solver attempts such problems and verifies what it
  returns; nothing else is promised.
- ``NOT_P``: a non-positive principal minor was found: for d > 10 a diagonal entry or a 2 x 2
  minor (for example the linearised friction cone, copositive but not P, with zeros on its
  diagonal). Solutions may be non-unique or missing.
"""

from __future__ import annotations

import itertools
from enum import IntEnum

import numpy as np

#: Largest d for which all 2^d - 1 principal minors are checked.
MAX_EXACT_P_CHECK = 10


class MatrixClass(IntEnum):
    PSD = 0
    P_MATRIX = 1
    UNVERIFIED = 2
    NOT_P = 3


def symmetric_part_min_eigenvalue(F: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue of (F + F^T)/2 for F of shape (..., d, d); returns shape (...)."""
    sym = 0.5 * (F + np.swapaxes(F, -1, -2))
    return np.linalg.eigvalsh(sym)[..., 0]


def _strictly_diagonally_dominant(F: np.ndarray) -> np.ndarray:
    diag = np.diagonal(F, axis1=-2, axis2=-1)
    off = np.abs(F).sum(axis=-1) - np.abs(diag)
    off_col = np.abs(F).sum(axis=-2) - np.abs(diag)
    return np.all(diag > 0, axis=-1) & (
        np.all(diag > off, axis=-1) | np.all(diag > off_col, axis=-1)
    )


def _permuted_triangular(F: np.ndarray) -> bool:
    """True when a symmetric permutation makes F (d, d) triangular: the graph with an edge
    j -> i for every non-zero off-diagonal F_ij has no cycle (vertices without incoming edges
    are peeled off until none are left, or none can be)."""
    edges = (F != 0) & ~np.eye(F.shape[0], dtype=bool)
    alive = np.ones(F.shape[0], dtype=bool)
    while alive.any():
        sub = edges[np.ix_(alive, alive)]
        sources = ~sub.any(axis=1)  # rows of the surviving block without off-diagonal entries
        if not sources.any():
            return False
        alive[np.flatnonzero(alive)[sources]] = False
    return True


def _h_matrix_certificate(F: np.ndarray) -> bool:
    """True when F (d, d) has a positive diagonal and a vector x > 0 gives ``C x > 0`` for its
    comparison matrix C, beyond the rounding error of computing ``C x``
    (``gamma_d (|C| x)``): then C is a non-singular M-matrix, F an H-matrix with a positive
    diagonal, hence a P-matrix. The candidate x solves ``C x = 1``."""
    diag = np.diagonal(F)
    if not np.all(diag > 0):
        return False
    C = -np.abs(F)
    np.fill_diagonal(C, diag)
    with np.errstate(all="ignore"):
        try:
            x = np.linalg.solve(C, np.ones(F.shape[0]))
        except np.linalg.LinAlgError:
            return False
        if not np.all(np.isfinite(x) & (x > 0)):
            return False
        d = F.shape[0]
        eps = np.finfo(float).eps
        gamma = (d + 1) * eps / (1 - (d + 1) * eps)
        return bool(np.all(C @ x > gamma * (np.abs(C) @ x)))


def _small_minor_not_positive(F: np.ndarray) -> np.ndarray:
    """(...,) True where a diagonal entry or a 2 x 2 principal minor of F (..., d, d) is <= 0."""
    diag = np.diagonal(F, axis1=-2, axis2=-1)
    minors = diag[..., :, None] * diag[..., None, :] - F * np.swapaxes(F, -1, -2)
    off = ~np.eye(F.shape[-1], dtype=bool)
    return np.any(diag <= 0, axis=-1) | np.any((minors <= 0) & off, axis=(-2, -1))


def _all_principal_minors_positive(F: np.ndarray) -> np.ndarray:
    d = F.shape[-1]
    ok = np.ones(F.shape[:-2], dtype=bool)
    for k in range(1, d + 1):
        for idx in itertools.combinations(range(d), k):
            sub = F[..., idx, :][..., :, idx]
            ok &= np.linalg.det(sub) > 0
            if not ok.any():
                return ok
    return ok


def classify_matrix(F: np.ndarray, *, psd_tol: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Classify F of shape (..., d, d).

    Args:
        F: LCP matrices.
        psd_tol: the symmetric part counts as PSD when its smallest eigenvalue is at least
            ``-psd_tol * max|F|`` (relative to the matrix's size, dimensionless).

    Returns:
        ``(classes, min_eig)``: an int array of :class:`MatrixClass` values and the smallest
        eigenvalue of the symmetric part, both of shape (...).
    """
    min_eig = symmetric_part_min_eigenvalue(F)
    scale = np.max(np.abs(F), axis=(-2, -1))
    classes = np.full(F.shape[:-2], MatrixClass.UNVERIFIED, dtype=np.int8)
    psd = min_eig >= -psd_tol * np.maximum(scale, np.finfo(float).tiny)
    classes[psd] = MatrixClass.PSD
    rest = ~psd
    if rest.any():
        Fr = F[rest]
        dominant = _strictly_diagonally_dominant(Fr)
        sub = np.full(Fr.shape[0], MatrixClass.UNVERIFIED, dtype=np.int8)
        sub[dominant] = MatrixClass.P_MATRIX
        if F.shape[-1] <= MAX_EXACT_P_CHECK and (~dominant).any():
            p = _all_principal_minors_positive(Fr[~dominant])
            sub[np.flatnonzero(~dominant)] = np.where(p, MatrixClass.P_MATRIX, MatrixClass.NOT_P)
        elif (~dominant).any():  # d > 10: cheap sufficient tests, then cheap necessary ones
            for k in np.flatnonzero(~dominant):
                Fk = Fr[k]
                if np.all(np.diagonal(Fk) > 0) and (
                    _permuted_triangular(Fk) or _h_matrix_certificate(Fk)
                ):
                    sub[k] = MatrixClass.P_MATRIX
                elif _small_minor_not_positive(Fk):
                    sub[k] = MatrixClass.NOT_P
        classes[rest] = sub
    return classes, min_eig
