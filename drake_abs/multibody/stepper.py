"""The batched complementarity step of a multibody scene: one step ``x+ = f(x, u)`` of a plant
with point contacts, for a batch of states, with its Jacobians (docs/math.md section 6).

:class:`ComplementarityStepper` is the one implementation of this step: the Drake system
:class:`drake_abs.systems.ComplementarityPlant` and the batched rollouts call it. It leaves out
contacts farther than the activation distance, so a step's cost follows the contacts in play, not
the size of the model. Build one from a scene with :func:`drake_abs.multibody.make_stepper`, which
applies every setting the scene names.
"""

from __future__ import annotations

import copy
import functools
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np

from drake_abs._validation import as_real_number, batch_of_states, check_finite_batch
from drake_abs.contact.compliance import ContactCompliance
from drake_abs.contact.cone import FORMULATIONS, FrictionCone
from drake_abs.contact.contact_lcp import CONTACT_SOLVER_DEFAULTS, contact_step
from drake_abs.contact.damping import JointSprings, damped_parameters, effective_damping
from drake_abs.contact.lcs import GradientMode, check_gradient_mode
from drake_abs.contact.smoothing import Exact, Smoothing
from drake_abs.contact.step import Step
from drake_abs.contact.step_data import ParameterDerivatives, StepQuantities
from drake_abs.lcp.ipm import check_solver_options
from drake_abs.multibody.drake_dynamics import ContactModelBase
from drake_abs.multibody.floating import normalize_quaternions
from drake_abs.multibody.joint_friction import JointFrictionRows, JointFrictionSmoothing
from drake_abs.multibody.joint_limits import (
    JointLimitRows,
    effort_limits,
    joint_damping,
    joint_springs,
    spring_integration,
)
from drake_abs.multibody.parameters import (
    damping_columns,
    damping_joints,
    parameter_columns,
    parameter_derivatives,
    parameter_names,
    parameter_values,
    parameter_vector,
    with_values,
)
from drake_abs.multibody.unmodelled_geometry import (
    UnmodelledGeometry,
    warn_initial_penetration,
)

#: how deep (m) a candidate left out of a step's LCP may end below the ground before the step
#: is solved again with it (see ``ComplementarityStepper._repair``)
REPAIR_TOL = 1e-6
MAX_REPAIRS = 3

#: How deep (m) a state's contact candidate may be below its surface before the state counts as
#: inside the ground, with hard contact: a hard-contact step ends at most a linearisation error
#: (micrometres) below it (soft contact: :data:`SOFT_PENETRATION_TOL`). A deeper state is not
#: one the step models (the step pushes the body out in one step, with an impulse no scene
#: produced), so
#: :meth:`ComplementarityStepper.penetration` reports it and
#: :class:`drake_abs.tasks.gym_env.DrakeAbsEnv` refuses to set it.
PENETRATION_TOL = 0.01
#: The same for a plant with soft (MuJoCo-like) contact (m), whose states rest inside the ground
#: by design: its spring pushes a deeper body out over several steps, as MuJoCo's does. MuJoCo's
#: own gym models rest up to 17 mm deep (the HalfCheetah, ``mujoco-comparison``); a body 5 cm
#: deep is beyond any resting state of these scenes.
SOFT_PENETRATION_TOL = 0.05

#: The options a stepper passes on to its contact solve (``**solver_options``): the
#: interior-point solver's ``tol``, ``max_iterations`` and ``exact_tol``
#: (:func:`drake_abs.solve_lcp`) and ``strict`` (raise instead of flagging an unconverged
#: solve). Any other name is refused when the stepper is built.
SOLVER_OPTIONS = ("tol", "max_iterations", "exact_tol", "strict")


@dataclass(frozen=True)
class ContactProblem:
    """The inputs of one batched step's LCP (:meth:`ComplementarityStepper.contact_problem`).

    Attributes:
        quantities: the step's :class:`~drake_abs.contact.step_data.StepQuantities` (no
            state derivatives): W and v_free of the damped step (joint damping and springs
            taken implicitly), distances ``phi`` (m) and
            rows ``Jn`` of the ``n_contacts`` candidates followed by the joint-limit rows and
            the joint-friction rows (pinned: :mod:`drake_abs.multibody.joint_friction`),
            tangent rows ``Jt`` (the candidates', then the joint frictions').
        cone: the friction cone over those rows (joint-limit rows frictionless).
        h: the time step (s).
        parameters: derivatives in the model parameters ``theta_names`` (None unless asked).
        theta_names: the columns of ``parameters``.
        n_contacts: the number of contact candidates (the rows after them are joint limits,
            then joint friction).
    """

    quantities: StepQuantities
    cone: FrictionCone
    h: float
    parameters: ParameterDerivatives | None
    theta_names: tuple[str, ...]
    n_contacts: int


class StepOverflowWarning(UserWarning):
    """A step from a finite state gave a non-finite next state or Jacobian (e.g. explicit
    Coriolis terms at very large joint velocities); its ``converged`` flag is False."""


class ExplicitSpringWarning(UserWarning):
    """Joint springs taken explicitly (``springs="explicit"``) past their stability bound at
    the model's time step: ``h^2 K_j W_jj >= 4`` at the plant's default configuration (W the
    inverse mass matrix, armature included), where the explicit step's oscillation grows each
    step, as MuJoCo's Euler integrator's does. Take them implicitly or reduce the time step."""


