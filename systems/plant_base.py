"""The state, parameters and ports the two complementarity plants share
(:class:`~drake_abs.systems.lcs_plant.LcsPlant` and
:class:`~drake_abs.systems.complementarity_plant.ComplementarityPlant`), declared the way
Drake's own discrete MultibodyPlant declares them:

- one discrete state vector ``x`` (so ``context.SetDiscreteState(x0)`` works);
- numeric parameters in the Context: ``smoothing`` (the smoothing's numeric parameters,
  e.g. ``(mu_max, length, mu_min)`` for ContactAware; absent for exact contact) and ``model``
  (the step's model parameters), so that AutoDiffXd can differentiate with respect to them;
- input ``actuation``; outputs ``state`` (x), and ``impulse``, ``mu`` and ``converged`` of the
  step that starts at the current state and input: the step is a cache entry that the discrete
  update applies and the outputs read (solved once per step), so ``impulse`` at time t is the
  impulse over [t, t + h] (Drake's MultibodyPlant reports contact results this way when its
  output ports are not sampled). These outputs depend on the input; ``state`` does not.

Everything the two plants share lives here, once: the declarations, the step from the Context
(values in double; under AutoDiffXd the core's implicit Jacobians chained onto the incoming
derivatives of x, u and the parameters), and the cache of steppers for changed parameter values.
A plant only says which stepper a Context's parameter values mean (``_stepper_for``). The step
itself is the core's stepper, the one the batched rollouts call.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector_, ValueProducer

from drake_abs._validation import check_finite_batch
from drake_abs.systems import autodiff

#: Steppers kept for changed parameter values, per plant (the oldest are dropped beyond this).
MAX_VARIANTS = 64


class ComplementarityPlantBase:
    """Mixin of :class:`~drake_abs.systems.lcs_plant.LcsPlant` and
    :class:`~drake_abs.systems.complementarity_plant.ComplementarityPlant` (listed before
    ``LeafSystem_[T]``). A plant calls :meth:`_declare_plant` in its constructor and defines
    ``_stepper_for(smoothing_values, model_values)``, returning a batched stepper whose
    ``step(x, u, *, jacobians, parameters, smoothing_parameters)`` takes those values; it sets
    ``on_unconverged`` (:mod:`drake_abs.contact.unconverged`)."""

    def _declare_plant(
        self,
        T,
        nx: int,
        nu: int,
        nc: int,
        x0,
        smoothing_values: Sequence[float],
        model_values: Sequence[float],
        period: float,
    ) -> None:
        """Declare the state x (default ``x0``), the ``smoothing`` and ``model`` numeric
        parameters (where non-empty), the ports and the periodic update (``period`` s)."""
        self._T, self._nu = T, nu
        self._variants = {}
        x0 = np.asarray(x0, dtype=float)
        if x0.shape != (nx,) or not np.all(np.isfinite(x0)):
            raise ValueError(f"initial_state must be {nx} finite numbers (x); got {x0.shape}")
        self._x = self.DeclareDiscreteState(x0)
        self._built = (
            np.asarray(smoothing_values, dtype=float),
            np.asarray(model_values, dtype=float),
        )
        self.smoothing_parameter_index = self.model_parameter_index = None
        if len(smoothing_values):
            self.smoothing_parameter_index = self.DeclareNumericParameter(
                BasicVector_[T](self._built[0])
            )
        if len(model_values):
            self.model_parameter_index = self.DeclareNumericParameter(
                BasicVector_[T](self._built[1])
            )
        self.actuation_port = self.DeclareVectorInputPort("actuation", nu)
        self.state_port = self.DeclareStateOutputPort("state", self._x)
        # the step from (x, u, parameters): one solve, read by the update and the outputs
        self._step_cache = self.DeclareCacheEntry(
            description="the complementarity step from the current state",
            value_producer=ValueProducer(
                allocate=lambda: AbstractValue.Make((None, None, None, 1.0, None)),
                calc=self._CalcStep,
            ),
            prerequisites_of_calc={self.all_sources_ticket()},
        )
        after = {self._step_cache.ticket()}

        def output(i):
            return lambda c, out: out.SetFromVector(self._step_cache.Eval(c)[i])

        self.impulse_port = self.DeclareVectorOutputPort(
            "impulse", nc, output(1), prerequisites_of_calc=after
        )
        self.mu_port = self.DeclareVectorOutputPort(
            "mu", nc, output(2), prerequisites_of_calc=after
        )
        self.converged_port = self.DeclareVectorOutputPort(
            "converged", 1,
            lambda c, out: out.SetFromVector([T(self._step_cache.Eval(c)[3])]),
            prerequisites_of_calc=after,
        )  # fmt: skip
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._Update)

    def get_actuation_input_port(self):
        return self.actuation_port

    def get_state_output_port(self):
        return self.state_port

    def SetInitialState(self, context, x0) -> None:
        """Set x in this system's ``context`` (the same as ``context.SetDiscreteState(x0)``)."""
        context.SetDiscreteState(np.asarray(x0))

    def _parameters(self, context) -> tuple[np.ndarray, np.ndarray]:
        """The smoothing and model parameter vectors of ``context`` (empty where absent)."""
        out = []
        for index, built in zip(
            (self.smoothing_parameter_index, self.model_parameter_index), self._built, strict=True
        ):
            if index is None:
                out.append(built if self._T is float else built.astype(object))
            else:
                out.append(context.get_numeric_parameter(index).value())
        return out[0], out[1]

    def _variant(self, key, make):
        """The stepper for changed parameter values ``key`` (made by ``make()`` once)."""
        if key not in self._variants:
            if len(self._variants) >= MAX_VARIANTS:
                self._variants.pop(next(iter(self._variants)))
            self._variants[key] = make()
        return self._variants[key]

    def _CalcStep(self, context, value) -> None:
        x = context.get_discrete_state(self._x).value()
        u = self.actuation_port.Eval(context) if self._nu else np.zeros(0, dtype=x.dtype)
        s, m = self._parameters(context)
        value.set_value(self._step_values(x, u, s, m))

    def _step_values(self, x, u, s, m):
        """``(x_next, impulse, mu, converged, friction_impulse)`` of the step from (x, u) under
        the parameters (s, m); under AutoDiffXd with the derivatives chained (the ``mu``
        output's are zero where the stepper does not form them). ``friction_impulse`` is the
        stepper's (nc, 3) in double (N s, world frame; values only), or None where its step has
        none (an LCS)."""
        if not any(autodiff.is_autodiff(a) for a in (x, u, s, m)):
            self._check_finite(x, u)
            stepper = self._stepper_for(np.asarray(s, float), np.asarray(m, float))
            r = stepper.step(
                np.asarray(x, float)[None], np.asarray(u, float)[None], jacobians=False
            )
            friction = None if r.friction_impulse is None else r.friction_impulse[0]
            return r.x_next[0], r.impulse[0], r.mu[0], bool(np.all(r.converged)), friction
        (xv, uv, sv, mv), (gx, gu, gs, gm) = autodiff.split([x, u, s, m])
        self._check_finite(xv, uv)
        model, smooth = bool(np.any(gm)), bool(np.any(gs))
        r = (
            self._stepper_for(sv, mv)
            .step(xv[None], uv[None], jacobians=True, parameters=model, smoothing_parameters=smooth)
            .first()
        )
        grads = [gx, gu]
        columns = ["x", "u"]
        if model or smooth:  # the theta columns: the model's parameters, then the smoothing's
            grads.append(np.concatenate([g for g, on in ((gm, model), (gs, smooth)) if on]))
            columns.append("theta")
        names = [n for n in ("dx", "dimpulse", "dmu") if getattr(r, f"{n}_dx") is not None]
        blocks = [getattr(r, f"{n}_d{c}") for n in names for c in columns]
        blocks = autodiff.guarded_jacobians(r.converged, self.on_unconverged, *blocks)
        k, per = gx.shape[1], len(columns)
        derivative = {
            n: sum(J @ g for J, g in zip(blocks[i * per : (i + 1) * per], grads, strict=True))
            for i, n in enumerate(names)
        }
        x_next, impulse, mu = (
            autodiff.join(v, derivative.get(n, np.zeros((v.shape[0], k))))
            for v, n in ((r.x_next, "dx"), (r.impulse, "dimpulse"), (r.mu, "dmu"))
        )
        return x_next, impulse, mu, bool(np.all(r.converged)), r.friction_impulse

    def _name(self) -> str:
        """How messages name this plant: its family (``ComplementarityPlant``, not the scalar
        type's class) and its name in a diagram where it has one."""
        plant = type(self).__name__.split("_")[0]
        return f"{plant} {self.get_name()!r}" if self.get_name() else plant

    def _check_finite(self, x, u) -> None:
        """``ValueError`` naming the first entry of the discrete state x or of the actuation
        input u that is not finite (its index and value), before the step is taken."""
        plant = self._name()
        check_finite_batch(np.asarray(x, float)[None], "x", batched=False,
                           what=f"{plant}: the discrete state ")  # fmt: skip
        check_finite_batch(np.asarray(u, float)[None], "u", batched=False,
                           what=f"{plant}: the actuation input ")  # fmt: skip

    def _Update(self, context, discrete_state) -> None:
        discrete_state.set_value(self._x, self._step_cache.Eval(context)[0])
