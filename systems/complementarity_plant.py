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

from drake_abs.contact.unconverged import OnUnconverged, check_on_unconverged
from drake_abs.multibody.stepper import ComplementarityStepper
from drake_abs.systems.plant_base import ComplementarityPlantBase


@TemplateSystem.define("ComplementarityPlant_", T_list=[float, AutoDiffXd])
def ComplementarityPlant_(T):
    class Impl(ComplementarityPlantBase, LeafSystem_[T]):
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
            on_unconverged: OnUnconverged = "drop",
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
            check_on_unconverged(on_unconverged)
            self.on_unconverged = on_unconverged
            self.stepper = stepper
            self.time_step = stepper.model.h
            nq, nv, nu, nc = stepper.sizes
            if initial_state is None:  # the model files' default positions, at rest
                plant = stepper.model.plant
                q0 = plant.GetPositions(plant.CreateDefaultContext())
                initial_state = np.concatenate([q0, np.zeros(nv)])
            self.initial_state = np.asarray(initial_state, dtype=float)
            self._declare_plant(
                T, nq + nv, nu, nc, self.initial_state, stepper.smoothing.parameter_values(),
                stepper.parameter_values(), self.time_step,
            )  # fmt: skip
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
                    prerequisites_of_calc={self.discrete_state_ticket(self._x)},
                )

        def _construct_copy(self, other, converter=None):
            Impl._construct(
                self, other.stepper, other.on_unconverged, initial_state=other.initial_state,
                converter=converter, _geometry=other._geometry,
            )  # fmt: skip

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

        def _CalcGeometryPose(self, context, output):
            nq = self.stepper.sizes[0]
            x = context.get_discrete_state(self._x).value()
            g = self._geometry_T
            g.SetPositions(self._geometry_context, x[:nq])
            output.set_value(g.get_geometry_pose_output_port().Eval(self._geometry_context))

        def _stepper_for(self, smoothing_values, model_values) -> ComplementarityStepper:
            """The step under a Context's parameter values: a changed smoothing is used, the
            model parameters must keep the scene's values (they carry derivatives only)."""
            built_s, built_m = self._built
            if not np.array_equal(model_values, built_m):
                changed = [
                    f"{n}: {a:g} -> {b:g}"
                    for n, a, b in zip(
                        self.stepper.parameter_names, built_m, model_values, strict=True
                    )
                    if a != b
                ]
                raise ValueError(
                    "ComplementarityPlant: the model parameters in the Context carry derivatives "
                    "only; their values must stay those of the scene the plant was built from "
                    f"(changed: {', '.join(changed)}). Build the scene with the new values."
                )
            if np.array_equal(smoothing_values, built_s):
                return self.stepper
            return self._variant(
                smoothing_values.tobytes(),
                lambda: self.stepper.with_smoothing(
                    self.stepper.smoothing.with_parameters(smoothing_values)
                ),
            )

    return Impl


ComplementarityPlant = ComplementarityPlant_[None]
