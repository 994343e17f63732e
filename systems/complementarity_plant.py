"""The complementarity plant as a Drake system: a MultibodyPlant's dynamics with the scene's
point contacts, stepped by :class:`drake_abs.multibody.ComplementarityStepper` (the same batched
step the rollouts use; this system only moves values and derivatives in and out of it).
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd
from pydrake.common.value import AbstractValue
from pydrake.geometry import FramePoseVector_
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs.contact.unconverged import UnconvergedPolicy, check_unconverged_policy
from drake_abs.multibody.stepper import ComplementarityStepper
from drake_abs.systems import autodiff
from drake_abs.systems.plant_ports import PlantPorts


@TemplateSystem.define("ComplementarityPlant_", T_list=[float, AutoDiffXd])
def ComplementarityPlant_(T):
    class Impl(LeafSystem_[T]):
        """A MultibodyPlant with complementarity contact, stepped every ``time_step`` seconds
        (the scene's, ``stepper.model.h``).

        .. pydrake_system::

            name: ComplementarityPlant
            input_ports:
            - actuation
            output_ports:
            - state
            - impulse
            - mu
            - converged
            - geometry_pose

        State: one discrete vector x = (q, v) of the scene's plant. Outputs ``impulse`` (the
        normal impulse of every contact candidate, N s), ``mu`` and ``converged`` (1.0 or 0.0)
        are those of the most recent step (sampled; zeros and 1.0 before the first).
        ``geometry_pose`` exists when the plant was given a ``scene_graph`` (see
        :func:`~drake_abs.diagrams.scene_plant.AddComplementarityPlantSceneGraph`): the poses of
        the scene's geometry for that SceneGraph, as a MultibodyPlant's.

        Numeric parameters (in the Context; AutoDiffXd may seed derivatives on them):
        ``smoothing`` (the policy's parameters, ``stepper.smoothing_parameter_names``; index
        ``smoothing_parameter_index``; absent for exact contact) and ``model``
        (``stepper.parameter_names``: ground height, friction coefficients, masses; index
        ``model_parameter_index``). A changed smoothing value is used by the next step;
        the model parameters carry derivatives only (a changed value raises: rebuild the
        scene with it).

        Under AutoDiffXd the step is solved in double and its implicit Jacobians are chained
        onto the incoming derivatives of the state, the input and the parameters; the
        derivatives are those of the simulation for the stepper's ``gradient="total"`` (the
        default), and Zhang et al. 2023's biased Algorithm 1 for ``"frozen"``. The ``mu``
        port carries values only (zero derivatives). Those of an unconverged step follow
        ``on_unconverged``.

        Args:
            stepper: the batched step (model, smoothing, gradient mode, activation distance).
            on_unconverged: ``"drop"`` (default: NaN derivatives, with a warning), ``"flag"``
                or ``"raise"`` (:mod:`drake_abs.contact.unconverged`).
            scene_graph, scene: register ``scene``'s geometry (the scene the stepper was
                built from) with ``scene_graph`` and declare ``geometry_pose``.
            initial_state: x0 = (q, v) of a new Context (default: the model files' default
                positions, at rest; ``AddComplementarityPlantSceneGraph`` gives the scene's).
        """

        def _construct(
            self,
            stepper: ComplementarityStepper,
            on_unconverged: UnconvergedPolicy = "drop",
            scene_graph=None,
            scene=None,
            initial_state=None,
            converter=None,
            _geometry=None,
        ):
            LeafSystem_[T].__init__(self, converter)
            if not isinstance(stepper, ComplementarityStepper):
                raise ValueError(
                    "ComplementarityPlant: stepper must be a ComplementarityStepper (e.g. "
                    f"build_scene_model(scene).stepper()); got {type(stepper).__name__}"
                )
            check_unconverged_policy(on_unconverged)
            self.on_unconverged = on_unconverged
            self.stepper = stepper
            self.time_step = stepper.model.h
            self._model_values = stepper.parameter_values()
            self._variants = {}
            nq, nv, nu, nc = stepper.sizes
            if initial_state is None:  # the model files' default positions, at rest
                plant = stepper.model.plant
                q0 = plant.GetPositions(plant.CreateDefaultContext())
                initial_state = np.concatenate([q0, np.zeros(nv)])
            self.initial_state = np.asarray(initial_state, dtype=float)
            self.ports = PlantPorts(
                self, T, nq + nv, nu, nc, self.initial_state, stepper.smoothing.parameter_values(),
                self._model_values, self.time_step, self._Update,
            )  # fmt: skip
            self.actuation_port = self.ports.actuation_port
            self.state_port = self.ports.state_port
            self.impulse_port = self.ports.impulse_port
            self.mu_port = self.ports.mu_port
            self.converged_port = self.ports.converged_port
            self.smoothing_parameter_index = self.ports.smoothing
            self.model_parameter_index = self.ports.model
            self._geometry = _geometry
            if scene_graph is not None:
                if scene is None:
                    raise ValueError(
                        "ComplementarityPlant: scene_graph needs the scene (its models and "
                        "contacts are drawn)"
                    )
                from drake_abs.multibody.geometry_plant import make_geometry_plant

                self._geometry = make_geometry_plant(scene, scene_graph)
                n_geometry = self._geometry.num_positions()
                if n_geometry != nq:
                    raise ValueError(
                        f"ComplementarityPlant: scene {scene.name!r} has {n_geometry} positions, "
                        f"the stepper's model {nq}: not the scene the stepper was built from"
                    )
            self.geometry_pose_port = None
            if self._geometry is not None:
                self._geometry_T = self._geometry if T is float else self._geometry.ToAutoDiffXd()
                self._geometry_context = self._geometry_T.CreateDefaultContext()
                self.geometry_pose_port = self.DeclareAbstractOutputPort(
                    "geometry_pose",
                    lambda: AbstractValue.Make(FramePoseVector_[T]()),
                    self._CalcGeometryPose,
                    prerequisites_of_calc={self.discrete_state_ticket(self.ports.x)},
                )

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self, other.stepper, other.on_unconverged, initial_state=other.initial_state,
                converter=converter, _geometry=other._geometry,
            )  # fmt: skip

        def get_actuation_input_port(self):
            return self.actuation_port

        def get_state_output_port(self):
            return self.state_port

        def get_geometry_pose_output_port(self):
            if self.geometry_pose_port is None:
                raise RuntimeError(
                    "this ComplementarityPlant has no geometry: build it with "
                    "AddComplementarityPlantSceneGraph (or scene_graph=..., scene=...)"
                )
            return self.geometry_pose_port

        def get_source_id(self):
            """The SceneGraph source id of the plant's geometry (None without geometry)."""
            return None if self._geometry is None else self._geometry.get_source_id()

        def geometry_plant(self):
            """The MultibodyPlant (double) that holds the registered geometry, for frame and
            body lookups (its q is this plant's)."""
            return self._geometry

        def SetInitialState(self, context, x0) -> None:
            """Set x = (q, v) in ``context`` (same as ``context.SetDiscreteState(x0)``)."""
            context.SetDiscreteState(np.asarray(x0))

        def _CalcGeometryPose(self, context, output):
            nq = self.stepper.sizes[0]
            x = context.get_discrete_state(self.ports.x).value()
            g = self._geometry_T
            g.SetPositions(self._geometry_context, x[:nq])
            output.set_value(g.get_geometry_pose_output_port().Eval(self._geometry_context))

        def _stepper_for(self, smoothing_values):
            s = self.stepper.smoothing
            if np.array_equal(smoothing_values, s.parameter_values()):
                return self.stepper
            key = smoothing_values.tobytes()
            if key not in self._variants:
                if len(self._variants) > 64:
                    self._variants.clear()
                self._variants[key] = self.stepper.with_smoothing(
                    s.with_parameters(smoothing_values)
                )
            return self._variants[key]

        def _check_model(self, m):
            if not np.array_equal(m, self._model_values):
                names = self.stepper.parameter_names
                changed = [
                    f"{n}: {a:g} -> {b:g}"
                    for n, a, b in zip(names, self._model_values, m, strict=True)
                    if a != b
                ]
                raise ValueError(
                    "ComplementarityPlant: the model parameters in the Context carry derivatives "
                    "only; their values must stay those of the scene the plant was built from "
                    f"(changed: {', '.join(changed)}). Build the scene with the new values."
                )

        def _Update(self, context, x, u, s, m):
            nu = self.stepper.sizes[2]
            if not any(autodiff.is_autodiff(a) for a in (x, u, s, m)):
                self._check_model(np.asarray(m, float))
                stepper = self._stepper_for(np.asarray(s, float))
                u = np.asarray(u, float) if nu else np.zeros(0)
                r = stepper.step(np.asarray(x)[None], u[None], jacobians=False)
                return r.x_next[0], r.impulse[0], r.mu[0], np.all(r.converged)
            (xv, uv, sv, mv), (gx, gu, gs, gm) = autodiff.split([x, u, s, m])
            self._check_model(mv)
            stepper = self._stepper_for(sv)
            model, smooth = bool(np.any(gm)), bool(np.any(gs))
            r = stepper.step(
                xv[None], uv[None], jacobians=True, parameters=model, smoothing_parameters=smooth
            ).first()
            J = autodiff.guarded_jacobians(
                r.converged, self.on_unconverged, r.dx_dx, r.dx_du, r.dimpulse_dx, r.dimpulse_du,
                *((r.dx_dtheta, r.dimpulse_dtheta) if model or smooth else ()),
            )  # fmt: skip
            dx = J[0] @ gx + J[1] @ gu
            dimpulse = J[2] @ gx + J[3] @ gu
            if model or smooth:
                gtheta = np.concatenate([g for g, on in ((gm, model), (gs, smooth)) if on])
                dx, dimpulse = dx + J[4] @ gtheta, dimpulse + J[5] @ gtheta
            x_next = autodiff.join(r.x_next, dx)
            impulse = autodiff.join(r.impulse, dimpulse)
            mu = autodiff.join(r.mu, np.zeros((r.mu.shape[0], gx.shape[1])))
            return x_next, impulse, mu, np.all(r.converged)

    return Impl


ComplementarityPlant = ComplementarityPlant_[None]
