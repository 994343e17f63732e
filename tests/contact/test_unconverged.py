"""Open-loop rollouts never hand out the Jacobians of an unconverged solve silently: by default
they are NaN and the rollout is marked unused; ``flag`` keeps them (warned), ``raise`` raises."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from drake_abs import ContactAware, LcsStepper, open_loop, point_mass_lcs
from drake_abs.contact.smoothing import Smoothing
from drake_abs.contact.unconverged import UnconvergedStepError, UnconvergedStepWarning
from drake_abs.lcp import ipm
from drake_abs.lcp.ipm import LCPConvergenceWarning

X0 = np.array([[0.0, 0.02, 1.0, -1.0], [0.0, 3.0, 0.0, 0.0]])  # landing / far above the ground
U = np.zeros((6, 2))


@pytest.fixture
def no_crossover(monkeypatch):
    """The solver's crossover (drake_abs.lcp.pivoting) finds the high ball's exact answer
    (lam = 0) whatever the iteration limit; these tests need a step that stays unconverged."""
    monkeypatch.setattr(ipm, "POLISH", False)


def _starved():
    """The point mass whose solver may take only 5 iterations: enough for the landing ball's
    steps, too few for the exact floor of the ball 3 m up (measured: 4 iterations fail the
    landing from its fourth step, 5 pass it; the high ball fails at up to 10)."""
    lcs = point_mass_lcs(2, time_step=0.01)
    return replace(lcs, solver_options={**lcs.solver_options, "max_iterations": 5})


@pytest.mark.usefixtures("no_crossover")
def test_default_drops_the_jacobians_of_unconverged_rollouts():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)
        with pytest.warns(UnconvergedStepWarning, match="1 of 2 rollouts"):
            r = open_loop(LcsStepper(_starved(), ContactAware(1e-2, 0.05), "total"), X0, U)
    assert r.converged[0].all() and not r.converged[1].any()
    assert r.used.tolist() == [True, False]
    assert np.isnan(r.dxH_dx0[1]).all() and np.isnan(r.dxH_du[1]).all()
    assert np.isfinite(r.dxH_dx0[0]).all()
    full = open_loop(LcsStepper(point_mass_lcs(2, time_step=0.01), ContactAware(1e-2, 0.05)), X0, U)
    np.testing.assert_allclose(r.dxH_dx0[0], full.dxH_dx0[0], rtol=1e-12)


@pytest.mark.usefixtures("no_crossover")
def test_flag_keeps_them_and_raise_refuses():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LCPConvergenceWarning)
        with pytest.warns(UnconvergedStepWarning, match="kept"):
            r = open_loop(
                LcsStepper(_starved(), ContactAware(1e-2, 0.05)), X0, U, on_unconverged="flag"
            )
        assert r.used.all() and np.isfinite(r.dxH_dx0).all()
        with pytest.raises(UnconvergedStepError, match="1 of 2"):
            open_loop(
                LcsStepper(_starved(), ContactAware(1e-2, 0.05)), X0, U, on_unconverged="raise"
            )
    with pytest.raises(ValueError, match="on_unconverged"):
        open_loop(LcsStepper(_starved()), X0, U, on_unconverged="skip")


class _RowMu(Smoothing):
    """A constant mu per LCP row (the contact step's normal and friction rows)."""

    is_constant = True

    def __init__(self, rows):
        self.rows = np.asarray(rows, float)

    def mu(self, z, F):
        return np.broadcast_to(self.rows, np.shape(z)).copy()


def test_an_lcs_step_that_does_not_converge_takes_the_exact_step(monkeypatch):
    """The same fallback as the rigid-body step: a frictional LCP of gymnasium's HalfCheetah
    on our plant (22 rows, one mu on the normal rows and 100 times it on the friction rows,
    from a fixed-mu rollout), which the default start alone does not solve, as an LCS whose
    state records the impulse. The unconverged step's next state is the exact step's
    (flagged), not the unconverged iterate."""
    from pathlib import Path

    from drake_abs import LCS, Exact
    from drake_abs.lcp import ipm

    data = np.load(Path(__file__).with_name("half_cheetah_step_lcp.npz"))
    d = data["z"].size
    lcs = LCS(A=np.eye(d), B=np.zeros((d, 1)), C=np.eye(d), c=np.zeros(d), D=np.zeros((d, d)),
              E=np.zeros((d, 1)), F=data["F"], d=data["z"], on_bad_matrix="attempt")  # fmt: skip
    x, u = np.zeros(d), np.zeros(1)
    monkeypatch.setattr(ipm, "SECOND_START", False)  # the default start alone fails here
    with pytest.warns(LCPConvergenceWarning, match="use the exact"):
        smoothed = lcs.step(x, u, _RowMu(data["mu"]))
    exact = lcs.step(x, u, Exact())
    assert not smoothed.converged and exact.converged
    # the same exact solve, reached through the fallback and directly
    np.testing.assert_allclose(smoothed.x_next, exact.x_next, rtol=1e-12, atol=1e-15)
    monkeypatch.setattr(ipm, "SECOND_START", True)  # with the second starts it converges
    assert lcs.step(x, u, _RowMu(data["mu"])).converged
