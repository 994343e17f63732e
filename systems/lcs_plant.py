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

from drake_abs.contact.lcs import LCS, GradientMode, check_gradient_mode
from drake_abs.contact.smoothing import Exact, SmoothingPolicy
from drake_abs.contact.unconverged import UnconvergedPolicy, check_unconverged_policy
from drake_abs.systems import autodiff
from drake_abs.systems.plant_ports import PlantPorts


def _check_arguments(lcs, smoothing) -> None:
    if not isinstance(lcs, LCS):
        raise ValueError(f"LcsPlant: lcs must be a drake_abs.LCS; got {type(lcs).__name__}")
    if lcs.time_step is None:
        raise ValueError(
            "LcsPlant: lcs.time_step is None; build the LCS with time_step=h, the step (s) its "
            "matrices were discretised with (the plant's update period is read from there)"
        )
    if smoothing is not None and not isinstance(smoothing, SmoothingPolicy):
        raise ValueError(
            "LcsPlant(lcs, smoothing=None, ...): smoothing must be a SmoothingPolicy or None; got "
            f"{smoothing!r} (the time step is not an argument: it is lcs.time_step = "
            f"{lcs.time_step} s)"
        )


@TemplateSystem.define("LcsPlant_", T_list=[float, AutoDiffXd])
def LcsPlant_(T):
    class Impl(LeafSystem_[T]):
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
        ``smoothing`` (the policy's :attr:`~SmoothingPolicy.parameter_names`, index
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
            smoothing: SmoothingPolicy | None = None,
            gradient: GradientMode = "total",
            on_unconverged: UnconvergedPolicy = "drop",
            converter=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            _check_arguments(lcs, smoothing)
            check_unconverged_policy(on_unconverged)
            check_gradient_mode(gradient)
            self.on_unconverged = on_unconverged
            self.lcs = lcs
            self.time_step = lcs.time_step
            self.smoothing = Exact() if smoothing is None else smoothing
            self.gradient = gradient
            self._variants = {}  # (kind, parameter bytes) -> LCS or policy, for changed values
            nx, nu, nc = lcs.dims
            self.ports = PlantPorts(
                self, T, nx, nu, nc, np.zeros(nx), self.smoothing.parameter_values(),
                lcs.parameter_values(), lcs.time_step, self._Update,
            )  # fmt: skip
            self.actuation_port = self.ports.actuation_port
            self.state_port = self.ports.state_port
            self.impulse_port = self.ports.impulse_port
            self.mu_port = self.ports.mu_port
            self.converged_port = self.ports.converged_port
            self.smoothing_parameter_index = self.ports.smoothing
            self.model_parameter_index = self.ports.model

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self, other.lcs, other.smoothing, other.gradient, other.on_unconverged,
                converter=converter,
            )  # fmt: skip

        def get_actuation_input_port(self):
            return self.actuation_port

        def get_state_output_port(self):
            return self.state_port

        def SetInitialState(self, context, x0) -> None:
            """Set x in this system's ``context`` (same as ``context.SetDiscreteState(x0)``)."""
            context.SetDiscreteState(np.asarray(x0))

        def _variant(self, kind, base, values):
            built = base.parameter_values()
            if np.array_equal(values, built):
                return base
            key = (kind, values.tobytes())
            if key not in self._variants:
                if len(self._variants) > 64:
                    self._variants.clear()
                self._variants[key] = base.with_parameters(values)
            return self._variants[key]

        def _Update(self, context, x, u, s, m):
            if not any(autodiff.is_autodiff(a) for a in (x, u, s, m)):
                lcs = self._variant("model", self.lcs, np.asarray(m, float))
                smoothing = self._variant("smoothing", self.smoothing, np.asarray(s, float))
                r = lcs.step(x, u, smoothing, gradient=self.gradient, jacobians=False)
                return r.x_next, r.impulse, r.mu, np.all(r.converged)
            (xv, uv, sv, mv), (gx, gu, gs, gm) = autodiff.split([x, u, s, m])
            lcs = self._variant("model", self.lcs, mv)
            smoothing = self._variant("smoothing", self.smoothing, sv)
            model = bool(np.any(gm))
            smooth = bool(np.any(gs))
            r = lcs.step(
                xv, uv, smoothing, gradient=self.gradient, jacobians=True, parameters=model,
                smoothing_parameters=smooth,
            )  # fmt: skip
            gtheta = np.concatenate([g for g, on in ((gm, model), (gs, smooth)) if on] or [gs[:0]])
            J = autodiff.guarded_jacobians(
                r.converged, self.on_unconverged,
                r.dx_dx, r.dx_du, r.dimpulse_dx, r.dimpulse_du, r.dmu_dx, r.dmu_du,
                *((r.dx_dtheta, r.dimpulse_dtheta, r.dmu_dtheta) if model or smooth else ()),
            )  # fmt: skip
            k = gx.shape[1]
            extra = [np.zeros((J[0].shape[0], k)), np.zeros((J[2].shape[0], k)), 0.0]
            if model or smooth:
                extra = [J[6] @ gtheta, J[7] @ gtheta, J[8] @ gtheta]
            x_next = autodiff.join(r.x_next, J[0] @ gx + J[1] @ gu + extra[0])
            impulse = autodiff.join(r.impulse, J[2] @ gx + J[3] @ gu + extra[1])
            mu = autodiff.join(r.mu, J[4] @ gx + J[5] @ gu + extra[2])
            return x_next, impulse, mu, np.all(r.converged)

    return Impl


LcsPlant = LcsPlant_[None]
