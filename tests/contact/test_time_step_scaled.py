"""Time-step consistency of barrier smoothing (issue 13, item 4): mu is an impulse times a gap
(m N s), so a body resting on a barrier contact floats at mu / (m g h). A policy stated at a
reference step and run through ``TimeStepScaled`` keeps the reference's rest gap at every h;
the same mu at a finer step launches the body."""

import numpy as np
import pytest
from scipy.optimize import brentq

from drake_abs.contact.lcs import LcsStepper
from drake_abs.contact.smoothing import (
    ContactAware,
    Exact,
    Fixed,
    GaussianMatched,
    TimeStepScaled,
)
from drake_abs.tasks.point_mass import point_mass_lcs

G = 9.81
H_REF = 0.01
POLICY = ContactAware(1e-2, 0.05)  # stated at H_REF


def rest_gap(policy, h: float, mass: float = 1.0) -> float:
    """The height p of the 1-D point mass at rest under ``policy`` at step h: the normal row's
    impulse is m g h and the gap after it is p, so p = mu(z) / (m g h) with the pre-impulse
    distance z = p - g h^2 (the one root: the left side grows with p, mu does not)."""

    def residual(p):
        return mass * G * h * p - policy.mu(np.array([[p - G * h * h]]), None)[0, 0]

    return brentq(residual, G * h * h * (1 + 1e-9), 1e3, xtol=1e-14, rtol=1e-12)


def heights(policy, h: float, p0: float, duration: float = 1.0) -> np.ndarray:
    """Heights of the 1 kg point mass released at rest at p0, one per step."""
    stepper = LcsStepper(point_mass_lcs(1, time_step=h), policy)
    x, u = np.array([[p0, 0.0]]), np.zeros((1, 1))
    out = []
    for _ in range(int(round(duration / h))):
        step = stepper.step(x, u, jacobians=False)
        assert step.converged.all()
        x = step.x_next
        out.append(x[0, 0])
    return np.array(out)


@pytest.fixture(scope="module")
def reference_gap():
    gap = rest_gap(POLICY, H_REF)
    assert 0.04 < gap < 0.05  # 4.35 cm
    return gap


@pytest.mark.parametrize("h", [1e-2, 1e-3, 1e-4])
def test_a_resting_point_mass_stays_at_the_reference_gap_at_every_time_step(h, reference_gap):
    """Measured: max 4.353 cm at every h; the gap after 1 s 4.353, 4.302, 4.300 cm."""
    p = heights(TimeStepScaled.between(POLICY, h, H_REF), h, reference_gap)
    assert p.max() <= reference_gap + 1e-4  # never launched
    assert p.min() >= 0.95 * reference_gap
    assert p[-1] == pytest.approx(reference_gap, rel=0.02)
    assert rest_gap(TimeStepScaled.between(POLICY, h, H_REF), h) == pytest.approx(
        reference_gap, rel=0.02
    )


@pytest.mark.parametrize(("h", "higher_than"), [(1e-3, 0.2), (1e-4, 1.0)])
def test_without_the_scaling_the_same_mu_launches_it(h, higher_than, reference_gap):
    """The reproduction (and the proof that the test above can fail): unscaled, the point mass
    resting at the 10 ms gap is thrown to 0.31 m (h = 1 ms) and 2.8 m (h = 0.1 ms)."""
    p = heights(POLICY, h, reference_gap)
    assert p.max() > higher_than
    assert rest_gap(POLICY, h) > 2 * reference_gap


def test_fixed_mu_rest_gap_is_mu_over_m_g_h_and_scales_back():
    mu = 1e-3
    assert rest_gap(Fixed(mu), H_REF) == pytest.approx(mu / (G * H_REF))
    for h in (1e-3, 1e-4):
        assert rest_gap(Fixed(mu), h) == pytest.approx(mu / (G * h))
        scaled = TimeStepScaled.between(Fixed(mu), h, H_REF)
        assert rest_gap(scaled, h) == pytest.approx(mu / (G * H_REF))


def test_scaled_policy_multiplies_mu_and_its_derivative(rng):
    z = rng.uniform(-0.01, 0.1, size=(5, 3))
    F = np.eye(3)
    scaled = TimeStepScaled(POLICY, 0.25)
    np.testing.assert_array_equal(scaled.mu(z, F), 0.25 * POLICY.mu(z, F))
    np.testing.assert_array_equal(scaled.dmu_dz(z, F), 0.25 * POLICY.dmu_dz(z, F))
    assert not scaled.is_constant and not scaled.is_exact
    fixed = TimeStepScaled(Fixed(2e-3), 0.5)
    assert fixed.is_constant
    np.testing.assert_array_equal(fixed.mu(z, F), np.full_like(z, 1e-3))


def test_between_leaves_equal_steps_and_exact_policies_alone():
    assert TimeStepScaled.between(POLICY, 0.01, 0.01) is POLICY
    exact = Exact()
    assert TimeStepScaled.between(exact, 1e-4, 0.01) is exact
    assert TimeStepScaled.between(POLICY, 1e-3, 0.01).scale == pytest.approx(0.1)


@pytest.mark.parametrize(
    ("call", "name"),
    [
        (lambda: TimeStepScaled(POLICY, 0.0), "scale"),
        (lambda: TimeStepScaled(POLICY, float("nan")), "scale"),
        (lambda: TimeStepScaled("fixed", 0.5), "smoothing"),
        (lambda: TimeStepScaled(GaussianMatched(0.002), 0.5), "GaussianMatched"),
        (lambda: TimeStepScaled.between(POLICY, -1.0, 0.01), "time_step"),
        (lambda: TimeStepScaled.between(POLICY, 1e-3, 0.0), "reference_time_step"),
    ],
)
def test_bad_arguments_name_the_argument(call, name):
    with pytest.raises(ValueError, match=name):
        call()
