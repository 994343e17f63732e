"""Open-loop rollouts never hand out the Jacobians of an unconverged solve silently: by default
they are NaN and the rollout is marked unused; ``flag`` keeps them (warned), ``raise`` raises."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from drake_abs import ContactAware, LcsStepper, open_loop, point_mass_lcs
from drake_abs.contact.unconverged import UnconvergedStepError, UnconvergedStepWarning
from drake_abs.lcp.ipm import LCPConvergenceWarning

X0 = np.array([[0.0, 0.02, 1.0, -1.0], [0.0, 3.0, 0.0, 0.0]])  # landing / far above the ground
U = np.zeros((6, 2))


def _starved():
    """The point mass whose solver may take only 5 iterations: enough for the landing ball's
    steps, too few for the exact floor of the ball 3 m up (measured: 4 iterations fail the
    landing from its fourth step, 5 pass it; the high ball fails at up to 10)."""
    lcs = point_mass_lcs(2, time_step=0.01)
    return replace(lcs, solver_options={**lcs.solver_options, "max_iterations": 5})


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
