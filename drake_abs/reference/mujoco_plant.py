"""MuJoCo as a stepper: ``mj_step`` ``frame_skip`` times per step, batched over a leading axis,
returning the one step record, so that MuJoCo runs in the same engine
(:func:`drake_abs.engine.open_loop`, :func:`~drake_abs.engine.rollout`) as this package's
steppers. MuJoCo is an optional dependency (the ``mujoco`` extra: ``pip install
'drake-abs[mujoco]'``), imported when a stepper is made.

Coordinates are MuJoCo's: x = (qpos, qvel, act) (nq + nv + na,), u = ctrl (nu,) (MuJoCo's
control, e.g. gymnasium's action; the joint torque is ctrl times the actuator's gear, which
MuJoCo clamps to ``ctrlrange`` where the model says so). One step lasts ``frame_skip *
model.opt.timestep`` seconds, as one ``env.step`` of a gymnasium MuJoCo environment.

Warm start: MuJoCo's constraint solver starts from the previous step's accelerations
(``qacc_warmstart``). A row of the batch whose state is exactly the previous call's ``x_next``
of that row continues from that row's data, warm start included, so an engine rollout equals
MuJoCo stepped by hand to the last bit; any other state starts cold, as after
``mj_resetData``.

Jacobians ``dx_dx``, ``dx_du`` are MuJoCo's finite differences (``mjd_transitionFD``, centred by
default) of each ``mj_step``, chained over the frame skip. They need a model whose qpos is its
own tangent space (hinge and slide joints only: nq = nv) and an integrator other than RK4;
otherwise ``ValueError`` says which.
"""

from __future__ import annotations

import copy
import warnings
from pathlib import Path

import numpy as np

from drake_abs._validation import as_count, batch_of_states
from drake_abs.contact.step import Step

__all__ = ["INTEGRATORS", "MujocoDivergenceWarning", "MujocoStepper", "apply_options"]

#: The integrators :func:`apply_options` can set (MuJoCo's names).
INTEGRATORS = ("Euler", "RK4", "implicit", "implicitfast")
_OPTION_KEYS = ("timestep", "integrator", "cone", "contact", "springs")


def apply_options(model, options: dict | None) -> None:
    """Set ``options`` on a MuJoCo model, in place: ``timestep`` (s), ``integrator`` (one of
    :data:`INTEGRATORS`), ``cone`` (``"pyramidal"`` or ``"elliptic"``), ``contact`` (False:
    contacts disabled), ``springs`` (False: joint stiffness zeroed). ``ValueError`` names an
    unknown key or value."""
    import mujoco

    options = dict(options or {})
    unknown = set(options) - set(_OPTION_KEYS)
    if unknown:
        raise ValueError(f"options: unknown keys {sorted(unknown)}; known: {list(_OPTION_KEYS)}")
    if "timestep" in options:
        timestep = float(options["timestep"])
        if not (np.isfinite(timestep) and timestep > 0):
            raise ValueError(f"options['timestep'] must be > 0 (s); got {options['timestep']!r}")
        model.opt.timestep = timestep
    if "integrator" in options:
        name = options["integrator"]
        if name not in INTEGRATORS:
            raise ValueError(f"options['integrator'] must be one of {INTEGRATORS}; got {name!r}")
        model.opt.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{name.upper()}")
    if "cone" in options:
        if options["cone"] not in ("pyramidal", "elliptic"):
            raise ValueError(
                f"options['cone'] must be 'pyramidal' or 'elliptic'; got {options['cone']!r}"
            )
        model.opt.cone = getattr(mujoco.mjtCone, f"mjCONE_{options['cone'].upper()}")
    if options.get("contact", True) is False:
        model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    if options.get("springs", True) is False:
        model.jnt_stiffness[:] = 0.0


class MujocoDivergenceWarning(UserWarning):
    """A MuJoCo step diverged and MuJoCo reset its state; the step is flagged unconverged."""


