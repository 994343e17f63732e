"""Drake's own contact models as a stepper: a scene's twin (the same model files in a discrete
MultibodyPlant under SAP, Similar or Lagged, compliant point contact at the scene's contact
points; :func:`~drake_abs.reference.drake_twin.make_drake_twin`) stepped one discrete update at
a time, batched over a leading axis, returning the one step record.

Coordinates are the scene's: x = (q, v) (nq + nv,) as :func:`drake_abs.multibody.build_scene_model`
orders them, u the actuation (nu,) in N or N m, applied as given (Drake's plant does not clip
the actuation at effort limits; this package's stepper does).

Jacobians ``dx_dx`` (B, nx, nx) and ``dx_du`` (B, nx, nu) come from the same update in
AutoDiffXd (the whole diagram converted, plant and SceneGraph), seeded with the identity on
(x, u). ``x_next`` is always the double update's, so a rollout is the same with or without
Jacobians. Drake's AutoDiffXd geometry supports only some shape pairs (a sphere against a box,
half-space or sphere); a twin whose active contacts need another pair raises
``NotImplementedError`` naming the geometries.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drake_abs._validation import batch_of_states
from drake_abs.contact.step import Step
from drake_abs.multibody.scene import Scene
from drake_abs.reference.drake_twin import APPROXIMATIONS, hydroelastic_settings, make_drake_twin

__all__ = ["DrakePlantStepper"]


class DrakePlantStepper:
    """A scene in Drake's discrete MultibodyPlant, as a :class:`~drake_abs.engine.Stepper`.

    Args:
        scene: a :class:`~drake_abs.multibody.scene.Scene`, a shipped scene's name or a YAML
            path.
        approximation: Drake's discrete contact approximation: ``"sap"``, ``"similar"`` or
            ``"lagged"``.
        time_step: the plant's period h (s); the scene's ``time_step`` by default.
        material: point-contact parameters ``point_stiffness`` (N/m),
            ``hunt_crossley_dissipation`` (s/m), ``relaxation_time`` (s, SAP); Drake's defaults
            for the missing ones.
        hydroelastic: None (point contact), or hydroelastic contact: ``modulus`` (Pa),
            ``resolution_hint`` (m), ``ground_thickness`` (m), as
            :func:`~drake_abs.reference.drake_twin.make_drake_twin` takes them. The scene's
            point candidates are then not modelled: ``impulse`` has no columns (nc = 0), and
            Jacobians exist only where Drake differentiates hydroelastic contact.

    ``step`` returns, besides the state: ``impulse`` (B, nc) the normal contact impulse (N s)
    of each of the scene's nc contact candidates over the step (Drake's contact force at the
    step's start state times h: a discrete plant's force acts over the whole step), ``mu`` zeros
    (Drake does not smooth by a central path), ``converged`` True (Drake raises when its
    solver fails), ``iterations`` 0.
    """

    parameter_names: tuple[str, ...] = ()

    def __init__(
        self,
        scene: Scene | str | Path,
        approximation: str = "sap",
        *,
        time_step: float | None = None,
        material: dict | None = None,
        hydroelastic: dict | None = None,
    ):
        if approximation not in APPROXIMATIONS:
            raise ValueError(
                f"approximation must be one of {sorted(APPROXIMATIONS)}; got {approximation!r}"
            )
        if time_step is not None and not (np.isfinite(time_step) and time_step > 0):
            raise ValueError(f"time_step must be a finite number > 0 (s); got {time_step!r}")
        self.scene = scene if isinstance(scene, Scene) else Scene.load(scene)
        self.approximation = approximation
        self.time_step = float(time_step or self.scene.time_step)
        self.material = None if material is None else dict(material)
        self.hydroelastic = hydroelastic_settings(hydroelastic)
        self._build()

    def _build(self) -> None:
        twin = make_drake_twin(
            self.scene, self.approximation, time_step=self.time_step, sampled_outputs=False,
            material=self.material, hydroelastic=self.hydroelastic,
        )  # fmt: skip
        self.twin = twin
        plant = twin.plant
        self.nq, self.nv = plant.num_positions(), plant.num_velocities()
        self.nu = plant.num_actuators()
        self._context = twin.diagram.CreateDefaultContext()
        self._plant_context = plant.GetMyMutableContextFromRoot(self._context)
        self._candidate = twin.candidates  # geometry -> contact candidate
        self.nc = twin.num_candidates
        self._autodiff = None  # the AutoDiffXd diagram, made when Jacobians are first asked for

    # pickling: Drake's systems cannot be pickled; the settings are, and rebuild the twin
    def __getstate__(self) -> dict:
        keys = ("scene", "approximation", "time_step", "material", "hydroelastic")
        return {k: getattr(self, k) for k in keys}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._build()

    @property
    def nx(self) -> int:
        """The state's size nq + nv."""
        return self.nq + self.nv

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False) -> Step:
        """One discrete update of each state of a batch.

        Args:
            x: (B, nq + nv) states or one state (nq + nv,).
            u: (B, nu) actuation (N, N m) or (nu,) shared by the batch.
            jacobians: also ``dx_dx`` (B, nx, nx), ``dx_du`` (B, nx, nu) by AutoDiffXd.
            parameters: must be False (Drake's plant here has no model parameters to
                differentiate).
        """
        if parameters:
            raise ValueError("parameters=True: DrakePlantStepper names no model parameters")
        x, u, batched = batch_of_states(x, u, self.nx, self.nu)
        B = x.shape[0]
        x_next = np.empty_like(x)
        impulse = np.zeros((B, self.nc))
        for b in range(B):
            x_next[b], impulse[b] = self._update(x[b], u[b])
        out = dict(x_next=x_next, impulse=impulse)
        if jacobians:
            out["dx_dx"], out["dx_du"] = self._jacobians(x, u)
        step = Step(
            converged=np.ones(B, bool), iterations=np.zeros(B, int), mu=np.zeros((B, self.nc)),
            **out,
        )  # fmt: skip
        return step if batched else step.first()

    def _update(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The double discrete update of one state, and the candidates' normal impulses."""
        plant, context, pc = self.twin.plant, self._context, self._plant_context
        plant.SetPositionsAndVelocities(pc, x)
        if self.nu:
            plant.get_actuation_input_port().FixValue(pc, u)
        update = self.twin.diagram.EvalUniquePeriodicDiscreteUpdate(context)
        impulse = np.zeros(self.nc)
        results = plant.get_contact_results_output_port().Eval(pc)
        for i in range(results.num_point_pair_contacts()):
            info = results.point_pair_contact_info(i)
            pair = info.point_pair()
            k = self._candidate.get(pair.id_A, self._candidate.get(pair.id_B))
            if k is not None:
                impulse[k] += abs(float(info.contact_force() @ pair.nhat_BA_W)) * self.time_step
        context.SetDiscreteState(update)
        return plant.GetPositionsAndVelocities(pc).copy(), impulse

    def _jacobians(self, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

        if self._autodiff is None:
            diagram = self.twin.diagram.ToAutoDiffXd()
            plant = diagram.GetSubsystemByName(self.twin.plant.get_name())
            context = diagram.CreateDefaultContext()
            self._autodiff = (diagram, plant, context, plant.GetMyMutableContextFromRoot(context))
        diagram, plant, context, pc = self._autodiff
        B, nx, nu = x.shape[0], self.nx, self.nu
        dx = np.empty((B, nx, nx))
        du = np.empty((B, nx, nu))
        for b in range(B):
            seeds = InitializeAutoDiff(np.concatenate([x[b], u[b]]).reshape(-1, 1)).ravel()
            plant.SetPositionsAndVelocities(pc, seeds[:nx])
            if nu:
                plant.get_actuation_input_port().FixValue(pc, seeds[nx:])
            try:
                update = diagram.EvalUniquePeriodicDiscreteUpdate(context)
            except RuntimeError as err:
                if "not supported for scalar type" not in str(err):
                    raise
                raise NotImplementedError(
                    f"Drake cannot differentiate this step of {self.scene.name!r}: "
                    f"{self._unsupported()}; Drake's message: {err}"
                ) from None
            # the plant's state is the diagram's only discrete state (group 0: q, v)
            grad = ExtractGradient(update.get_vector(0).CopyToVector().reshape(-1, 1))
            if grad.shape[1] != nx + nu:  # a value with no derivative gives an empty gradient
                grad = np.zeros((nx, nx + nu))
            dx[b], du[b] = grad[:, :nx], grad[:, nx:]
        return dx, du

    def _unsupported(self) -> str:
        """The collision candidates of the derivative's context without a sphere on either side
        (the pairs Drake's AutoDiffXd geometry queries refuse)."""
        _, plant, _, pc = self._autodiff
        inspector = plant.get_geometry_query_input_port().Eval(pc).inspector()
        named = []
        for pair in inspector.GetCollisionCandidates():
            shapes = [type(inspector.GetShape(g)).__name__ for g in pair]
            if "Sphere" not in shapes:
                names = [inspector.GetName(g).rsplit("::", 1)[-1] for g in pair]
                named.append(f"{names[0]} ({shapes[0]}) against {names[1]} ({shapes[1]})")
        return (
            "its collision candidates " + "; ".join(sorted(named))
            if named
            else "a contact between shapes without AutoDiffXd penetration queries"
        )