def warn_unstable_explicit_springs(model: ContactModelBase, springs: JointSprings) -> None:
    """Warn (:class:`ExplicitSpringWarning`) when an explicit spring of ``model`` is past the
    stability bound of its step (above), naming each velocity and its ``h^2 K W_jj``."""
    if springs.implicit or not springs.active:
        return
    plant = model.plant
    q0 = plant.GetPositions(plant.CreateDefaultContext())[None]
    quant = model.quantities(
        q0, np.zeros((1, model.nv)), np.zeros((1, model.nu)), np.arange(0), derivatives=False
    )
    bound = model.h**2 * springs.stiffness * np.diag(np.asarray(quant.W, dtype=float)[0])
    bad = np.flatnonzero(bound >= 4.0)
    if bad.size:
        listed = ", ".join(f"velocity {j}: {bound[j]:.3g}" for j in bad)
        warnings.warn(
            f"explicit joint springs past their stability bound h^2 K W_jj < 4 at h = "
            f"{model.h} s ({listed}): their oscillation grows each step; take them "
            "implicitly (springs='implicit', scene joint_springs: implicit) or reduce the "
            "time step",
            ExplicitSpringWarning,
            stacklevel=3,
        )


def check_unmodelled_option(value) -> bool | float:
    """``check_unmodelled`` checked: True, False, or a tolerance (m, a number >= 0; ``inf``:
    off); ``ValueError`` naming it otherwise."""
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if (
        not isinstance(value, int | float | np.integer | np.floating)
        or np.isnan(value)
        or value < 0
    ):
        raise ValueError(
            "check_unmodelled must be True, False or a tolerance in m (a number >= 0); got "
            f"{value!r}"
        )
    return float(value)


def check_solver_options_given(options: Mapping) -> None:
    """Refuse, when a stepper is built rather than at its first step, a solver option that is
    not one of :data:`SOLVER_OPTIONS` (a misspelt or misplaced setting would otherwise fail
    only when stepping) or that has a bad value (``ValueError`` naming it)."""
    unknown = sorted(set(options) - set(SOLVER_OPTIONS))
    if unknown:
        raise ValueError(
            f"unknown stepper option(s) {unknown}: a stepper takes smoothing, gradient, "
            "activation_distance, friction, joint_limits, damping, springs, joint_friction, "
            f"compliance, check_unmodelled and the solver's {', '.join(SOLVER_OPTIONS)}"
        )
    for name in ("tol", "exact_tol"):
        if name in options:
            as_real_number(options[name], name)
    merged = {**CONTACT_SOLVER_DEFAULTS, "tol": 1e-12, **options}
    check_solver_options(merged["tol"], merged["max_iterations"], merged["exact_tol"])
    if "strict" in options and not isinstance(options["strict"], bool | np.bool_):
        raise ValueError(f"strict must be True or False; got {options['strict']!r}")


