"""The mu-softened LCS as a Drake discrete-time system (docs/math.md section 1).

Every step calls :meth:`drake_abs.LCS.step`, the same code the batched core runs. Under
AutoDiffXd the step is solved in double and the implicit-function-theorem Jacobians (with
respect to x, u, the LCS's matrices and the smoothing parameters) are chained onto the incoming
derivatives (docs/math.md section 4).
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs.contact.lcs import LCS, GradientMode, LcsStepper, check_gradient_mode
from drake_abs.contact.smoothing import Exact, Smoothing
from drake_abs.contact.unconverged import OnUnconverged, check_on_unconverged
from drake_abs.systems.plant_base import ComplementarityPlantBase


def _check_arguments(lcs, smoothing) -> None:
    if not isinstance(lcs, LCS):
        raise ValueError(f"LcsPlant: lcs must be a drake_abs.LCS; got {type(lcs).__name__}")
    if lcs.time_step is None:
        raise ValueError(
            "LcsPlant: lcs.time_step is None; build the LCS with time_step=h, the step (s) its "
            "matrices were discretised with (the plant's update period is read from there)"
        )
    if smoothing is not None and not isinstance(smoothing, Smoothing):
        raise ValueError(
            "LcsPlant(lcs, smoothing=None, ...): smoothing must be a Smoothing or None; got "
            f"{smoothing!r} (the time step is not an argument: it is lcs.time_step = "
            f"{lcs.time_step} s)"
        )


@TemplateSystem.define("LcsPlant_", T_list=[float, AutoDiffXd])
def LcsPlant_(T):
    class Impl(ComplementarityPlantBase, LeafSystem_[T]):
        """A linear complementarity system stepped every ``lcs.time_step`` seconds.

        .. pydrake_system::

            name: LcsPlant
            input_ports:
            - actuation
            output_ports:
            - state
            - impulse
            - mu
            - converged

        State: one discrete vector x (dx). Outputs ``impulse`` (lam, d), ``mu`` (d) and
        ``converged`` (1.0 or 0.0) are those of the most recent step (sampled; zeros and 1.0
        before the first step).

        Numeric parameters (in the Context; AutoDiffXd may seed derivatives on them):
        ``smoothing`` (the policy's :attr:`~Smoothing.parameter_names`, index
        ``smoothing_parameter_index``; absent for a policy without any, e.g. Exact) and
        ``model`` (every entry of A, B, C, c, D, E, F, d, :attr:`LCS.parameter_names`, index
        ``model_parameter_index``). Changed values are used by the next step.

        Under AutoDiffXd the derivatives are those of the simulation (``gradient="total"``,
        the default). ``gradient="frozen"`` gives Zhang et al. 2023's Algorithm 1 instead: mu's
        dependence on the state is held, a biased estimate wherever mu varies with the state
        (ContactAware, GaussianMatched). The derivatives of an unconverged step follow
        ``on_unconverged``.

        Args:
            lcs: the system, with its ``time_step`` (s; the update period).
            smoothing: per-contact mu policy (default Exact); larger mu is smoother.
            gradient: ``"total"`` (default) or ``"frozen"`` (biased; see above).
            on_unconverged: under AutoDiffXd, the derivatives of a step whose solve did not
                converge: ``"drop"`` (default: NaN, with a warning), ``"flag"`` (kept, with a
                warning) or ``"raise"`` (:mod:`drake_abs.contact.unconverged`).
        """

        def _construct(
            self,
            lcs: LCS,
            smoothing: Smoothing | None = None,
            gradient: GradientMode = "total",
            on_unconverged: OnUnconverged = "drop",
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            _check_arguments(lcs, smoothing)
            check_on_unconverged(on_unconverged)
            check_gradient_mode(gradient)
            self.on_unconverged = on_unconverged
            self.lcs = lcs
            self.time_step = lcs.time_step
            self.smoothing = Exact() if smoothing is None else smoothing
            self.gradient = gradient
            self._base = LcsStepper(lcs, self.smoothing, gradient)
            nx, nu, nc = lcs.dims
            self._declare_plant(
                T, nx, nu, nc, np.zeros(nx), self.smoothing.parameter_values(),
                lcs.parameter_values(), lcs.time_step,
            )  # fmt: skip

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self, other.lcs, other.smoothing, other.gradient, other.on_unconverged,
                converter=converter,
            )  # fmt: skip

        def _stepper_for(self, smoothing_values, model_values) -> LcsStepper:
            """The step under a Context's parameter values (the built ones: no new LCS)."""
            built_s, built_m = self._built
            if np.array_equal(smoothing_values, built_s) and np.array_equal(model_values, built_m):
                return self._base
            return self._variant(
                (smoothing_values.tobytes(), model_values.tobytes()),
                lambda: LcsStepper(
                    self.lcs.with_parameters(model_values),
                    self.smoothing.with_parameters(smoothing_values),
                    self.gradient,
                ),
            )

    return Impl


LcsPlant = LcsPlant_[None]
