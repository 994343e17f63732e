"""The smoothing designs' numeric parameters and the LCS's matrices as differentiable
parameters: mu's derivatives with respect to the parameters and to F's diagonal, and a step's
parameter Jacobians, against central differences (the independent path: re-built policies and
systems stepped again)."""

import numpy as np
import pytest

from drake_abs import ContactAware, Fixed, GaussianMatched, TimeStepScaled, point_mass_lcs
from drake_abs.tasks.box_lcs import TranslatingBox

POLICIES = [
    Fixed(1e-3),
    ContactAware(1e-2, 0.03, 1e-4),
    GaussianMatched(0.01, 0.1, 1e-3),
    TimeStepScaled(ContactAware(1e-2, 0.03, 1e-4), 0.5),
]


@pytest.mark.parametrize("policy", POLICIES, ids=lambda p: type(p).__name__)
def test_mu_derivatives_match_central_differences(policy):
    rng = np.random.default_rng(0)
    z = rng.normal(0.0, 0.02, (6, 3))
    F = np.diag([0.5, 0.7, 0.9]) + 0.05
    theta = policy.parameter_values()
    assert policy.with_parameters(theta) == policy
    D = policy.dmu_dparameters(z, F)
    assert D.shape == (6, 3, theta.size)
    for k in range(theta.size):
        e = np.zeros_like(theta)
        e[k] = 1e-6 * max(abs(theta[k]), 1e-3)
        fd = policy.with_parameters(theta + e).mu(z, F) - policy.with_parameters(theta - e).mu(z, F)
        fd /= 2 * e[k]
        np.testing.assert_allclose(D[..., k], fd, rtol=1e-6, atol=1e-9 * np.abs(fd).max())
    DF = policy.dmu_dF_diagonal(z, F)
    assert DF.shape == (6, 3, 3)
    for j in range(3):
        E = np.zeros((3, 3))
        E[j, j] = 1e-7
        fd = (policy.mu(z, F + E) - policy.mu(z, F - E)) / 2e-7
        np.testing.assert_allclose(DF[:, :, j], fd, rtol=1e-6, atol=1e-12)


def test_with_parameters_refuses_a_wrong_shape_or_value_by_name():
    with pytest.raises(ValueError, match=r"ContactAware.with_parameters: values must have shape"):
        ContactAware(1e-2, 0.03).with_parameters([1.0, 2.0])
    with pytest.raises(ValueError, match=r"ContactAware.length"):
        ContactAware(1e-2, 0.03).with_parameters([1e-2, -1.0, 0.0])
    with pytest.raises(ValueError, match=r"LCS.with_parameters: values must have shape"):
        point_mass_lcs(2).with_parameters(np.zeros(3))


def _check_step_parameters(lcs, smoothing, x, u, gradient="total"):
    r = lcs.step(x, u, smoothing, gradient=gradient, parameters=True, smoothing_parameters=True)
    theta, s = lcs.parameter_values(), smoothing.parameter_values()
    assert r.dx_dtheta.shape == (x.shape[0], lcs.dims[0], theta.size + s.size)
    assert r.theta_names == lcs.parameter_names + tuple(
        f"smoothing.{n}" for n in smoothing.parameter_names
    )
    for k in range(theta.size):
        e = np.zeros_like(theta)
        e[k] = 1e-7
        fd = lcs.with_parameters(theta + e).step(x, u, smoothing, gradient=gradient).x_next
        fd = fd - lcs.with_parameters(theta - e).step(x, u, smoothing, gradient=gradient).x_next
        fd /= 2e-7
        scale = 1 + np.abs(fd).max()
        np.testing.assert_allclose(
            r.dx_dtheta[:, :, k], fd, atol=1e-5 * scale, err_msg=lcs.parameter_names[k]
        )
    for k in range(s.size):
        e = np.zeros_like(s)
        e[k] = 1e-6 * max(abs(s[k]), 1e-3)
        plus = lcs.step(x, u, smoothing.with_parameters(s + e)).x_next
        minus = lcs.step(x, u, smoothing.with_parameters(s - e)).x_next
        fd = (plus - minus) / (2 * e[k])
        np.testing.assert_allclose(
            r.dx_dtheta[:, :, theta.size + k], fd, rtol=1e-5, atol=1e-7 * (1 + np.abs(fd).max())
        )
    return r


@pytest.mark.parametrize(
    "policy", [ContactAware(1e-2, 0.05, 1e-5), GaussianMatched(0.003, 0.1, 1e-4)]
)
def test_point_mass_step_differentiates_every_matrix_entry(policy):
    lcs = point_mass_lcs(2, time_step=0.01)
    x = np.array([[0.0, 0.004, 1.0, -0.3], [0.0, 0.02, 0.5, -1.0], [0.0, 0.0, 0.1, 0.0]])
    r = _check_step_parameters(lcs, policy, x, np.array([[0.5, -2.0]] * 3))
    assert np.abs(r.dx_dtheta).max() > 1.0


def test_frictional_box_step_differentiates_its_matrices_under_gaussian_smoothing():
    """The box's LCS has friction and cone rows whose mu follows the normal row's F_ii: the
    derivative with respect to F's diagonal goes through them too."""
    box = TranslatingBox(time_step=0.01)
    smoothing = box.smoothing(GaussianMatched(0.002, 0.0, 1e-4))
    x = np.array([[0.0, box.half_height + 0.001, 1.0, -0.2], box.resting_state(v_x=0.5)])
    _check_step_parameters(box.lcs, smoothing, x, np.array([[2.0]] * 2))