class ComplementarityStepper:
    """Batched step ``x+ = f(x, u)`` with Jacobians, for one contact model.

    Args:
        model: the plant's contact model (quantities and derivatives).
        smoothing: per-contact mu policy (default Exact); larger mu is smoother.
        gradient: ``"frozen"`` or ``"total"`` (see
            :func:`drake_abs.contact.contact_lcp.contact_step`).
        activation_distance: candidates farther than this (m) are left out of the LCP.
        friction: the friction formulation, ``"stewart_trinkle"`` (default, the papers') or
            ``"anitescu"`` (monotone; converges under every smoothing, but a sliding contact
            lifts off at ``alpha |v_t|``): see
            :class:`~drake_abs.contact.cone.FrictionCone`.
        joint_limits: honour the plant's joint position limits (unilateral rows in the same
            LCP as the contacts, smoothed by the same policy, pruned by the same activation
            distance in rad or m) and its actuators' effort limits (the input is clipped to
            them; a clipped input's column of ``dx_du`` is 0). See
            :mod:`drake_abs.multibody.joint_limits`.
        damping: apply the plant's joint damping, implicitly (stable at any h; see
            :mod:`drake_abs.contact.damping`).
        springs: apply the plant's joint springs (its ``RevoluteSpring`` and
            ``PrismaticSpring`` force elements: an MJCF joint's ``stiffness``, an SDF joint's
            ``spring_stiffness``; :func:`~drake_abs.multibody.joint_limits.joint_springs`):
            True or ``"implicit"`` takes them implicitly like the damping (stable at any h),
            ``"explicit"`` at the step's start as MuJoCo's Euler integrator does
            (:mod:`drake_abs.contact.damping`), False drops them.
        joint_friction: dry friction bound per velocity (nv,) (N m or N; 0 or None: none), e.g.
            the MJCF joints' ``frictionloss``
            (:attr:`drake_abs.multibody.builder.SceneModel.joint_friction`, which
            :meth:`~drake_abs.multibody.builder.SceneModel.stepper` passes): complementarity
            rows in the same LCP as the contacts and joint limits, smoothed by the same policy
            (:mod:`drake_abs.multibody.joint_friction`; Stewart-Trinkle only). The step's
            ``joint_friction_impulse`` holds their impulses.
        compliance: soft contact as MuJoCo's (solref, solimp, margin per candidate;
            :class:`~drake_abs.contact.compliance.ContactCompliance`), or None (default) for
            hard contact. A soft candidate has rows only while its distance is below its
            margin (as MuJoCo's contacts), and a step may end with it below the ground.
        check_unmodelled: after every step, measure how deep the collision geometry that no
            contact candidate covers lies below the ground, and warn
            (:class:`~drake_abs.multibody.unmodelled_geometry.UnmodelledPenetrationWarning`,
            once per body and stepper, naming the body, the depth and the contact entries that
            would model it) where it is deeper than the tolerance: True (default) with
            :attr:`penetration_tolerance` (1 cm with hard contact, 5 cm with soft), a number
            for another tolerance (m), False (or ``inf``) for no check. Only a stepper built
            from a scene has the geometry (:attr:`unmodelled`); the check costs 1 to 4 % of a
            step (:mod:`drake_abs.multibody.unmodelled_geometry`).
        solver_options: passed to the interior-point solver.
    """

    def __init__(
        self,
        model: ContactModelBase,
        smoothing: Smoothing | None = None,
        gradient: GradientMode = "total",
        activation_distance: float = float("inf"),
        friction: str = "stewart_trinkle",
        joint_limits: bool = True,
        damping: bool = True,
        springs: bool | str = True,
        joint_friction: np.ndarray | None = None,
        compliance: ContactCompliance | None = None,
        check_unmodelled: bool | float = True,
        **solver_options,
    ):
        check_gradient_mode(gradient)
        self.check_unmodelled = check_unmodelled_option(check_unmodelled)
        check_solver_options_given(solver_options)
        spring_mode = spring_integration(springs)
        if friction not in FORMULATIONS:
            raise ValueError(f"friction must be one of {FORMULATIONS}; got {friction!r}")
        self.friction = friction
        self.model = model
        self.smoothing = Exact() if smoothing is None else smoothing
        self.gradient = gradient
        self.activation_distance = float(activation_distance)
        self.solver_options = solver_options
        plant = model.plant
        self.limits = JointLimitRows.of(plant if joint_limits else None)
        self.effort = effort_limits(plant) if joint_limits else np.full(model.nu, np.inf)
        self._clips = bool(np.isfinite(self.effort).any())  # per-step work only where needed
        self._set_joint_terms(
            joint_damping(plant) if damping else np.zeros(model.nv),
            joint_springs(plant, implicit=spring_mode != "explicit")
            if spring_mode
            else JointSprings.none(model.nv),
        )
        warn_unstable_explicit_springs(model, self.springs)
        self._flags = {
            "joint_limits": bool(joint_limits),
            "damping": bool(damping),
            "springs": spring_mode,
        }
        self.joint_friction = JointFrictionRows.of(plant, joint_friction)
        if self.joint_friction.size and friction != "stewart_trinkle":
            raise ValueError(
                "joint_friction (dry joint friction rows) needs friction='stewart_trinkle'; got "
                f"friction={friction!r}"
            )
        if compliance is not None and compliance.size != len(model.contacts):
            raise ValueError(
                f"compliance must have one entry per contact candidate ({len(model.contacts)}); "
                f"got {compliance.size}"
            )
        self.compliance = compliance
        #: The scene this stepper was built from (set by
        #: :meth:`drake_abs.multibody.builder.SceneModel.stepper`), which
        #: makes it picklable: it is sent as the scene description and its settings, and
        #: rebuilt where it is unpickled (a Ray worker: :mod:`drake_abs.parallel`).
        self.scene = None
        #: The function that rebuilds it there, ``rebuild(scene, settings)`` (set with
        #: :attr:`scene`: :func:`drake_abs.multibody.builder.rebuild_stepper`).
        self.rebuild = None
        #: the model parameters :meth:`with_parameters` changed from the scene's, ``{name:
        #: value}`` (pickled with the settings)
        self._parameters: dict[str, float] = {}
        #: The scene's collision geometry that no contact candidate covers
        #: (:class:`~drake_abs.multibody.unmodelled_geometry.UnmodelledGeometry`, read from the
        #: model files when first needed), which ``check_unmodelled`` measures after every
        #: step; set with :attr:`scene` (None: no check).
        self.unmodelled: UnmodelledGeometry | None = None
        #: the bodies already warned about (once per body; shared with this stepper's copies,
        #: :meth:`with_smoothing`, :meth:`with_parameters`)
        self._unmodelled_warned: set[str] = set()

    def _set_joint_terms(self, damping: np.ndarray, springs: JointSprings) -> None:
        """Hold the joint damping (nv,) and springs, and what the provider is passed of them
        (None where all are 0)."""
        self.damping, self.springs = damping, springs
        self._damps = bool(damping.any()) or springs.active  # the step's W, v_free move
        self._damping = damping if damping.any() else None  # passed to the provider
        self._springs = springs if springs.active else None

    def __copy__(self) -> ComplementarityStepper:
        """A shallow copy (the same contact model), for :meth:`with_smoothing` and
        :meth:`with_parameters`; without it ``copy.copy`` would go through :meth:`__reduce__`,
        which rebuilds the stepper from its scene (or fails without one)."""
        other = object.__new__(type(self))
        other.__dict__.update(self.__dict__)
        return other

    def __reduce__(self):
        """Pickled as its scene and settings (see :attr:`scene`); a stepper built from a contact
        model directly has no description to send."""
        if self.scene is None or self.rebuild is None:
            raise TypeError(
                "this ComplementarityStepper was built from a contact model, not from a scene, "
                "so it cannot be pickled (e.g. sent to Ray workers): build it with "
                "make_stepper(scene, ...) or SceneModel.stepper(...)"
            )
        settings = dict(
            smoothing=self.smoothing, gradient=self.gradient,
            activation_distance=self.activation_distance, friction=self.friction,
            check_unmodelled=self.check_unmodelled, **self._flags, **self.solver_options,
        )  # fmt: skip
        if self.compliance is not None:
            settings["compliance"] = self.compliance
        if self.joint_friction.size:
            bound = np.zeros(self.sizes[1])
            bound[self.joint_friction.v_index] = self.joint_friction.bound
            settings["joint_friction"] = bound
        if self._parameters:  # a stepper of with_parameters: the scene's, then its changes
            settings["parameters"] = dict(self._parameters)
        return self.rebuild, (self.scene, settings)

    @property
    def sizes(self) -> tuple[int, int, int, int]:
        """``(nq, nv, nu, nc)``."""
        m = self.model
        return m.nq, m.nv, m.nu, len(m.contacts)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """The model parameters ``step(..., parameters=True)`` differentiates with respect to,
        in column order (docs/math.md section 6d):

        - ``"ground_height"`` (m);
        - ``"friction[i]"`` for every frictional contact candidate i (its Coulomb coefficient);
        - ``"mass[body]"`` (kg) for every body with a mass (its centre of mass and unit inertia
          held);
        - ``"radius[i]"`` (m) for every point candidate i against the ground (radius 0
          included): the sphere's radius, which moves the distance and the witness point;
        - ``"damping[joint]"`` (N m s / rad or N s / m) for every one-velocity joint (revolute,
          prismatic; ``"instance::joint"`` where a name occurs in several model instances),
          when this stepper applies joint damping (``damping=True``), also where it is 0;
        - ``"offset[i].x"``, ``".y"``, ``".z"`` (m) for every point candidate i: its point
          ``p_BC`` in its body's frame;
        - ``"unit_inertia[body].xx"``, ``".yy"``, ``".zz"``, ``".xy"``, ``".xz"``, ``".yz"``
          (m^2) for every body with a mass: the entries of its rotational inertia about its
          centre of mass, in its body frame, per unit mass (the rotational inertia is the mass
          times this, so a mass column keeps this held; a product column moves both symmetric
          entries of the matrix; Drake's sign convention, the matrix entries). These come after
          the offsets, so the columns before them keep their indices;
        - ``"stiffness[joint]"`` (N m / rad or N / m), then ``"springref[joint]"`` (rad or m),
          for every one-velocity joint, when this stepper applies joint springs
          (``springs=True``), also where the stiffness is 0: the joint springs (taken
          implicitly, :mod:`drake_abs.contact.damping`). These come last.

        :meth:`with_parameters` gives a stepper with other values of any of them
        (:mod:`drake_abs.multibody.parameters`).
        """
        return parameter_names(self.model, self._damping_joints, self._spring_joints)

    @functools.cached_property
    def _damping_joints(self) -> tuple[tuple[str, int], ...]:
        """``(name, velocity index)`` of every one-velocity joint, the joint-damping parameters
        (none when this stepper does not apply damping). A name that occurs in several model
        instances is qualified as ``"instance::joint"``."""
        return damping_joints(self.model.plant) if self._flags["damping"] else ()

    @functools.cached_property
    def _spring_joints(self) -> tuple[tuple[str, int], ...]:
        """``(name, velocity index)`` of every one-velocity joint with a position coordinate,
        the joint-spring parameters (none when this stepper does not apply springs)."""
        if not self._flags["springs"]:
            return ()
        q_index = self.springs.q_index
        return tuple((n, v) for n, v in damping_joints(self.model.plant) if q_index[v] >= 0)

    def with_smoothing(self, smoothing: Smoothing) -> ComplementarityStepper:
        """The same stepper with another smoothing (larger mu: more smoothing)."""
        if not isinstance(smoothing, Smoothing):
            raise ValueError(f"smoothing must be a Smoothing; got {type(smoothing).__name__}")
        other = copy.copy(self)
        other.smoothing = smoothing
        return other

    def parameter_values(self) -> np.ndarray:
        """The values of :attr:`parameter_names` in this stepper's model (T,): the ground
        height (m), the friction coefficients (dimensionless), the masses (kg), the point
        candidates' radii (m), the joint damping (N m s / rad or N s / m), the point
        candidates' offsets (m), the bodies' unit rotational inertias about their centres of
        mass (m^2), the joint springs' stiffness (N m / rad or N / m) and reference (rad or m).
        The masses and inertias are those the dynamics use (the plant's defaults, or those
        :meth:`with_parameters` set)."""
        return parameter_values(
            self.model, self.damping, self._damping_joints, self.springs, self._spring_joints
        )

    def with_parameters(self, values: np.ndarray | Mapping[str, float]) -> ComplementarityStepper:
        """A stepper whose :meth:`parameter_values` are ``values`` (this one is left as it is):
        an array of all of them in :attr:`parameter_names` order (T,), or a mapping ``{name:
        value}`` of some of them (the others kept). Every column takes effect in the step and
        its Jacobians: the ground height, each candidate's friction coefficient, each body's
        mass (centre of mass and unit inertia held, so its rotational inertia scales with it,
        as ``RigidBody.SetMass`` does) and unit inertia, each point candidate's radius and
        offset, each joint's damping and spring. The plant is shared (its default inertias
        cannot change once finalized): the contact model is rebuilt on it with the bodies'
        inertias as overrides
        (:meth:`~drake_abs.multibody.drake_dynamics.ContactModelBase.rebuilt`), no model file
        is read. A stepper built from a scene stays picklable: it is sent as the
        scene, its settings and the parameters changed.

        Raises:
            ValueError: for an array of another length, an unknown name, a value that is not a
                finite number, a mass <= 0, a negative radius, friction coefficient, damping or
                stiffness,
                or a unit inertia that is not physically valid (its moments must satisfy the
                triangle inequality).
        """
        names = self.parameter_names
        current = self.parameter_values()
        new = parameter_vector(values, names, current)
        model, damping, springs, changed = with_values(
            self.model, self.damping, self._damping_joints, names, new, current,
            self.springs, self._spring_joints,
        )  # fmt: skip
        other = copy.copy(self)
        other.__dict__.pop("_cones", None)  # friction cones of this model
        other.model = model
        other.solver_options = dict(self.solver_options)
        other._set_joint_terms(damping, springs)
        other._parameters = {**self._parameters, **changed}
        return other

    @property
    def penetration_tolerance(self) -> float:
        """How deep (m) a state may be inside the ground and still be one the step models:
        :data:`PENETRATION_TOL` with hard contact, :data:`SOFT_PENETRATION_TOL` with soft."""
        return PENETRATION_TOL if self.compliance is None else SOFT_PENETRATION_TOL

    @property
    def unmodelled_tolerance(self) -> float | None:
        """How deep (m) collision geometry that no candidate covers may lie below the ground
        after a step before a warning
        (:class:`~drake_abs.multibody.unmodelled_geometry.UnmodelledPenetrationWarning`): the
        option ``check_unmodelled`` (:attr:`penetration_tolerance` for True); None when the
        check is off or the stepper has no geometry (:attr:`unmodelled`)."""
        if self.unmodelled is None or self.check_unmodelled is False:
            return None
        if self.check_unmodelled is True:
            return self.penetration_tolerance
        return None if np.isinf(self.check_unmodelled) else float(self.check_unmodelled)

    def check_state(self, x, where: str | None = None) -> None:
        """Warn about a state this stepper starts from (one state (nq + nv,)): its contact
        candidates deeper than :attr:`penetration_tolerance` below the ground
        (:class:`~drake_abs.multibody.unmodelled_geometry.InitialPenetrationWarning`, naming
        each candidate, its scene entry and its depth) and, with ``check_unmodelled``, its
        uncovered collision geometry deeper than :attr:`unmodelled_tolerance`
        (:class:`~drake_abs.multibody.unmodelled_geometry.UnmodelledPenetrationWarning`, once
        per body). ``where`` starts the first message (default: the scene's name).
        :class:`~drake_abs.systems.ComplementarityPlant` calls it with its initial state."""
        nq = self.sizes[0]
        q = np.asarray(x, dtype=float).reshape(-1)[:nq]
        if where is None:
            where = "ComplementarityStepper" if self.scene is None else f"scene {self.scene.name!r}"
        warn_initial_penetration(
            self.model, q, self.penetration_tolerance, where, self.scene, stacklevel=2
        )
        self._check_unmodelled(q[None], stacklevel=3)

    def _check_unmodelled(self, q: np.ndarray, stacklevel: int = 3) -> None:
        """Warn once per body whose uncovered collision geometry is deeper than
        :attr:`unmodelled_tolerance` below the ground at some state of q (B, nq)."""
        tolerance = self.unmodelled_tolerance
        if tolerance is not None:
            self.unmodelled.check(
                q, self.model.ground, tolerance, self._unmodelled_warned, stacklevel
            )

    def penetration(self, x) -> np.ndarray:
        """How deep (m) each state of x (B, nq + nv) (or one state (nq + nv,)) is inside the
        ground: the largest depth of a contact candidate below its surface (its signed distance
        with the sign turned), 0 where none is below. (B,), or a float for one state. A depth
        above :attr:`penetration_tolerance` is a state the step does not model."""
        nq, nv, _, nc = self.sizes
        arr = np.asarray(x, dtype=float)
        single = arr.ndim == 1
        arr = np.atleast_2d(arr)
        if arr.ndim != 2 or arr.shape[1] != nq + nv:
            raise ValueError(
                f"x must have shape (B, nq + nv) = (B, {nq + nv}) or (nq + nv,); got {arr.shape}"
            )
        check_finite_batch(arr, "x", batched=not single)
        depth = np.zeros(arr.shape[0])
        if nc:
            depth = np.maximum(0.0, -self.model.distances(arr[:, :nq]).min(axis=1))
        return float(depth[0]) if single else depth

    @property
    def smoothing_parameter_names(self) -> tuple[str, ...]:
        """The smoothing's numeric parameters as ``step(..., smoothing_parameters=True)``
        names its columns: ``"smoothing.<name>"`` (e.g. ``smoothing.mu_max``)."""
        return tuple(f"smoothing.{n}" for n in self.smoothing.parameter_names)

    def step(
        self,
        x: np.ndarray,
        u: np.ndarray,
        *,
        jacobians: bool = True,
        parameters: bool | Sequence[str] = False,
        smoothing_parameters: bool = False,
    ) -> Step:
        """Step a batch: x (B, nq + nv), u (B, nu) or (nu,) shared. With ``parameters`` (and
        ``jacobians``), also the derivatives with respect to :attr:`parameter_names`, or to the
        names given (a sequence of some of them: only those columns are computed, in that
        order).

        Returns:
            a :class:`~drake_abs.contact.step.Step` over the nc contact candidates: ``impulse``
            is each candidate's normal impulse, ``friction_impulse`` its tangential impulse
            in the world (B, nc, 3) (N s; on the body for a ground contact, on body A for a
            pair candidate, whose normal impulse acts along its own normal), ``active`` which
            candidates were in the LCP.
        """
        if (parameters or smoothing_parameters) and not jacobians:
            raise ValueError("parameters=True and smoothing_parameters=True need jacobians=True")
        # the theta columns: the model's parameters, then the smoothing's
        names = parameter_columns(parameters, lambda: self.parameter_names) + (
            self.smoothing_parameter_names if smoothing_parameters else ()
        )
        nq, nv, nu, nc = self.sizes
        x, u, saturated = self._inputs(x, u)
        B = x.shape[0]
        q, v = x[:, :nq], x[:, nq:]
        # soft contacts have rows only within their margins (MuJoCo's contacts)
        soft = self.compliance is not None
        pruned = np.isfinite(self.activation_distance) or soft
        if self.limits.size:
            limit_active = np.ones((B, self.limits.size), dtype=bool)
            if pruned:
                limit_active = self.limits.distances(q) <= self.activation_distance
        groups = None  # (rows, active contact indices, quantities or None) per active set
        if B == 1 and pruned and not soft:  # one state: the provider shares kinematics
            idx, quant = self.model.quantities_within(
                q, v, u, self.activation_distance, derivatives=jacobians, damping=self._damping,
                springs=self._springs,
            )  # fmt: skip
            active = np.zeros((1, nc), dtype=bool)
            active[0, idx] = True
            groups = [(slice(None), idx, quant)]
        elif pruned:
            phi = self.model.distances(q)
            active = phi <= self.activation_distance
            if soft:
                active &= self.compliance.active(phi)
        else:  # nothing to prune: skip the distance evaluation
            active = np.ones((B, nc), dtype=bool)
        if self.limits.size:  # contacts, then limit rows
            active = np.concatenate([active, limit_active], axis=1)
        if groups is not None and self.limits.size:  # the one state's contacts, then limits
            both = np.concatenate([groups[0][1], nc + np.flatnonzero(limit_active[0])])
            groups = [(slice(None), both, groups[0][2])]
        out = self._solve(q, v, u, active, groups, jacobians, names)
        if pruned:
            self._repair(q, v, u, active, out, jacobians, names)
        if jacobians and saturated is not None:  # a clipped input does not move the step
            for key in ("dx_du", "dimpulse_du"):
                out[key] = out[key] * ~saturated[:, None, :]
        # free bodies' quaternions back to unit norm, Jacobians chained (multibody/floating.py)
        starts = getattr(self.model, "quaternion_starts", ())
        if len(starts):
            normalize_quaternions(out, starts)
        finite = np.isfinite(out["x_next"]).all(axis=1)
        for key in ("dx_dx", "dx_du", "dx_dtheta") if jacobians else ():
            if key in out:
                finite &= np.isfinite(out[key]).all(axis=(1, 2))
        if not finite.all():  # the dynamics overflowed (not the LCP): flag, never pass as valid
            out["converged"] &= finite
            warnings.warn(
                f"{int((~finite).sum())} of {B} step(s) overflowed to a non-finite state or "
                f"Jacobian (largest |x| in: {float(np.abs(x[~finite]).max()):.3g}); their "
                "`converged` flags are False",
                StepOverflowWarning,
                stacklevel=2,
            )
        if self.unmodelled is not None:  # geometry no candidate covers, below the ground
            self._check_unmodelled(out["x_next"][:, :nq])
        return Step(active=active[:, :nc], theta_names=names, **out)

    def _inputs(self, x, u) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """States x (B, nq + nv) (one state (nq + nv,) becomes a batch of one) and inputs u
        (B, nu) or (nu,) shared, checked (shapes, finite), with u clipped to the actuators'
        effort limits as the step applies it; and which entries were clipped (B, nu), or None
        where none was."""
        nq, nv, nu, _ = self.sizes
        x, u, _ = batch_of_states(x, u, nq + nv, nu)
        saturated = None
        if self._clips:  # effort limits: the input applied is clipped
            saturated = np.abs(u) > self.effort
            if saturated.any():
                u = np.clip(u, -self.effort, self.effort)
            else:
                saturated = None
        return x, u, saturated

    def contact_problem(
        self, x: np.ndarray, u: np.ndarray, *, parameters: bool | Sequence[str] = True
    ) -> ContactProblem:
        """The dynamics one step's LCP is built from, at states x (B, nq + nv) and inputs
        u (B, nu) or (nu,), with every contact candidate, joint-limit and joint-friction row
        included (no pruning) and the inputs clipped to the effort limits as :meth:`step` does:
        the inverse mass matrix and free velocity of the (damped) step, the distances and rows,
        the friction cone; with ``parameters`` (True, or some names), their derivatives in
        :attr:`parameter_names` (or those names).

        This is what a loss that does not solve the step needs (the violation-implicit loss of
        :mod:`drake_abs.learning.scene_losses`): the step itself is ``contact_step`` of these
        quantities."""
        nq, nv, nu, nc = self.sizes
        x, u, _ = self._inputs(x, u)
        q, v = x[:, :nq], x[:, nq:]
        idx = np.arange(nc)
        lidx = np.arange(self.limits.size)
        fidx = np.arange(self.joint_friction.size)
        quant = self.model.quantities(
            q, v, u, idx, derivatives=False, damping=self._damping, springs=self._springs
        )
        cone = self._cone(idx, lidx.size)
        names = parameter_columns(parameters, lambda: self.parameter_names)
        par = parameter_derivatives(self.model, idx, cone, q, v, u, names) if names else None
        quant, par = self._joint_rows(quant, par, q, lidx, False, names, fidx)
        cone = self._cone(idx, lidx.size, fidx.size)
        return ContactProblem(quant, cone, float(self.model.h), par, names, nc)

    def _cone(self, idx: np.ndarray, n_limits: int = 0, n_friction: int = 0) -> FrictionCone:
        """The friction cone of the candidates ``idx`` under this stepper's formulation, with
        ``n_limits`` frictionless joint-limit rows after them, then ``n_friction`` joint-friction
        rows (pinned contacts of coefficient 1: :mod:`drake_abs.multibody.joint_friction`)."""
        cone = self.model.cone_for(idx)
        if cone.formulation == self.friction and n_limits == 0 and n_friction == 0:
            return cone
        cache = self.__dict__.setdefault("_cones", {})
        key = (np.asarray(idx, dtype=np.int64).tobytes(), n_limits, n_friction)
        if key not in cache:
            coefficients = np.concatenate(
                [cone.coefficients, np.full(n_limits, np.nan), np.ones(n_friction)]
            )
            pinned = np.arange(coefficients.size) >= coefficients.size - n_friction
            cache[key] = FrictionCone(
                coefficients, cone.directions, cone.regularization, self.friction, pinned
            )
        return cache[key]

    def _joint_rows(self, quant, par, q, lidx: np.ndarray, jacobians: bool, names=(), fidx=None):
        """One group's quantities with the joint-limit rows ``lidx`` appended to the contact
        rows (frictionless; their distances and rows do not depend on the model parameters),
        then the joint-friction rows ``fidx`` (pinned normal rows, and their tangent rows after
        the contacts'; constant), and the model-parameter derivatives (columns ``names``)
        carried to the damped step (the provider took the joint damping and springs:
        ``quantities(..., damping=..., springs=...)``), with the damping's and springs' own
        columns (:func:`~drake_abs.multibody.parameters.damping_columns`)."""
        if lidx.size:
            P = quant.dphi.shape[-1] if jacobians else None
            phi, J, dphi, dJ = self.limits.rows(q, lidx, self.sizes[1], P)
            extra = dict(
                phi=np.concatenate([quant.phi, phi], axis=1),
                Jn=np.concatenate([quant.Jn, J], axis=1),
            )
            if jacobians:
                extra.update(
                    dphi=np.concatenate([quant.dphi, dphi], axis=1),
                    dJn=np.concatenate([quant.dJn, dJ], axis=1),
                )
            quant = replace(quant, **extra)
            if par is not None:
                zeros = np.zeros((q.shape[0], lidx.size, par.dphi.shape[-1]))
                padded = dict(dphi=np.concatenate([par.dphi, zeros], axis=1))
                if par.dJn is not None:
                    rows = np.zeros((q.shape[0], lidx.size) + par.dJn.shape[2:])
                    padded["dJn"] = np.concatenate([par.dJn, rows], axis=1)
                par = replace(par, **padded)
        if fidx is not None and fidx.size:
            quant, par = self._friction_rows(quant, par, fidx, jacobians)
        if par is None:
            return quant, par
        h = self.model.h
        if self._damps:  # the provider took the damping (quantities): carry theta's to it
            D = effective_damping(self.damping, self._springs, self.sizes[1], h)
            tau_k = None if self._springs is None else self._springs.torque(q)
            par = damped_parameters(par, quant.W, quant.v_free, D, h, tau_k)
        return quant, damping_columns(
            par, quant, names, self._damping_joints, h, self.springs, self._spring_joints
        )

    def _friction_rows(self, quant, par, fidx: np.ndarray, jacobians: bool):
        """``quant`` and ``par`` with the joint-friction rows ``fidx`` appended (see
        :meth:`_joint_rows`): normal rows after the others, tangent rows after the others;
        their parameter derivatives are 0 (their cone rows' coefficient is no parameter)."""
        B, nv = quant.v.shape
        k = self.model.cone.directions
        P = quant.dphi.shape[-1] if jacobians else None
        f = self.joint_friction.rows(fidx, B, nv, k, self.model.h, P)
        extra = {
            "phi": np.concatenate([quant.phi, f["phi"]], axis=1),
            "Jn": np.concatenate([quant.Jn, f["Jn"]], axis=1),
            "Jt": np.concatenate([quant.Jt, f["Jt"]], axis=1),
        }
        if jacobians:
            for name in ("dphi", "dJn", "dJt"):
                extra[name] = np.concatenate([getattr(quant, name), f[name]], axis=1)
        quant = replace(quant, **extra)
        if par is not None:
            T, r = par.dphi.shape[-1], fidx.size
            padded = {
                "dphi": np.concatenate([par.dphi, np.zeros((B, r, T))], axis=1),
                "dfriction": np.concatenate([par.dfriction, np.zeros((r, T))], axis=0),
            }
            if par.dJn is not None:
                padded["dJn"] = np.concatenate([par.dJn, np.zeros((B, r, nv, T))], axis=1)
            if par.dJt is not None:
                padded["dJt"] = np.concatenate([par.dJt, np.zeros((B, r * k, nv, T))], axis=1)
            par = replace(par, **padded)
        return quant, par

    def _smoothing_for(self, quant, n_rows: int, fidx: np.ndarray) -> Smoothing:
        """The smoothing of a group whose last ``fidx.size`` of its ``n_rows`` normal rows are
        joint friction (:class:`~drake_abs.multibody.joint_friction.JointFrictionSmoothing`,
        with each joint's compliance ``h W_jj`` at the group's states); this stepper's own
        smoothing for a group without."""
        if not fidx.size:
            return self.smoothing
        v = self.joint_friction.v_index[fidx]
        rows = np.arange(n_rows - fidx.size, n_rows)
        return JointFrictionSmoothing(self.smoothing, rows, self.model.h * quant.W[:, v, v])

    def _solve(self, q, v, u, active, groups, jacobians: bool, parameters: tuple) -> dict:
        """The step of states (q, v, u) with the candidates ``active`` (B, nc + nl: contacts,
        then joint-limit rows) in the LCP, one batched LCP per active set (``groups``:
        precomputed, or None): the output arrays."""
        nq, nv, nu, nc = self.sizes
        B = q.shape[0]
        out = {
            "x_next": np.empty((B, nq + nv)),
            "impulse": np.zeros((B, nc)),
            "friction_impulse": np.zeros((B, nc, 3)),
            "limit_impulse": np.zeros((B, self.limits.size)),
            "joint_friction_impulse": np.zeros((B, self.joint_friction.size)),
            "mu": np.zeros((B, nc)),
            "converged": np.ones(B, dtype=bool),
            "iterations": np.zeros(B, dtype=np.int64),
        }
        if jacobians:
            out.update(
                dx_dx=np.empty((B, nq + nv, nq + nv)),
                dx_du=np.empty((B, nq + nv, nu)),
                dimpulse_dx=np.zeros((B, nc, nq + nv)),
                dimpulse_du=np.zeros((B, nc, nu)),
            )
        if parameters:  # the theta columns' names
            T = len(parameters)
            out.update(dx_dtheta=np.empty((B, nq + nv, T)), dimpulse_dtheta=np.zeros((B, nc, T)))
        if groups is None:
            groups = _groups_by_active_set(active)
        fidx = np.arange(self.joint_friction.size)  # always in the LCP
        for rows, both, quant in groups:
            idx, lidx = (
                (both[both < nc], both[both >= nc] - nc) if self.limits.size else (both, both[:0])
            )
            if quant is None:
                quant = self.model.quantities(
                    q[rows], v[rows], u[rows], idx, derivatives=jacobians, damping=self._damping,
                    springs=self._springs,
                )  # fmt: skip
            par = None
            if parameters:
                par = parameter_derivatives(
                    self.model, idx, self._cone(idx, lidx.size), q[rows], v[rows], u[rows],
                    parameters,
                )  # fmt: skip
            quant, par = self._joint_rows(quant, par, q[rows], lidx, jacobians, parameters, fidx)
            cone = self._cone(idx, lidx.size, fidx.size)
            soft = None
            if self.compliance is not None:  # the group's contacts soft, its limit rows hard
                soft = self.compliance.rows(
                    idx, lidx.size + fidx.size, cone.coefficients[: idx.size], self.friction,
                    cone.directions, self.model.h,
                )  # fmt: skip
            smoothing = self._smoothing_for(quant, cone.sizes()[0], fidx)
            r = contact_step(
                quant, cone, self.model.h, smoothing, gradient=self.gradient,
                parameters=par, compliance=soft, **self.solver_options,
            )  # fmt: skip
            if jacobians and r.dx_du.shape[-1] != nu:  # the (q, v, u) columns, checked
                raise ValueError(
                    f"the dynamics provider's derivatives have {r.dx_du.shape[-1]} input "
                    f"columns after (q, v); the model has nu = {nu}"
                )
            self._scatter(out, rows, idx, lidx, fidx, cone, r, jacobians, q[rows])
        return out

    def _repair(self, q, v, u, active, out, jacobians: bool, parameters: tuple) -> None:
        """Pruning never lets a step pass through a contact: a candidate left out of the LCP
        (beyond the activation distance) that the step would leave deeper than
        :data:`REPAIR_TOL` below the ground (a fast impact closes more than the activation
        distance within one step), or a joint-limit row it would leave violated by more than
        that (rad or m), joins the LCP, and that state's step is solved again. With no such
        row, the pruned answer with zero impulse on the left-out rows solves the full LCP:
        pruning does not change an exact step. ``active`` (B, nc + nl) and ``out`` are updated
        in place."""
        if active.all():  # nothing was left out
            return
        nq, nc = self.sizes[0], self.sizes[3]
        for repair in range(MAX_REPAIRS + 1):
            # a non-finite state's distances are NaN, which compare False
            q_next = out["x_next"][:, :nq]
            phi = self.model.distances(q_next)
            if self.limits.size:
                phi = np.concatenate([phi, self.limits.distances(q_next)], axis=1)
            missed = (phi < -REPAIR_TOL) & ~active
            if self.compliance is not None:  # a soft contact may close within a step
                missed[:, :nc] = False
            if not missed.any():
                return
            rows = np.flatnonzero(missed.any(axis=1))
            if repair == MAX_REPAIRS:  # out of repairs: flagged, never passed as valid
                out["converged"][rows] = False
                warnings.warn(
                    f"{rows.size} step(s) still pass a left-out contact or joint limit after "
                    f"{MAX_REPAIRS} repairs; their `converged` flags are False",
                    StepOverflowWarning,
                    stacklevel=3,
                )
                return
            active[rows] |= missed[rows]
            sub = self._solve(q[rows], v[rows], u[rows], active[rows], None, jacobians, parameters)
            for key, value in sub.items():
                out[key][rows] = value

    def _scatter(self, out, rows, idx, lidx, fidx, cone, r, jacobians, q) -> None:
        """Write one group's step into the batch outputs (rows: a slice or row indices; q: the
        rows' positions at the step's start). The group's normal rows are its contacts ``idx``,
        then its joint-limit rows ``lidx``, then its joint-friction rows ``fidx``; its tangent
        rows, the frictional contacts', then the joint frictions'. A friction impulse is its
        coefficients times its rows' directions: the ground's tangents, or a pair candidate's
        own (the impulse on its body A)."""
        nc_g, nt, _ = cone.sizes()
        k = idx.size  # the group's contact rows; its limit rows follow them
        nl = lidx.size
        nq = r.q_next.shape[1]
        out["x_next"][rows, :nq] = r.q_next
        out["x_next"][rows, nq:] = r.v_next
        out["converged"][rows] = r.converged
        if jacobians:  # also without contact (free flight): the Jacobian is the free step's
            out["dx_dx"][rows] = r.dx_dx
            out["dx_du"][rows] = r.dx_du
        if r.dx_dtheta is not None:
            out["dx_dtheta"][rows] = r.dx_dtheta
        if r.lcp is None:
            return
        out["iterations"][rows] = r.lcp.iterations
        # rows x contacts blocks: index the rows first (a view for a slice, a copy otherwise)
        whole = isinstance(rows, slice)
        fr = idx[cone.frictional[cone.frictional < k]]
        beta = r.lam[:, nc_g : nc_g + nt].reshape(r.lam.shape[0], -1, cone.directions)
        blocks = [
            ("impulse", idx, r.lam[:, :k]),
            ("limit_impulse", lidx, r.lam[:, k : k + nl]),
            ("mu", idx, r.mu[:, :k]),
            ("friction_impulse", fr, self._friction_vectors(beta[:, : fr.size], fr, q)),
            ("joint_friction_impulse", fidx, self.joint_friction.impulses(beta[:, fr.size :])),
        ]
        if jacobians:
            blocks += [
                ("dimpulse_dx", idx, r.dlam_dx[:, :k]),
                ("dimpulse_du", idx, r.dlam_du[:, :k]),
            ]
        if r.dlam_dtheta is not None:
            blocks.append(("dimpulse_dtheta", idx, r.dlam_dtheta[:, :k]))
        for key, cols, value in blocks:
            if whole:
                out[key][:, cols] = value
            else:
                out[key][np.ix_(rows, cols)] = value

    def _friction_vectors(self, beta: np.ndarray, fr: np.ndarray, q: np.ndarray) -> np.ndarray:
        """The friction impulses (B, n, 3) in the world of the frictional candidates ``fr``
        (n,) from their coefficients ``beta`` (B, n, k) at the step's start positions q."""
        if not getattr(self.model, "_pair_bodies_d", None):  # only ground contacts
            return beta @ self.model.tangents
        directions = self.model.tangent_directions(q, fr)  # (B, n, k, 3)
        return np.einsum("bnk,bnkd->bnd", beta, directions)


def _groups_by_active_set(active: np.ndarray) -> list[tuple]:
    """``(rows, active contact indices, None)`` per distinct row of ``active`` (B, nc): states
    with the same active set share one batched LCP (rows is a slice when all of them do)."""
    if active.shape[0] == 0:
        return []
    if (active == active[0]).all():
        return [(slice(None), np.flatnonzero(active[0]), None)]
    masks, group = np.unique(active, axis=0, return_inverse=True)
    return [
        (np.flatnonzero(group.ravel() == g), np.flatnonzero(mask), None)
        for g, mask in enumerate(masks)
    ]
