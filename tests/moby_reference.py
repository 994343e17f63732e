"""Drake's MobyLcpSolver (Lemke) as an independent reference for exact LCP answers, used only
where its answer is valid: ``is_success()`` alone is not enough (Moby reports success with
w < 0 on some P-matrix problems, e.g. Kostreva's example 1)."""

import numpy as np
from pydrake.solvers import MathematicalProgram, MobyLcpSolver


def moby(F, q):
    """``(usable, z)``: Moby's answer z and whether it is usable as a reference, i.e. reported
    successful *and* a valid solution (z >= 0, w = F z + q >= 0, min(z, w) = 0, each to 1e-9
    of its row's terms)."""
    prog = MathematicalProgram()
    z = prog.NewContinuousVariables(len(q))
    prog.AddLinearComplementarityConstraint(F, q, z)
    result = MobyLcpSolver().Solve(prog)
    zs = result.GetSolution(z)
    w = F @ zs + q
    row = np.abs(q) + np.abs(F) @ np.abs(zs)
    valid = (
        np.all(zs >= -1e-9 * row)
        and np.all(w >= -1e-9 * row)
        and np.all(np.minimum(np.abs(zs), np.abs(w)) <= 1e-9 * (1 + row))
    )
    return bool(result.is_success() and valid), zs
