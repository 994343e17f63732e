"""The complementarity plant as a Drake system: a MultibodyPlant's dynamics with the scene's
point contacts, stepped by :class:`drake_abs.multibody.ComplementarityStepper` (the same batched
step the rollouts use; this system only moves values and derivatives in and out of it).
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, ExtractValue
from pydrake.common.value import AbstractValue
from pydrake.geometry import FramePoseVector_
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from drake_abs._validation import check_finite_batch
from drake_abs.contact.unconverged import OnUnconverged, check_on_unconverged
from drake_abs.multibody.contact_results import PointContactResults, point_contact_results
from drake_abs.multibody.stepper import ComplementarityStepper
from drake_abs.systems import autodiff
from drake_abs.systems.plant_base import ComplementarityPlantBase


def _values(a) -> np.ndarray:
    """The values of a vector of floats or AutoDiffXd, as floats."""
    a = np.asarray(a)
    return ExtractValue(a).ravel() if autodiff.is_autodiff(a) else a.astype(float)


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
            - contact_results
            - geometry_pose

        State: one discrete vector x = (q, v) of the scene's plant, in the order of
        :meth:`plant`'s positions and velocities (:meth:`GetPositions`,
        :meth:`SetPositions`, ... as on a MultibodyPlant). Outputs ``impulse`` (the normal
        impulse of every contact candidate, N s), ``mu``, ``converged`` (1.0 or 0.0) and
        ``contact_results`` are those of the step that starts at the current state and input
        (the step the next update applies, solved once; see
        :mod:`drake_abs.systems.plant_base`). ``contact_results`` holds that step's contacts
        as Drake's ``PointPairContactInfo`` records (force = impulse / h, N), in a
        :class:`~drake_abs.multibody.contact_results.PointContactResults`, which reads like
        Drake's ``ContactResults``; pydrake cannot fill a ``ContactResults`` from Python, so
        Drake's ``ContactVisualizer`` cannot take this port:
        :class:`~drake_abs.systems.ContactForceVisualizer` draws it in Meshcat instead.
        ``geometry_pose`` exists when the plant was given a ``scene_graph`` (see
        :func:`~drake_abs.diagrams.scene_plant.AddComplementarityPlantSceneGraph`): the poses of
        the scene's geometry for that SceneGraph, as a MultibodyPlant's.

        Numeric parameters (in the Context; AutoDiffXd may seed derivatives on them):
        ``smoothing`` (the policy's parameters, ``stepper.smoothing_parameter_names``; index
        ``smoothing_parameter_index``; absent for exact contact) and ``model``
        (``stepper.parameter_names``: ground height, friction coefficients, masses, ...; index
        ``model_parameter_index``). A changed value of either is used by the next step: the
        stepper is rebuilt for it (:meth:`ComplementarityStepper.with_parameters`, no model
        file read), once per distinct value (cached by value, up to
        :data:`~drake_abs.systems.plant_base.MAX_VARIANTS` per plant), in a double Context
        as in an AutoDiffXd one (whose derivatives are then those at the new values). A value
        the stepper refuses (a mass <= 0, a negative friction coefficient, ...) raises
        ``ValueError`` naming it. The drawn geometry (``geometry_pose``) and :meth:`plant`
        keep the scene's values.

        Floating bases: a model's free root body has the coordinates its scene entry asks for
        (``ModelSpec.floating_base``): by default (``"euler"``) a chain of joints, q = (x, y,
        z, yaw, pitch, roll) and v their rates (singular at pitch = +-pi/2); with
        ``floating_base: quaternion``, or where the model file declares a floating joint (a
        URDF ``floating`` joint), Drake's ``QuaternionFloatingJoint``, q = (qw, qx, qy, qz, x,
        y, z) and v = (angular, translational velocity in the world). A MultibodyPlant gives
        every free body a quaternion floating joint by default: here that is the scene's
        choice (:func:`~drake_abs.diagrams.scene_plant.AddComplementarityPlantSceneGraph`'s
        ``floating_base`` sets it for every model).

        Under AutoDiffXd the step is solved in double and its implicit Jacobians are chained
        onto the incoming derivatives of the state, the input and the parameters; the
        derivatives are those of the simulation for the stepper's ``gradient="total"`` (the
        default), and Zhang et al. 2023's biased Algorithm 1 for ``"frozen"``. The ``mu``
        port carries values only (zero derivatives), as does ``contact_results``. Those of an
        unconverged step follow ``on_unconverged``.

        Args:
            stepper: the batched step (model, smoothing, gradient mode, activation distance).
            on_unconverged: ``"drop"`` (default: NaN derivatives, with a warning), ``"flag"``
                or ``"raise"`` (:mod:`drake_abs.contact.unconverged`).
            scene_graph, scene: register ``scene``'s geometry (the scene the stepper was
                built from) with ``scene_graph`` and declare ``geometry_pose``.
            initial_state: x0 = (q, v) of a new Context, shape (nq + nv,) (default: the model
                files' default positions, at rest; ``AddComplementarityPlantSceneGraph`` gives
                the scene's ``initial_state``). :meth:`GetDefaultPositions` and
                :meth:`GetDefaultVelocities` return it; ``SetDefaultContext(context)`` restores
                it (and the built parameter values) in a Context. A contact candidate deeper
                below the ground than the stepper's ``penetration_tolerance`` there raises
                :class:`~drake_abs.multibody.unmodelled_geometry.InitialPenetrationWarning`,
                and collision geometry that no candidate covers deeper than its
                ``unmodelled_tolerance``
                :class:`~drake_abs.multibody.unmodelled_geometry.UnmodelledPenetrationWarning`
                (as after every step: the stepper's option ``check_unmodelled``).
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
            _contact_ids=None,
            _check_initial=True,
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
            if _check_initial and self.initial_state.shape == (nq + nv,):
                # a start inside the ground, or with geometry no candidate covers below it
                stepper.check_state(self.initial_state, "ComplementarityPlant")
            self._declare_plant(
                T, nq + nv, nu, nc, self.initial_state, stepper.smoothing.parameter_values(),
                stepper.parameter_values(), self.time_step,
            )  # fmt: skip
            self._geometry = _geometry
            self._contact_ids = _contact_ids
            if scene_graph is not None:
                if scene is None:
                    raise ValueError(
                        "ComplementarityPlant: scene_graph needs the scene (its models and "
                        "contacts are drawn)"
                    )
                from drake_abs.multibody.geometry_plant import (
                    contact_geometry_ids,
                    make_geometry_plant,
                )

                self._geometry = make_geometry_plant(scene, scene_graph)
                n_geometry = self._geometry.num_positions()
                if n_geometry != nq:
                    raise ValueError(
                        f"ComplementarityPlant: scene {scene.name!r} has {n_geometry} positions, "
                        f"the stepper's model {nq}: not the scene the stepper was built from"
                    )
                self._contact_ids = contact_geometry_ids(
                    self._geometry, scene_graph.model_inspector(), stepper.model.contacts
                )
            # kinematics of the contact results (the dynamics plant's own Context)
            self._kinematics_context = stepper.model.plant.CreateDefaultContext()
            self.contact_results_port = self.DeclareAbstractOutputPort(
                "contact_results",
                lambda: AbstractValue.Make(PointContactResults()),
                self._CalcContactResults,
                prerequisites_of_calc={self._step_cache.ticket()},
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
                _contact_ids=other._contact_ids, _check_initial=False,
            )  # fmt: skip

        # --- the MultibodyPlant habits: sizes, state, defaults, the plant -------------------

        def num_positions(self) -> int:
            """nq, the number of generalized positions (q of x = (q, v))."""
            return self.stepper.sizes[0]

        def num_velocities(self) -> int:
            """nv, the number of generalized velocities (v of x = (q, v))."""
            return self.stepper.sizes[1]

        def num_multibody_states(self) -> int:
            """nq + nv, the size of the state x = (q, v)."""
            return self.num_positions() + self.num_velocities()

        def num_actuators(self) -> int:
            """nu, the size of the ``actuation`` input (one entry per actuator of
            :meth:`plant`, in its actuator order; N m or N, before the effort limits clip
            it)."""
            return self.stepper.sizes[2]

        def GetPositions(self, context) -> np.ndarray:
            """q (nq,) in this system's ``context`` (m, rad; quaternion entries for a
            quaternion floating base): a copy (AutoDiffXd entries under AutoDiffXd)."""
            return self._state(context)[: self.num_positions()].copy()

        def GetVelocities(self, context) -> np.ndarray:
            """v (nv,) in this system's ``context`` (m/s, rad/s): a copy."""
            return self._state(context)[self.num_positions() :].copy()

        def GetPositionsAndVelocities(self, context) -> np.ndarray:
            """x = (q, v) (nq + nv,) in this system's ``context``: a copy."""
            return self._state(context).copy()

        def SetPositions(self, context, q) -> None:
            """Set q (nq,) in this system's ``context`` (v kept). ``ValueError`` naming ``q``
            unless it has shape (nq,) and finite entries (floats, or AutoDiffXd under
            AutoDiffXd); a quaternion is not normalized here (the step normalizes its
            result)."""
            self._set_state(context, q, "q", 0, self.num_positions(), "SetPositions")

        def SetVelocities(self, context, v) -> None:
            """Set v (nv,) in this system's ``context`` (q kept); checked as
            :meth:`SetPositions` (``ValueError`` naming ``v``)."""
            nq = self.num_positions()
            self._set_state(context, v, "v", nq, self.num_velocities(), "SetVelocities")

        def SetPositionsAndVelocities(self, context, q_v) -> None:
            """Set x = (q, v) (nq + nv,) in this system's ``context``; checked as
            :meth:`SetPositions` (``ValueError`` naming ``q_v``). The same as
            ``context.SetDiscreteState(q_v)``, checked."""
            n = self.num_multibody_states()
            self._set_state(context, q_v, "q_v", 0, n, "SetPositionsAndVelocities")

        def GetDefaultPositions(self) -> np.ndarray:
            """q0 (nq,): the positions of a new Context (of ``SetDefaultContext``), from
            ``initial_state``: a copy."""
            return self.initial_state[: self.num_positions()].copy()

        def GetDefaultVelocities(self) -> np.ndarray:
            """v0 (nv,): the velocities of a new Context, from ``initial_state`` (a scene's
            ``initial_state.v``; a MultibodyPlant's are always 0): a copy."""
            return self.initial_state[self.num_positions() :].copy()

        def SetDefaultPositions(self, q) -> None:
            """Not available: a Drake LeafSystem written in Python fixes its default state
            when it is declared, so this plant's cannot change afterwards. Build the plant with
            the state (``initial_state=`` here, the scene's ``initial_state`` for
            :func:`~drake_abs.diagrams.scene_plant.AddComplementarityPlantSceneGraph`), or set
            it in a Context (:meth:`SetPositions`).

            Raises:
                NotImplementedError: always, saying so.
            """
            raise NotImplementedError(
                f"{self._name()}: SetDefaultPositions: the default state is fixed when the "
                "plant is built (a Python LeafSystem cannot change it): build the plant with "
                "initial_state=... (a scene's initial_state for "
                "AddComplementarityPlantSceneGraph), or set q in a Context with "
                "SetPositions(context, q)"
            )

        def plant(self) -> MultibodyPlant:
            """The MultibodyPlant (double, continuous, finalized) of this plant's model: its
            bodies, frames, joints and actuators, with q and v in this system's order (x =
            (q, v) of this system's state poses it directly). With geometry
            (:func:`~drake_abs.diagrams.scene_plant.AddComplementarityPlantSceneGraph`) it is
            the one registered with the SceneGraph (its ``get_source_id()``, geometry ids and
            frame ids are the SceneGraph's), otherwise the stepper's dynamics plant
            (``stepper.model.plant``, no SceneGraph); both have the same bodies, in the same
            order (the body indices of ``contact_results``).

            It is not a system of the diagram (no port of it is connected, its time step is
            0): use it with a Context of its own for kinematics, e.g.
            ``mbp.SetPositions(mbp_context, plant.GetPositions(context))`` then
            ``mbp.EvalBodyPoseInWorld(mbp_context, mbp.GetBodyByName("box"))``. Its default
            masses and inertias are the model files' (a changed ``model`` parameter is this
            system's, not its)."""
            return self.stepper.model.plant if self._geometry is None else self._geometry

        def get_contact_results_output_port(self):
            """``contact_results``: the contacts of the step from the current state, a
            :class:`~drake_abs.multibody.contact_results.PointContactResults` (point pairs as
            Drake's ``PointPairContactInfo``; draw them with
            :class:`~drake_abs.systems.ContactForceVisualizer`)."""
            return self.contact_results_port

        def _state(self, context) -> np.ndarray:
            self.ValidateContext(context)
            return context.get_discrete_state(self._x).value()

        def _set_state(self, context, value, name: str, start: int, size: int, method: str):
            """Write ``value`` (the argument ``name`` of ``method``) into x[start : start +
            size] of ``context``, checked (shape, numbers, finite)."""
            x = self._state(context).copy()
            where = f"{self._name()}: {method}: "
            arr = np.asarray(value)
            if arr.shape != (size,):
                raise ValueError(f"{where}{name} must have shape ({size},); got {arr.shape}")
            if not autodiff.is_autodiff(arr):
                try:
                    arr = arr.astype(float)
                except (TypeError, ValueError):
                    raise ValueError(
                        f"{where}{name} must hold {size} numbers; got {value!r:.80}"
                    ) from None
            elif T is float:
                raise ValueError(
                    f"{where}{name} must hold floats in a double Context; got AutoDiffXd "
                    "(convert the system with ToAutoDiffXd() to carry derivatives)"
                )
            check_finite_batch(_values(arr)[None], name, batched=False, what=where)
            x[start : start + size] = arr
            context.get_mutable_discrete_state(self._x).SetFromVector(x)

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

        def _CalcContactResults(self, context, output) -> None:
            step = self._step_cache.Eval(context)
            nq = self.num_positions()
            s, m = (_values(a) for a in self._parameters(context))
            model = self._stepper_for(s, m).model
            output.set_value(
                point_contact_results(
                    model,
                    _values(self._state(context))[:nq],
                    _values(step[0])[nq:],
                    _values(step[1]),
                    step[4],
                    context=self._kinematics_context,
                    geometry_ids=self._contact_ids,
                    plant=self.plant(),
                )  # fmt: skip
            )

        def _stepper_for(self, smoothing_values, model_values) -> ComplementarityStepper:
            """The step under a Context's parameter values: the built stepper for the built
            values, else one rebuilt for them (:meth:`ComplementarityStepper.with_parameters`
            for the model's, :meth:`~ComplementarityStepper.with_smoothing` for the
            smoothing's), made once per distinct value (cached by value, see
            :data:`~drake_abs.systems.plant_base.MAX_VARIANTS`)."""
            built_s, built_m = self._built
            same_s = np.array_equal(smoothing_values, built_s)
            same_m = np.array_equal(model_values, built_m)
            if same_s and same_m:
                return self.stepper
            model = self.stepper
            if not same_m:  # one rebuild per model values, shared by every smoothing
                model = self._variant(
                    ("model", model_values.tobytes()),
                    lambda: self._with_model_values(model_values),
                )
            if same_s:
                return model
            return self._variant(
                ("smoothing", smoothing_values.tobytes(), model_values.tobytes()),
                lambda: model.with_smoothing(model.smoothing.with_parameters(smoothing_values)),
            )

        def _with_model_values(self, model_values: np.ndarray) -> ComplementarityStepper:
            """The stepper rebuilt for a Context's model parameter values (T,), or a
            ``ValueError`` naming the plant and the value refused."""
            try:
                return self.stepper.with_parameters(model_values)
            except ValueError as err:
                raise ValueError(
                    f"{self._name()}: the model parameters in the Context (model_parameter_"
                    f"index, in stepper.parameter_names order): {err}"
                ) from err

    return Impl


ComplementarityPlant = ComplementarityPlant_[None]
