"""The state, parameters and ports the two complementarity plants share
(:class:`~drake_abs.systems.lcs_plant.LcsPlant` and
:class:`~drake_abs.systems.complementarity_plant.ComplementarityPlant`), declared the way
Drake's own discrete MultibodyPlant declares them:

- one discrete state vector ``x`` (so ``context.SetDiscreteState(x0)`` works);
- numeric parameters in the Context: ``smoothing`` (the smoothing policy's numeric parameters,
  e.g. ``(mu_max, length, mu_min)`` for ContactAware; absent for exact contact) and ``model``
  (the step's model parameters), so that AutoDiffXd can differentiate with respect to them;
- input ``actuation``; outputs ``state`` (x), and ``impulse``, ``mu`` and ``converged`` of the
  step that starts at the current state and input: the step is a cache entry that the discrete
  update applies and the outputs read (solved once per step), so ``impulse`` at time t is the
  impulse over [t, t + h] (Drake's MultibodyPlant reports contact results this way when its
  output ports are not sampled). These outputs depend on the input; ``state`` does not.

This module only declares; the step itself is the core's, called by each plant.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector_, ValueProducer


class PlantPorts:
    """Declare the shared state, parameters and ports on ``system`` (a LeafSystem_[T]).

    Args:
        system: the plant being constructed.
        T: its scalar type (float or AutoDiffXd).
        nx, nu, nc: state, input and impulse sizes.
        x0: (nx,) the default state.
        smoothing_values: (S,) the smoothing policy's parameters (may be empty).
        model_values: (P,) the model parameters (may be empty).
        period: the update period (s).
        update: ``update(context, x, u, smoothing, model) -> (x_next, impulse, mu, converged)``,
            the step (evaluated once per context change, as a cache entry).
    """

    def __init__(
        self,
        system,
        T,
        nx: int,
        nu: int,
        nc: int,
        x0,
        smoothing_values: Sequence[float],
        model_values: Sequence[float],
        period: float,
        update: Callable,
    ):
        self.T, self.nu, self.nc = T, nu, nc
        self._update = update
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (nx,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"initial_state must be {nx} finite numbers (x); got {x0.shape}")
        self.x = system.DeclareDiscreteState(x0)
        self.smoothing = self.model = None
        if len(smoothing_values):
            self.smoothing = system.DeclareNumericParameter(
                BasicVector_[T](np.asarray(smoothing_values, dtype=float))
            )
        if len(model_values):
            self.model = system.DeclareNumericParameter(
                BasicVector_[T](np.asarray(model_values, dtype=float))
            )
        self.actuation_port = system.DeclareVectorInputPort("actuation", nu)
        self.state_port = system.DeclareStateOutputPort("state", self.x)
        # the step from (x, u, parameters): one solve, read by the update and the outputs
        self.step = system.DeclareCacheEntry(
            description="the complementarity step from the current state",
            value_producer=ValueProducer(
                allocate=lambda: AbstractValue.Make((None, None, None, 1.0)), calc=self._CalcStep
            ),
            prerequisites_of_calc={system.all_sources_ticket()},
        )
        after = {self.step.ticket()}
        self.impulse_port = system.DeclareVectorOutputPort(
            "impulse", nc, lambda c, out: out.SetFromVector(self._step(c)[1]),
            prerequisites_of_calc=after,
        )  # fmt: skip
        self.mu_port = system.DeclareVectorOutputPort(
            "mu", nc, lambda c, out: out.SetFromVector(self._step(c)[2]),
            prerequisites_of_calc=after,
        )  # fmt: skip
        self.converged_port = system.DeclareVectorOutputPort(
            "converged", 1, lambda c, out: out.SetFromVector([T(self._step(c)[3])]),
            prerequisites_of_calc=after,
        )  # fmt: skip
        system.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._Update)

    def _step(self, context):
        return self.step.Eval(context)

    def parameters(self, context) -> tuple[np.ndarray, np.ndarray]:
        """The smoothing and model parameter vectors of ``context`` (empty where absent)."""
        empty = np.zeros(0, dtype=object if self.T is not float else float)
        s = (
            context.get_numeric_parameter(self.smoothing).value()
            if self.smoothing is not None
            else empty
        )
        m = context.get_numeric_parameter(self.model).value() if self.model is not None else empty
        return s, m

    def _CalcStep(self, context, value) -> None:
        x = context.get_discrete_state(self.x).value()
        if self.nu:
            u = self.actuation_port.Eval(context)
        else:
            u = np.zeros(0, dtype=x.dtype)
        s, m = self.parameters(context)
        x_next, impulse, mu, converged = self._update(context, x, u, s, m)
        value.set_value((x_next, impulse, mu, float(converged)))

    def _Update(self, context, discrete_state) -> None:
        discrete_state.set_value(self.x, self._step(context)[0])