class MujocoStepper:
    """A MuJoCo model as a :class:`~drake_abs.engine.Stepper`.

    Args:
        model: an ``mujoco.MjModel`` (copied) or the path of an MJCF/URDF file MuJoCo loads.
        frame_skip: MuJoCo steps per step (>= 1).
        options: model settings applied to the copy (:func:`apply_options`), e.g.
            ``{"integrator": "Euler", "springs": False}``.
        fd_eps, fd_centered: the finite-difference step and scheme of the Jacobians.

    ``step`` returns, besides the state: ``impulse`` (B, ngeom) the normal contact impulse (N s)
    on each geom over the step (a contact between two geoms counts for both), ``limit_impulse``
    (B, njnt) each joint's limit impulse (N s or N m s; 0 for a joint without a limit),
    ``iterations`` the solver's iterations summed over the frame skip, ``mu`` zeros (ngeom),
    ``converged`` False where MuJoCo diverged and reset the state during the step (with a
    :class:`MujocoDivergenceWarning`), True otherwise.

    Use :meth:`from_gymnasium` for the model of a gymnasium environment.
    """

    parameter_names: tuple[str, ...] = ()

    def __init__(
        self,
        model,
        *,
        frame_skip: int = 1,
        options: dict | None = None,
        fd_eps: float = 1e-6,
        fd_centered: bool = True,
    ):
        import mujoco

        if isinstance(model, str | Path):
            if not Path(model).is_file():
                raise ValueError(f"model must be an MjModel or a model file; no file {model}")
            model = mujoco.MjModel.from_xml_path(str(model))
        elif isinstance(model, mujoco.MjModel):
            model = copy.deepcopy(model)
        else:
            raise TypeError(
                f"model must be a mujoco.MjModel or a model file's path; got {type(model).__name__}"
            )
        apply_options(model, options)
        self.model = model
        self.frame_skip = as_count(frame_skip, "frame_skip", minimum=1)
        if not (np.isfinite(fd_eps) and fd_eps > 0):
            raise ValueError(f"fd_eps must be a finite number > 0; got {fd_eps!r}")
        self.fd_eps, self.fd_centered = float(fd_eps), bool(fd_centered)
        self.nq, self.nv, self.na, self.nu = model.nq, model.nv, model.na, model.nu
        self._rows: list = []  # one MjData per batch row, kept for the warm start
        self._last: np.ndarray | None = None  # the previous call's x_next

    @classmethod
    def from_gymnasium(
        cls,
        env_id: str,
        *,
        frame_skip: int | None = None,
        options: dict | None = None,
        **make_kwargs,
    ) -> MujocoStepper:
        """The MuJoCo model of gymnasium's ``env_id`` (e.g. ``"Hopper-v5"``; ``make_kwargs`` go
        to ``gymnasium.make``) with the environment's ``frame_skip`` unless one is given, so
        that one step is one ``env.step`` (the state is MuJoCo's, not the observation)."""
        import gymnasium

        env = gymnasium.make(env_id, disable_env_checker=True, **make_kwargs)
        try:
            raw = env.unwrapped
            skip = int(raw.frame_skip) if frame_skip is None else frame_skip
            return cls(raw.model, frame_skip=skip, options=options)
        finally:
            env.close()

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_rows"], state["_last"] = [], None  # MjData is rebuilt, cold
        return state

    @property
    def nx(self) -> int:
        """The state's size nq + nv + na."""
        return self.nq + self.nv + self.na

    @property
    def time_step(self) -> float:
        """The seconds one step lasts, ``frame_skip * model.opt.timestep``."""
        return self.frame_skip * float(self.model.opt.timestep)

    def state(self, data) -> np.ndarray:
        """x = (qpos, qvel, act) of an ``MjData`` (nx,)."""
        return np.concatenate([data.qpos, data.qvel, data.act])

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False) -> Step:
        """``frame_skip`` MuJoCo steps from each state of a batch.

        Args:
            x: (B, nx) states (qpos, qvel, act) or one state (nx,).
            u: (B, nu) ctrl or (nu,) shared by the batch.
            jacobians: also ``dx_dx`` (B, nx, nx), ``dx_du`` (B, nx, nu) (see the module).
            parameters: must be False (no model parameters to differentiate).
        """
        import mujoco

        if parameters:
            raise ValueError("parameters=True: MujocoStepper names no model parameters")
        x, u, batched = batch_of_states(x, u, self.nx, self.nu)
        if jacobians:
            self._check_differentiable()
        B, nx, m = x.shape[0], self.nx, self.model
        rows = self._data_rows(x)
        x_next = np.empty_like(x)
        impulse = np.zeros((B, m.ngeom))
        limit = np.zeros((B, m.njnt))
        iterations = np.zeros(B, int)
        converged = np.ones(B, bool)
        dx = np.empty((B, nx, nx)) if jacobians else None
        du = np.empty((B, nx, self.nu)) if jacobians else None
        A = np.empty((2 * self.nv + self.na,) * 2)
        Bm = np.empty((2 * self.nv + self.na, self.nu))
        for b, data in enumerate(rows):
            data.ctrl[:] = u[b]
            if jacobians:
                dx[b], du[b] = np.eye(nx), 0.0
            resets = self._resets(data)
            for _ in range(self.frame_skip):
                if jacobians:
                    mujoco.mjd_transitionFD(m, data, self.fd_eps, self.fd_centered, A, Bm,
                                            None, None)  # fmt: skip
                    dx[b], du[b] = A @ dx[b], A @ du[b] + Bm
                mujoco.mj_step(m, data)
                # the step's constraint forces (from its forward pass at the substep's start)
                impulse[b] += self._contact_impulses(data)
                limit[b] += self._limit_impulses(data)
                iterations[b] += int(data.solver_niter[0])
            x_next[b] = self.state(data)
            # MuJoCo resets a state whose position, velocity or acceleration left the finite
            # range (|value| > 1e10 or NaN) and says so only by a warning count: such a step is
            # not the model's, and is flagged
            converged[b] = self._resets(data) == resets
        self._last = x_next.copy()
        if not converged.all():
            warnings.warn(
                f"MujocoStepper: {int((~converged).sum())} of {B} states diverged (MuJoCo reset "
                "them: a position, velocity or acceleration beyond 1e10 or not finite); their "
                "steps are flagged converged = False",
                MujocoDivergenceWarning,
                stacklevel=2,
            )
        step = Step(
            x_next=x_next, converged=converged, iterations=iterations, impulse=impulse,
            mu=np.zeros((B, m.ngeom)), dx_dx=dx, dx_du=du, limit_impulse=limit,
        )  # fmt: skip
        return step if batched else step.first()

    def _data_rows(self, x: np.ndarray) -> list:
        """One MjData per row at state x[b]: the previous call's data of that row where x[b] is
        its x_next (warm start kept), a reset one otherwise."""
        import mujoco

        B, m = x.shape[0], self.model
        while len(self._rows) < B:
            self._rows.append(mujoco.MjData(m))
        last = self._last if self._last is not None and self._last.shape[0] >= B else None
        rows = self._rows[:B]
        for b, data in enumerate(rows):
            if last is not None and np.array_equal(x[b], last[b]):
                continue
            mujoco.mj_resetData(m, data)
            data.qpos[:] = x[b, : self.nq]
            data.qvel[:] = x[b, self.nq : self.nq + self.nv]
            data.act[:] = x[b, self.nq + self.nv :]
        return rows

    @staticmethod
    def _resets(data) -> int:
        """How often MuJoCo has reset ``data`` for a bad position, velocity or acceleration."""
        import mujoco

        bad = (mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
               mujoco.mjtWarning.mjWARN_BADQACC)  # fmt: skip
        return sum(int(data.warning[int(w)].number) for w in bad)

    def _contact_impulses(self, data) -> np.ndarray:
        """(ngeom,) normal impulse (N s) on each geom over the MuJoCo step just taken: each
        contact's normal force as ``mj_contactForce`` decodes it (a pyramidal cone's normal
        force is the sum of its edge forces; an elliptic cone's is its first row), times the
        timestep."""
        import mujoco

        out = np.zeros(self.model.ngeom)
        n = data.ncon
        if n == 0:
            return out
        contact = data.contact
        adr, dim = np.asarray(contact.efc_address), np.asarray(contact.dim)
        force = np.asarray(data.efc_force)
        pyramidal = self.model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL
        rows = np.where(pyramidal & (dim > 1), 2 * (dim - 1), 1)
        normal = np.array(
            [force[a : a + r].sum() if a >= 0 else 0.0 for a, r in zip(adr, rows, strict=True)]
        )
        geoms = np.asarray(contact.geom)
        np.add.at(out, geoms[:, 0], normal * self.model.opt.timestep)
        np.add.at(out, geoms[:, 1], normal * self.model.opt.timestep)
        return out

    def _limit_impulses(self, data) -> np.ndarray:
        """(njnt,) each joint's limit impulse magnitude over the MuJoCo step just taken."""
        import mujoco

        limits = np.asarray(data.efc_type) == mujoco.mjtConstraint.mjCNSTR_LIMIT_JOINT
        if not limits.any():
            return np.zeros(self.model.njnt)
        force = np.abs(np.asarray(data.efc_force)[limits]) * self.model.opt.timestep
        return np.bincount(np.asarray(data.efc_id)[limits], force, minlength=self.model.njnt)

    def _check_differentiable(self) -> None:
        import mujoco

        m = self.model
        if m.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4:
            raise ValueError(
                "jacobians: MuJoCo's finite differences (mjd_transitionFD) do not support the RK4 "
                "integrator this model uses; make the stepper with options={'integrator': "
                "'Euler'} (or 'implicit', 'implicitfast')"
            )
        one_dof = {int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE)}
        other = [
            mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint {j}"
            for j in range(m.njnt)
            if int(m.jnt_type[j]) not in one_dof
        ]
        if other:
            raise ValueError(
                "jacobians: MuJoCo's finite differences are in the tangent space, which is qpos "
                f"only for hinge and slide joints; this model also has free or ball joints {other}"
            )
