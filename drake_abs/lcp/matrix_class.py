"""What kind of LCP matrix F is, which decides what the interior-point solver can promise.

- ``PSD``: the symmetric part of F is positive semidefinite (a monotone LCP; rigid-body contact
  without friction, F = J M^-1 J^T). The central path exists and is unique whenever the LCP has a
  strictly feasible point.
- ``P_MATRIX``: every principal minor is positive (checked exactly for d <= 10, or by strict
  diagonal dominance with a positive diagonal). The LCP has a unique solution for every q.
- ``UNVERIFIED``: the symmetric part is indefinite and the P property could not be decided cheaply
  (d > 10); the LCP may be fine, but nothing is guaranteed.
- ``NOT_P``: a non-positive principal minor was found (for example the linearised friction cone,
  which is copositive but not P): solutions may be non-unique or missing.
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
        classes[rest] = sub
    return classes, min_eig
