"""An empty batch (B = 0) is solved, Jacobians included: arrays of the right shapes with no rows
(issue 35, item 6)."""

import numpy as np
import pytest

from drake_abs import solve_lcp

F = np.array([[2.0, 1.0], [1.0, 2.0]])


@pytest.mark.parametrize(
    "mu_of, dmu_shape",
    [
        (lambda B: 1e-4, (2,)),  # one mu for every problem
        (lambda B: np.full(B, 1e-4), (2,)),  # one per problem
        (lambda B: np.full((B, 2), 1e-4), (2, 2)),  # one per contact
    ],
)
def test_an_empty_batch_with_jacobians_has_the_shapes_of_a_batch(mu_of, dmu_shape):
    r = solve_lcp(F, np.zeros((0, 2)), mu=mu_of(0), jacobians=True)
    assert r.lam.shape == r.slack.shape == (0, 2)
    assert r.converged.shape == r.status.shape == r.iterations.shape == (0,)
    assert r.dlam_dq.shape == (0, 2, 2)
    assert r.dlam_dmu.shape == (0, *dmu_shape)
    one = solve_lcp(F, np.zeros((1, 2)), mu=mu_of(1), jacobians=True)  # the same, with a row
    assert one.dlam_dq.shape == (1, 2, 2) and one.dlam_dmu.shape == (1, *dmu_shape)


def test_an_empty_batch_of_matrices_too():
    r = solve_lcp(np.zeros((0, 2, 2)), np.zeros((0, 2)), mu=1e-4, jacobians=True)
    assert r.lam.shape == (0, 2) and r.dlam_dq.shape == (0, 2, 2) and r.dlam_dmu.shape == (0, 2)
