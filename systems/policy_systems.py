"""Policies, exploration noise and reward accumulation as Drake systems (double and AutoDiffXd),
so that a plant + policy + reward diagram differentiates as a whole with respect to the policy
parameters (Zhang et al. 2023, eq. 4.1).

Every system computes in double with the core's code (:mod:`drake_abs.policy.policies`,
:mod:`drake_abs.policy.rewards`) and, under AutoDiffXd, chains the core's Jacobians onto the
incoming derivatives (of the state, the input and the policy parameters), like the plants of this
package.
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs.systems import autodiff


def _value(x) -> float:
    return x.value() if isinstance(x, AutoDiffXd) else float(x)


@TemplateSystem.define("PolicyController_", T_list=[float, AutoDiffXd])
def PolicyController_(T):
    class Impl(LeafSystem_[T]):
        """``u = pi(x; theta) + sigma xi``: a policy of :mod:`drake_abs.policy.policies` with its
        parameters theta held as the Context's numeric parameter 0 (set them with
        :meth:`SetTheta`; under AutoDiffXd they may carry derivatives).

        .. pydrake_system::

            name: PolicyController
            input_ports:
            - state
            - noise
            output_ports:
            - u

        Args:
            policy: the policy (act, jacobians; nx, nu, n_params).
            theta: (P,) default parameters.
            sigma: exploration scale (units of u) applied to the ``noise`` input (standard
                normal samples, e.g. from :class:`NoiseSource`).
        """

        def _construct(self, policy, theta, sigma: float = 0.0, converter=None):
            LeafSystem_[T].__init__(self, converter)
            theta = np.asarray(theta, float)
            if theta.shape != (policy.n_params,):
                raise ValueError(
                    f"theta must have shape (P,) = ({policy.n_params},); got {theta.shape}"
                )
            if not (np.isfinite(sigma) and sigma >= 0):
                raise ValueError(f"sigma must be a finite number >= 0; got {sigma!r}")
            self.policy, self.theta0, self.sigma = policy, theta, float(sigma)
            self._theta = self.DeclareNumericParameter(BasicVector_[T](theta))
            self.state_port = self.DeclareVectorInputPort("state", policy.nx)
            self.noise_port = self.DeclareVectorInputPort("noise", policy.nu)
            self.u_port = self.DeclareVectorOutputPort("u", policy.nu, self._CalcU)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.policy, other.theta0, other.sigma, converter=converter)

        def SetTheta(self, context, theta) -> None:
            """Set theta (P,) in this system's ``context`` (AutoDiffXd entries allowed)."""
            context.get_mutable_numeric_parameter(self._theta).SetFromVector(theta)

        def _CalcU(self, context, output):
            x = self.state_port.Eval(context)
            xi = self.noise_port.Eval(context)
            theta = context.get_numeric_parameter(self._theta).value()
            if any(autodiff.is_autodiff(a) for a in (x, xi, theta)):
                (xv, xiv, thv), (gx, gxi, gth) = autodiff.split([x, xi, theta])
                u = self.policy.act(thv, xv[None])[0] + self.sigma * xiv
                du_dx, du_dth = self.policy.jacobians(thv, xv[None])
                out = autodiff.join(u, du_dx[0] @ gx + du_dth[0] @ gth + self.sigma * gxi)
            else:
                out = self.policy.act(np.asarray(theta), np.asarray(x)[None])[0]
                out = out + self.sigma * np.asarray(xi)
            output.SetFromVector(out)

    return Impl


PolicyController = PolicyController_[None]


@TemplateSystem.define("NoiseSource_", T_list=[float, AutoDiffXd])
def NoiseSource_(T):
    class Impl(LeafSystem_[T]):
        """Replays pre-drawn samples: output ``noise`` = ``samples[k]`` for t in [k h, (k+1) h)
        and zeros after the last row (the samples are data: no derivatives).

        Args:
            samples: (H, n) samples (standard normal for exploration; the caller seeds them).
            time_step: h in s.
        """

        def _construct(self, samples, time_step: float, converter=None):
            LeafSystem_[T].__init__(self, converter)
            samples = np.asarray(samples, float)
            if samples.ndim != 2 or not np.all(np.isfinite(samples)):
                raise ValueError(f"samples must be a finite (H, n) array; got {samples.shape}")
            if not (np.isfinite(time_step) and time_step > 0):
                raise ValueError(f"time_step must be > 0; got {time_step!r}")
            self.samples, self.time_step = samples, float(time_step)
            self.DeclareVectorOutputPort("noise", samples.shape[1], self._CalcNoise)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.samples, other.time_step, converter=converter)

        def _CalcNoise(self, context, output):
            k = int(np.floor(_value(context.get_time()) / self.time_step + 1e-9))
            row = self.samples[k] if k < len(self.samples) else np.zeros(self.samples.shape[1])
            output.SetFromVector(row if T is float else autodiff.join(row, np.zeros((row.size, 0))))

    return Impl


NoiseSource = NoiseSource_[None]


@TemplateSystem.define("RewardAccumulator_", T_list=[float, AutoDiffXd])
def RewardAccumulator_(T):
    class Impl(LeafSystem_[T]):
        """The cost evaluator: accumulates ``sum_t r(x_t, u_t)`` every ``time_step`` (the same
        instants as the plant's update, from the same x_t and u_t) and outputs it plus the
        terminal reward of the current state: after H steps, the return of the rollout.

        .. pydrake_system::

            name: RewardAccumulator
            input_ports:
            - state
            - u
            output_ports:
            - return

        Args:
            reward: a reward of :mod:`drake_abs.policy.rewards` (stage, terminal).
            time_step: h in s (the plant's).
        """

        def _construct(self, reward, time_step: float, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self.reward, self.time_step = reward, float(time_step)
            self._sum = self.DeclareDiscreteState(1)
            self.state_port = self.DeclareVectorInputPort("state", reward.nx)
            self.u_port = self.DeclareVectorInputPort("u", reward.nu)
            self.return_port = self.DeclareVectorOutputPort("return", 1, self._CalcReturn)
            self.DeclarePeriodicDiscreteUpdateEvent(self.time_step, 0.0, self._Update)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other.reward, other.time_step, converter=converter)

        def _Update(self, context, discrete_state):
            x = self.state_port.Eval(context)
            u = self.u_port.Eval(context)
            total = context.get_discrete_state(self._sum).value()
            if any(autodiff.is_autodiff(a) for a in (x, u, total)):
                (xv, uv, sv), (gx, gu, gs) = autodiff.split([x, u, total])
                r, dr_dx, dr_du = self.reward.stage(xv[None], uv[None])
                new = autodiff.join(sv + r, gs + dr_dx @ gx + dr_du @ gu)
            else:
                r = self.reward.stage(np.asarray(x)[None], np.asarray(u)[None])[0]
                new = np.asarray(total) + r
            discrete_state.set_value(self._sum, new)

        def _CalcReturn(self, context, output):
            x = self.state_port.Eval(context)
            total = context.get_discrete_state(self._sum).value()
            if any(autodiff.is_autodiff(a) for a in (x, total)):
                (xv, sv), (gx, gs) = autodiff.split([x, total])
                rT, drT = self.reward.terminal(xv[None])
                output.SetFromVector(autodiff.join(sv + rT, gs + drT @ gx))
            else:
                output.SetFromVector(
                    np.asarray(total) + self.reward.terminal(np.asarray(x)[None])[0]
                )

    return Impl


RewardAccumulator = RewardAccumulator_[None]
