"""The interior-point iterations of :mod:`drake_abs.lcp.ipm`, compiled (numba), one problem at a
time over a batch: the algorithm and safeguards of the ``ipm`` module docstring, on the scaled
problem. It is the only implementation of the iterations; :func:`drake_abs.solve_lcp` validates,
scales and calls it, and computes the implicit Jacobians afterwards.

Work arrays are allocated once per call and reused across problems and iterations; the Newton
matrix is factored once per iteration (compiled LU with partial pivoting for d <= 32, LAPACK's
inverse above) for the predictor and corrector solves (pseudo-inverse steps when it is singular).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from drake_abs.lcp.status import LCPStatus

# The status codes, as plain integers for the compiled code (defined once, in LCPStatus).
CONVERGED = int(LCPStatus.CONVERGED)
MAX_ITERATIONS = int(LCPStatus.MAX_ITERATIONS)
NUMERICAL_FAILURE = int(LCPStatus.NUMERICAL_FAILURE)

#: Wide-neighbourhood constant; contacts still driving down keep lam_i s_i >= GAMMA * mean.
GAMMA = 1e-3
#: Step-length backtracking factors (neighbourhood and merit searches).
BACKTRACK = np.array([1.0, 0.5, 0.25, 0.1, 0.03, 0.01])
_TINY = np.finfo(np.float64).tiny
#: Fraction of the step to the boundary taken by default, and the smallest gap (scaled units)
#: that the adaptive fraction ``1 - tau = mu_cur`` near the solution follows.
STEP_TO_BOUNDARY = 0.995
MIN_STEP_GAP = 1e-10
#: The adaptive fraction is tried only for a nearly full Newton step (a_max at least this).
NEAR_FULL_STEP = 0.9
#: A step may not leave a product lam_i s_i below this fraction of its target (else a contact
#: held at its target could be driven to the boundary and stall).
TARGET_FLOOR = 0.5
#: Armijo sufficient-decrease slope of the residual merit (non-monotone problems).
ARMIJO_SLOPE = 1e-4
#: Mehrotra's correction is dropped once the measure fails to fall below STALL_RATIO times its
#: best value for STALLS_BEFORE_NO_CORRECTOR iterations in a row: the corrector can cycle.
STALL_RATIO = 0.5
STALLS_BEFORE_NO_CORRECTOR = 3
#: Roundoff that a contact held at a large target mu_j couples into a neighbour i through F
#: (relative to mu_j): part of contact i's absolute complementarity tolerance.
COUPLED_ROUNDOFF = 1e-13
#: Newton matrix: explicit Gauss-Jordan inverse up to this size, compiled LU above it up to
#: _LAPACK_FROM, LAPACK's inverse beyond (measured crossovers on this machine).
_GAUSS_JORDAN_TO = 4
_LAPACK_FROM = 32


@nb.njit(cache=True, inline="always")
def gauss_jordan_inverse(K, out, aug):
    """out = K^-1 by Gauss-Jordan with partial pivoting; False when singular."""
    d = K.shape[0]
    for i in range(d):
        for j in range(d):
            aug[i, j] = K[i, j]
            aug[i, d + j] = 1.0 if i == j else 0.0
    for c in range(d):
        p = c
        best = abs(aug[c, c])
        for r in range(c + 1, d):
            if abs(aug[r, c]) > best:
                best = abs(aug[r, c])
                p = r
        if not (best > 0.0) or not np.isfinite(best):
            return False
        if p != c:
            for j in range(2 * d):
                tmp = aug[c, j]
                aug[c, j] = aug[p, j]
                aug[p, j] = tmp
        inv_piv = 1.0 / aug[c, c]
        for j in range(c, 2 * d):  # columns left of c are zero in row c
            aug[c, j] *= inv_piv
        for r in range(d):
            if r != c:
                f = aug[r, c]
                if f != 0.0:
                    for j in range(c, 2 * d):
                        aug[r, j] -= f * aug[c, j]
    for i in range(d):
        for j in range(d):
            out[i, j] = aug[i, d + j]
            if not np.isfinite(out[i, j]):
                return False
    return True


@nb.njit(cache=True)
def _lu_factor(K, LU, piv):
    """LU = K with partial pivoting (Doolittle, in place in LU; row swaps in piv); False when
    K is singular to working precision or not finite."""
    d = K.shape[0]
    for i in range(d):
        for j in range(d):
            LU[i, j] = K[i, j]
    for c in range(d):
        p = c
        best = abs(LU[c, c])
        for r in range(c + 1, d):
            if abs(LU[r, c]) > best:
                best = abs(LU[r, c])
                p = r
        if not (best > 0.0) or not np.isfinite(best):
            return False
        piv[c] = p
        if p != c:
            for j in range(d):
                tmp = LU[c, j]
                LU[c, j] = LU[p, j]
                LU[p, j] = tmp
        inv = 1.0 / LU[c, c]
        for r in range(c + 1, d):
            f = LU[r, c] * inv
            LU[r, c] = f
            if f != 0.0:
                for j in range(c + 1, d):
                    LU[r, j] -= f * LU[c, j]
    return True


@nb.njit(cache=True)
def _lu_solve(LU, piv, b, out):
    """out = K^-1 b from the factors of :func:`_lu_factor`."""
    d = b.shape[0]
    for i in range(d):
        out[i] = b[i]
    for c in range(d):
        p = piv[c]
        if p != c:
            tmp = out[c]
            out[c] = out[p]
            out[p] = tmp
    for i in range(d):
        acc = out[i]
        for j in range(i):
            acc -= LU[i, j] * out[j]
        out[i] = acc
    for i in range(d - 1, -1, -1):
        acc = out[i]
        for j in range(i + 1, d):
            acc -= LU[i, j] * out[j]
        out[i] = acc / LU[i, i]


@nb.njit(cache=True)
def _matvec(A, x, out):
    d = x.shape[0]
    for i in range(A.shape[0]):
        acc = 0.0
        for j in range(d):
            acc += A[i, j] * x[j]
        out[i] = acc


@nb.njit(cache=True)
def _max_step(x, dx):
    a = np.inf
    for i in range(x.shape[0]):
        if dx[i] < 0.0:
            r = -x[i] / dx[i]
            if r < a:
                a = r
    return a


@nb.njit(cache=True)
def _neighbourhood_ok(L, S, dl, ds, a, drive, target, strict):
    d = L.shape[0]
    n = 0
    total = 0.0
    for i in range(d):
        if drive[i]:
            n += 1
            total += (L[i] + a * dl[i]) * (S[i] + a * ds[i])
    mean = total / max(n, 1)
    for i in range(d):
        new = (L[i] + a * dl[i]) * (S[i] + a * ds[i])
        if drive[i]:
            floor = GAMMA * mean if strict else min(GAMMA * mean, TARGET_FLOOR * target[i])
            if new < floor:
                return False
    return True


@nb.njit(cache=True)
def _merit(F, q, L, S, dl, ds, a, target, gap_scale, row_scale, La, FLa):
    d = L.shape[0]
    for i in range(d):
        La[i] = L[i] + a * dl[i]
    _matvec(F, La, FLa)
    total = 0.0
    for i in range(d):
        Sa = S[i] + a * ds[i]
        rc = (La[i] * Sa - target[i]) / gap_scale[i]
        rp = (Sa - FLa[i] - q[i]) / row_scale[i]
        total += rc * rc + rp * rp
    return np.sqrt(total)


@nb.njit(cache=True, inline="always")
def _keeps_targets(L, S, dl, ds, a, target):
    """The step of length ``a`` keeps every iterate positive and finite and no product
    ``lam_i s_i`` below ``TARGET_FLOOR`` times its target."""
    for i in range(L.shape[0]):
        ln = L[i] + a * dl[i]
        sn = S[i] + a * ds[i]
        if not (0.0 < ln < np.inf and 0.0 < sn < np.inf and ln * sn >= TARGET_FLOOR * target[i]):
            return False
    return True


@nb.njit(cache=True)
def iterate(Fs, shared, qs, mu_s, gap_scale, lam, s, tol, max_iterations, monotone):
    """Run the iterations on every problem of the batch, updating ``lam`` and ``s`` (B, d) in
    place. ``Fs`` is (1, d, d) when ``shared`` else (B, d, d). Returns
    ``(status, iterations, residual)``, each (B,), status an :class:`LCPStatus` code.

    One iteration, in the numbered steps marked below: (1) residuals and the stopping test;
    (2) the equilibrated Newton matrix; (3) its factorisation, once for both solves; (4) the
    predictor (affine-scaling) direction; (5) the centring weight and the stall safeguard;
    (6) the corrector direction; (7) the step length; (8) the update.

    The steps stay in one function on purpose: as separate compiled helpers (inlined or not),
    each call re-counts references to the dozen arrays it takes, which measured 5 times slower
    per problem at d = 1 (1.5 -> 7.8 us) and 1.5 times at d = 4 (4.9 -> 7.4 us); numba does not
    remove that overhead here.
    """
    B, d = qs.shape
    status = np.full(B, MAX_ITERATIONS, dtype=np.int8)
    iterations = np.full(B, max_iterations, dtype=np.int64)
    residual = np.full(B, np.inf)
    K = np.empty((d, d))
    Kinv = np.empty((d, d))
    LU = np.empty((d, d))
    aug = np.empty((d, 2 * d))
    piv = np.empty(d, dtype=np.int64)
    FL = np.empty(d)
    rp = np.empty(d)
    rs = np.empty(d)
    gap = np.empty(d)
    w = np.empty(d)
    rhs = np.empty(d)
    dl_aff = np.empty(d)
    ds_aff = np.empty(d)
    dl = np.empty(d)
    ds = np.empty(d)
    target = np.empty(d)
    work1 = np.empty(d)
    work2 = np.empty(d)
    drive = np.empty(d, dtype=np.bool_)
    for b in range(B):
        F = Fs[0] if shared else Fs[b]
        L = lam[b]
        S = s[b]
        q = qs[b]
        ma = mu_s[b]
        ga = gap_scale[b]
        strict = not monotone[b]
        best_mu = np.inf
        stalls = 0
        no_corr = False
        for k in range(max_iterations + 1):
            # (1) residuals: each row's backward error, and complementarity against the targets
            res_p = 0.0
            for i in range(d):
                fl = 0.0
                fa = 0.0
                for j in range(d):
                    fl += F[i, j] * L[j]
                    fa += abs(F[i, j]) * abs(L[j])
                FL[i] = fl
                rp[i] = S[i] - fl - q[i]
                rs[i] = abs(q[i]) + abs(S[i]) + fa + _TINY
                res_p = max(res_p, abs(rp[i]) / rs[i])
            res = res_p
            for i in range(d):
                gap[i] = L[i] * S[i]
                res = max(res, abs(gap[i] - ma[i]) / ga[i])
            residual[b] = res
            if res <= tol:
                status[b] = CONVERGED
                iterations[b] = k
                break
            if k == max_iterations:
                break
            if res_p <= tol:  # the primal residual is roundoff now: do not chase it
                for i in range(d):
                    rp[i] = 0.0
            # (2) Newton matrix S + Lam F, rows equilibrated by w = 1 / (s + lam)
            for i in range(d):
                w[i] = 1.0 / (S[i] + L[i])
                for j in range(d):
                    K[i, j] = L[i] * F[i, j] * w[i]
                K[i, i] += S[i] * w[i]
            # (3) factor once for both solves
            if d > _LAPACK_FROM:  # LAPACK's blocked inverse wins for larger matrices
                factored = False
                try:
                    Kinv[:, :] = np.linalg.inv(K)
                    inverted = np.all(np.isfinite(Kinv))
                except Exception:  # singular
                    inverted = False
            elif d <= _GAUSS_JORDAN_TO:  # tiny: the explicit inverse is cheapest
                factored = False
                inverted = gauss_jordan_inverse(K, Kinv, aug)
            else:
                factored = _lu_factor(K, LU, piv)
                inverted = factored
            if not inverted:  # singular to working precision: least-squares steps
                Kinv[:, :] = np.linalg.pinv(np.where(np.isfinite(K), K, 0.0))
            # (4) predictor (affine scaling): target lam o s = 0
            for i in range(d):
                rhs[i] = (L[i] * rp[i] - gap[i]) * w[i]
            if factored:
                _lu_solve(LU, piv, rhs, dl_aff)
            else:
                _matvec(Kinv, rhs, dl_aff)
            _matvec(F, dl_aff, ds_aff)
            for i in range(d):
                ds_aff[i] -= rp[i]
            a_aff = min(1.0, _max_step(L, dl_aff), _max_step(S, ds_aff))
            # (5) centring: mean product of the contacts still driving down, sigma = (aff/cur)^3
            n_drive = 0
            mu_cur = 0.0
            mu_aff = 0.0
            for i in range(d):
                drive[i] = gap[i] - ma[i] > tol * ga[i]
                if drive[i]:
                    n_drive += 1
                    mu_cur += gap[i]
                    mu_aff += (L[i] + a_aff * dl_aff[i]) * (S[i] + a_aff * ds_aff[i])
            mu_cur /= max(n_drive, 1)
            mu_aff /= max(n_drive, 1)
            sigma = 0.0
            if mu_cur > 0.0:
                ratio = min(mu_aff / mu_cur, 1.0)
                sigma = ratio * ratio * ratio
            # safeguard: drop Mehrotra's correction once the measure stalls (it can cycle)
            if mu_cur > STALL_RATIO * best_mu:
                stalls += 1
            else:
                stalls = 0
                best_mu = mu_cur
            use_corr = stalls < STALLS_BEFORE_NO_CORRECTOR and not no_corr
            if not use_corr:
                no_corr = True
            # (6) corrector: centre on max(sigma mu, mu_i), never below the requested target. A
            # contact already at a target that the tolerance resolves (a smoothed contact; not
            # driving) is held there exactly (step 3): sigma mu_cur, the mean of the others, can
            # lie above it when targets differ, and raising it made the iterations cycle. A
            # contact at a target below the absolute tolerance (an exact contact at the floor)
            # keeps centring with the others, which keeps it off the boundary.
            for i in range(d):
                held = not drive[i] and ma[i] > tol * ga[i]
                t = ma[i] if held else max(sigma * mu_cur, ma[i])
                target[i] = t
                corr = dl_aff[i] * ds_aff[i] if (t > ma[i] and use_corr) else 0.0
                rhs[i] = (L[i] * rp[i] - (gap[i] - t + corr)) * w[i]
            if factored:
                _lu_solve(LU, piv, rhs, dl)
            else:
                _matvec(Kinv, rhs, dl)
            _matvec(F, dl, ds)
            for i in range(d):
                ds[i] -= rp[i]
            a_max = min(_max_step(L, dl), _max_step(S, ds))
            # (7) Step length. Near the solution (a nearly full Newton step), the fraction of the
            # step to the boundary follows the gap being closed, 1 - tau = mu_cur (clipped to
            # [MIN_STEP_GAP, 1 - STEP_TO_BOUNDARY]): a fixed 0.995 would cap the gap's
            # reduction at 200x per iteration where Newton's method converges quadratically.
            # That step is kept if it passes the tests of the default step and leaves every
            # product at least half its target; otherwise the default step, backtracked.
            armijo = strict and not use_corr  # non-monotone, uncorrected: Armijo on the residual
            m0 = _merit(F, q, L, S, dl, ds, 0.0, target, ga, rs, work1, work2) if armijo else 0.0
            alpha = 0.0
            tau = 1.0 - min(1.0 - STEP_TO_BOUNDARY, max(mu_cur, MIN_STEP_GAP))
            if tau > STEP_TO_BOUNDARY and a_max >= NEAR_FULL_STEP and d > 1:
                a = min(1.0, tau * a_max)
                if (
                    _neighbourhood_ok(L, S, dl, ds, a, drive, ma, strict)
                    and _keeps_targets(L, S, dl, ds, a, ma)
                    and (
                        not armijo
                        or _merit(F, q, L, S, dl, ds, a, target, ga, rs, work1, work2)
                        <= (1.0 - ARMIJO_SLOPE * a) * m0
                    )
                ):
                    alpha = a
            if alpha == 0.0:
                alpha = min(1.0, STEP_TO_BOUNDARY * a_max)
                if d > 1:
                    chosen = alpha * BACKTRACK[-1]
                    for f in BACKTRACK:
                        if _neighbourhood_ok(L, S, dl, ds, alpha * f, drive, ma, strict):
                            chosen = alpha * f
                            break
                    alpha = chosen
                if armijo:
                    chosen = alpha * BACKTRACK[-1]
                    for f in BACKTRACK:
                        a = alpha * f
                        if (
                            _merit(F, q, L, S, dl, ds, a, target, ga, rs, work1, work2)
                            <= (1.0 - ARMIJO_SLOPE * a) * m0
                        ):
                            chosen = a
                            break
                    alpha = chosen
            # (8) update, if the new iterate is strictly positive and finite
            ok = True
            for i in range(d):
                ln = L[i] + alpha * dl[i]
                sn = S[i] + alpha * ds[i]
                if not (ln > 0.0 and sn > 0.0 and ln < np.inf and sn < np.inf):
                    ok = False
            if not ok:  # keep the last finite iterate, flag the problem
                status[b] = NUMERICAL_FAILURE
                iterations[b] = k
                break
            for i in range(d):
                L[i] += alpha * dl[i]
                S[i] += alpha * ds[i]
    return status, iterations, residual


@nb.njit(cache=True)
def prepare(F, shared, Q, mu_full, exact_tol, tol):
    """Scale a batch (step 1 of the :mod:`drake_abs.lcp.ipm` docstring) and build the default start.

    ``F`` is (1, d, d) when ``shared`` else (B, d, d); ``Q`` and ``mu_full`` are (B, d) in
    original units. Returns ``(D, Fs, qs, c, mu_s, gap_scale, lam, s)``: the Jacobi scale D
    ((1, d) or (B, d), powers of two), the scaled matrices (shape of F), q' = D^-1 q / c, the
    magnitude scale c (B,), the floored scaled targets, the gap scale of the stopping test (with
    the exact floor ``exact_tol^2`` plus the roundoff coupled in from the contacts F couples to
    contact i, about ``1e-13 mu_j``), and
    the start lam = s = max(1, sqrt(max mu')).
    """
    B, d = Q.shape
    nF = F.shape[0]
    D = np.empty((nF, d))
    Fs = np.empty_like(F)
    for f in range(nF):
        for i in range(d):
            a = F[f, i, i]
            D[f, i] = np.exp2(np.round(0.5 * np.log2(a))) if a > 0.0 else 1.0
        for i in range(d):
            for j in range(d):
                Fs[f, i, j] = F[f, i, j] / (D[f, i] * D[f, j])
    qs = np.empty((B, d))
    c = np.empty(B)
    mu_s = np.empty((B, d))
    gap_scale = np.empty((B, d))
    lam = np.empty((B, d))
    s = np.empty((B, d))
    floor = exact_tol * exact_tol
    for b in range(B):
        f = 0 if shared else b
        cmax = 0.0
        for i in range(d):
            qs[b, i] = Q[b, i] / D[f, i]
            cmax = max(cmax, abs(qs[b, i]))
        c[b] = np.exp2(np.round(np.log2(cmax))) if cmax > 0.0 else 1.0
        c2 = c[b] * c[b]
        top = 0.0
        for i in range(d):
            qs[b, i] /= c[b]
            mu_s[b, i] = max(mu_full[b, i] / c2, floor)  # c2 = inf: flagged after the solve
            top = max(top, mu_s[b, i])
        for i in range(d):
            neighbour = 0.0
            for j in range(d):
                if j != i and (Fs[f, i, j] != 0.0 or Fs[f, j, i] != 0.0):
                    neighbour = max(neighbour, mu_s[b, j])
            gap_scale[b, i] = mu_s[b, i] + (floor + COUPLED_ROUNDOFF * neighbour) / tol
        start = max(1.0, np.sqrt(top))
        for i in range(d):
            lam[b, i] = start
            s[b, i] = start
    return D, Fs, qs, c, mu_s, gap_scale, lam, s


@nb.njit(cache=True)
def unscale(lam, s, mu_s, D, c, shared):
    """Back to original units: ``(lam, s, lam o s, target mu, finite)``, with ``finite`` (B,)
    False where any of them over- or underflowed (not representable) or lam, s are not > 0."""
    B, d = lam.shape
    lam_out = np.empty((B, d))
    s_out = np.empty((B, d))
    mu_out = np.empty((B, d))
    target = np.empty((B, d))
    finite = np.ones(B, dtype=np.bool_)
    for b in range(B):
        f = 0 if shared else b
        for i in range(d):
            lam_out[b, i] = lam[b, i] * c[b] / D[f, i]
            s_out[b, i] = s[b, i] * c[b] * D[f, i]
            mu_out[b, i] = lam_out[b, i] * s_out[b, i]
            target[b, i] = mu_s[b, i] * (c[b] * c[b])
            ok = (
                np.isfinite(lam_out[b, i])
                and np.isfinite(s_out[b, i])
                and np.isfinite(mu_out[b, i])
                and np.isfinite(target[b, i])
                and lam_out[b, i] > 0.0
                and s_out[b, i] > 0.0
            )
            if not ok:
                finite[b] = False
    return lam_out, s_out, mu_out, target, finite


@nb.njit(cache=True)
def solve(F, shared, Q, mu_full, exact_tol, tol, max_iterations, monotone, lam0, s0, warm):
    """:func:`prepare`, :func:`iterate` and :func:`unscale` in one compiled call (the whole
    solve in original units). With ``warm``, the iterations start from ``(lam0, s0)`` (B, d),
    original units, strictly positive. Returns ``(status, iterations, residual, lam, s,
    lam o s, target mu, finite)``."""
    D, Fs, qs, c, mu_s, gap_scale, lam, s = prepare(F, shared, Q, mu_full, exact_tol, tol)
    if warm:
        B, d = Q.shape
        for b in range(B):
            f = 0 if shared else b
            for i in range(d):
                lam[b, i] = lam0[b, i] * D[f, i] / c[b]
                s[b, i] = s0[b, i] / (D[f, i] * c[b])
    status, iterations, residual = iterate(
        Fs, shared, qs, mu_s, gap_scale, lam, s, tol, max_iterations, monotone
    )
    lam_out, s_out, mu_out, target, finite = unscale(lam, s, mu_s, D, c, shared)
    return status, iterations, residual, lam_out, s_out, mu_out, target, finite
