"""ARS V2-t as the community runs it on gymnasium's locomotion tasks: the authors' setting
(Mania, Guy and Recht 2018; their code, github.com/modestyachts/ARS: ``code/ars.py``,
``code/policies.py``, ``code/filter.py``) on any environment our engine rolls out, e.g. a
:class:`drake_abs.tasks.locomotion.LocomotionTask` on our plant.

The policy acts on the environment's observation o = obs(x), normalised by running statistics
of the observations seen in training: ``u = K (o - mean) / std`` (a
:class:`~drake_abs.policy.ars_v2.NormalizedLinearPolicy` of the observation, no bias, K (nu,
n_obs) starting at 0; ``env.policy(inner)`` makes it a policy of the full state).

One iteration j:

1. draw N directions delta_k (P,) with standard-normal entries, then the initial states from the
   environment's reset noise (``env.initial_states``): one per direction, the + and - rollouts of
   a direction starting from the same state (``paired_starts``; ``False`` draws one per rollout);
2. with the normaliser (mean_j, std_j) frozen, run the 2N policies ``theta_j +- nu delta_k``
   (:func:`~drake_abs.policy.ars_v2.perturbations`) for one deterministic episode each: from its
   initial state until the reward says ``terminated`` or ``episode_length`` steps have run;
3. each rollout's training return is ``sum_t (r_t - shift)`` over its L counted steps, r_t the
   environment's reward and ``shift`` the survival shift (the authors subtract the alive bonus,
   1 per step, for Hopper, Walker2d and Ant, nothing for HalfCheetah:
   :data:`~drake_abs.policy.ars_v2.SURVIVAL_SHIFT`); the shift is for training only, and the
   returns logged are the environment's own;
4. update theta by the ARS V2-t step (:func:`~drake_abs.policy.ars_v2.ars_update`): of the
   directions with the b = ``top`` largest ``max(r_k+, r_k-)``,
   ``theta_{j+1} = theta_j + alpha / (b sigma_R) sum_top (r_k+ - r_k-) delta_k``;
5. push into the normaliser every observation at which a training policy acted this iteration,
   o(x_0) .. o(x_{L-1}) of each episode (the authors' filter, updated after the iteration).

**Environment steps** are the steps that counted: an episode of L steps counts L (the step that
ended it included; a reset counts nothing), the authors' ``timesteps``. The rollouts run in the
one engine (:func:`drake_abs.engine.rollout`, no gradient), in chunks of ``chunk`` steps over
the episodes still running (an ended episode leaves the batch between chunks; within a chunk the
engine holds it, counting nothing).

**Unconverged steps** (``on_unconverged``, :mod:`drake_abs.contact.unconverged`): ``"drop"``
(default) leaves a direction out of the update when either of its episodes took an unconverged
contact solve (its episode stops there; its observations stay out of the normaliser; the steps
it ran count as spent), and an iteration with fewer than b usable directions raises
:class:`~drake_abs.contact.unconverged.UnconvergedStepError` (the state is left as it was but for
the random generator); ``"flag"`` keeps every episode; ``"raise"`` raises at once. Each row logs
the directions dropped and the unconverged steps.

**Checkpoints and chunks**: :class:`ArsTrainer` has the shape of
:class:`drake_abs.policy.shac.ShacTrainer`: :meth:`ArsTrainer.iterate` runs one iteration and
returns its log row, :meth:`ArsTrainer.train` runs to a total number of iterations (or a wall-time
or environment-step budget) with periodic checkpoints, and :meth:`ArsTrainer.save` /
:meth:`ArsTrainer.load` write and continue the whole state (parameters, normaliser, counters,
log and the random generator): a run in chunks gives the numbers of an uninterrupted one, bit for
bit (the wall seconds aside).

Where this differs from the authors' code:

- the + and - episodes of a direction start from the same reset state (theirs call
  ``env.reset()`` before each rollout; ``paired_starts=False`` does that);
- one process and one seeded generator (directions, resets) instead of Ray workers with a shared
  noise table;
- the normaliser's std is the population std (ddof 0,
  :class:`~drake_abs.policy.observation_normalizer.RunningMeanStd`) where theirs is the
  sample std, and z = (o - mean) / std where theirs divides by std + 1e-8; an entry whose std
  is below 1e-7 gets weight 0 in both;
- the top b are exactly b (theirs keeps ties at the percentile);
- no evaluation inside the loop (theirs rolls out the unperturbed policy on 100 episodes every
  10 iterations, not counted): the returns logged are those of the iteration's perturbed
  rollouts, and a final policy is scored as a policy file, in MuJoCo's own environment
  (:func:`drake_abs.reference.gym_scoring.score_policy`) or on our plant
  (:func:`drake_abs.tasks.published_policies.score_on_plant`).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from drake_abs._validation import as_count, as_finite_array
from drake_abs.contact.unconverged import OnUnconverged, check_on_unconverged
from drake_abs.engine import rollout
from drake_abs.engine.protocols import Policy, TransitionReward, check_reward
from drake_abs.policy.ars_v2 import (
    PUBLISHED_SETTINGS,
    SURVIVAL_SHIFT,
    NormalizedLinearPolicy,
    ParameterBlocks,
    ars_update,
    perturbations,
)
from drake_abs.policy.checkpoints import read_checkpoint, train_resumable, write_checkpoint
from drake_abs.policy.observation_normalizer import RunningMeanStd
from drake_abs.policy.shac import TrainingEnvironment

__all__ = [
    "CHECKPOINT_FORMAT",
    "ArsConfig",
    "ArsState",
    "ArsTrainer",
    "Episodes",
    "published_key",
    "run_episodes",
]

#: The ``format`` entry of a checkpoint file.
CHECKPOINT_FORMAT = "drake-abs ars checkpoint"
_CHECKPOINT_VERSION = 1


def published_key(env_id: str) -> str:
    """The row of :data:`~drake_abs.policy.ars_v2.PUBLISHED_SETTINGS` for a gymnasium id: the
    paper's v1 task of the same body (``"Hopper-v5"`` -> ``"Hopper-v1"``); ``ValueError`` listing
    the bodies that have one."""
    if not isinstance(env_id, str) or "-v" not in env_id:
        raise ValueError(f"env_id must be a gymnasium id such as 'Hopper-v5'; got {env_id!r}")
    key = env_id.rsplit("-v", 1)[0] + "-v1"
    if key not in PUBLISHED_SETTINGS:
        known = sorted(k.rsplit("-v", 1)[0] for k in PUBLISHED_SETTINGS)
        raise ValueError(
            f"env_id {env_id!r} has no published ARS settings; bodies that do: {known}"
        )
    return key


@dataclass(frozen=True)
class ArsConfig:
    """ARS's settings (the defaults are the Hopper's published ones; :meth:`published` gives any
    task's).

    Attributes:
        directions: N, directions per iteration (2N episodes).
        top: b in [1, N], the directions used in the update.
        step_size: alpha.
        noise: nu, the std of the parameter perturbations (units of the normalised policy's
            entries).
        shift: the survival shift subtracted from every counted step's reward in training
            (reward units; 0: none).
        episode_length: the most steps of an episode (gymnasium's 1000).
        paired_starts: the + and - episodes of a direction start from the same reset state.
        chunk: engine steps per call (ended episodes leave the batch between calls).
        on_unconverged: ``"drop"``, ``"flag"`` or ``"raise"`` (module docstring).
    """

    directions: int = 8
    top: int = 4
    step_size: float = 0.01
    noise: float = 0.025
    shift: float = 1.0
    episode_length: int = 1000
    paired_starts: bool = True
    chunk: int = 25
    on_unconverged: OnUnconverged = "drop"

    def __post_init__(self):
        as_count(self.directions, "directions", minimum=1)
        as_count(self.top, "top", minimum=1)
        if self.top > self.directions:
            raise ValueError(f"top must be in [1, directions = {self.directions}]; got {self.top}")
        for name in ("step_size", "noise"):
            v = getattr(self, name)
            if isinstance(v, bool) or not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a finite number > 0; got {v!r}")
        if isinstance(self.shift, bool) or not np.isfinite(self.shift):
            raise ValueError(f"shift must be a finite number (reward per step); got {self.shift!r}")
        as_count(self.episode_length, "episode_length", minimum=1)
        as_count(self.chunk, "chunk", minimum=1)
        if not isinstance(self.paired_starts, bool):
            raise ValueError(f"paired_starts must be True or False; got {self.paired_starts!r}")
        check_on_unconverged(self.on_unconverged)

    @classmethod
    def published(cls, env_id: str, **overrides) -> ArsConfig:
        """The published settings (:data:`~drake_abs.policy.ars_v2.PUBLISHED_SETTINGS`) and
        survival shift (:data:`~drake_abs.policy.ars_v2.SURVIVAL_SHIFT`) of the task of the same
        body as ``env_id`` (:func:`published_key`); ``overrides`` replace any setting."""
        key = published_key(env_id)
        return cls(**(dict(PUBLISHED_SETTINGS[key]) | {"shift": SURVIVAL_SHIFT[key]} | overrides))


@dataclass(frozen=True)
class Episodes:
    """M deterministic episodes (:func:`run_episodes`).

    Attributes:
        returns: (M,) the sum of the environment's reward over each episode's counted steps (NaN
            for an episode left out, ``used`` False).
        lengths: (M,) counted steps (the step that ended the episode included).
        terminated: (M,) the episode ended at a terminal state (else it ran ``episode_length``
            steps, or was left out).
        used: (M,) the episode may be used (no unconverged step, or ``"flag"``).
        unconverged: counted steps whose contact solve did not converge.
        observations: (n, n_obs) the observations at which the policy acted in the used episodes,
            episode after episode, in time order.
    """

    returns: np.ndarray
    lengths: np.ndarray
    terminated: np.ndarray
    used: np.ndarray
    unconverged: int
    observations: np.ndarray


def run_episodes(
    env: TrainingEnvironment,
    inner: NormalizedLinearPolicy,
    thetas,
    x0,
    *,
    episode_length: int,
    chunk: int = 25,
    on_unconverged: OnUnconverged = "drop",
) -> Episodes:
    """One deterministic episode of ``env.policy(inner)`` per row: episode m acts with
    parameters ``thetas[m]`` from state ``x0[m]`` until the reward's ``terminated`` or
    ``episode_length`` steps, all in one batch of engine rollouts of ``chunk`` steps (module
    docstring).

    Args:
        env: the environment (``stepper``, ``reward``, ``observation``, ``policy(inner)``).
        inner: the policy of the observation (its normaliser frozen).
        thetas: (M, P) parameters, one row per episode.
        x0: (M, nx) initial states.
        episode_length: the most steps of an episode.
        chunk: steps per engine call.
        on_unconverged: ``"drop"``, ``"flag"`` or ``"raise"``.
    """
    if not isinstance(inner, NormalizedLinearPolicy):
        raise ValueError(f"inner must be a NormalizedLinearPolicy; got {type(inner).__name__}")
    check_reward(env.reward, "env.reward")
    check_on_unconverged(on_unconverged)
    thetas = as_finite_array(thetas, "thetas", ndim=(2,))
    x0 = as_finite_array(x0, "x0", ndim=(2,))
    M = thetas.shape[0]
    if thetas.shape[1] != inner.n_params:
        raise ValueError(
            f"thetas must have shape (M, P) with P = {inner.n_params}; got {thetas.shape}"
        )
    if x0.shape[0] != M:
        raise ValueError(f"x0 must have shape (M, nx) with M = {M} (thetas'); got {x0.shape}")
    length = as_count(episode_length, "episode_length", minimum=1)
    chunk = as_count(chunk, "chunk", minimum=1)
    ends = isinstance(env.reward, TransitionReward) and hasattr(env.reward, "terminated")

    x = x0.copy()
    returns, lengths = np.zeros(M), np.zeros(M, dtype=np.int64)
    terminated, used = np.zeros(M, dtype=bool), np.ones(M, dtype=bool)
    unconverged = 0
    seen: list[tuple[np.ndarray, np.ndarray]] = []  # (episode of each row, its states)
    live, flat, t = np.arange(M), thetas.reshape(-1), 0
    while live.size and t < length:
        h = min(chunk, length - t)
        policy = env.policy(ParameterBlocks(inner, M, owner=live))
        traj = rollout(env.stepper, policy, flat, x[live], np.zeros((live.size, h, env.nu)),
                       env.reward, sigma=0.0, gradient=False,
                       on_unconverged=on_unconverged)  # fmt: skip
        alive = traj.alive
        steps = alive.sum(axis=1)
        unconverged += int((~traj.converged & alive).sum())
        owner = np.broadcast_to(live[:, None], alive.shape)
        seen.append((owner[alive], traj.x[:, :-1][alive]))
        x[live] = traj.x[:, -1]
        lengths[live] += steps
        returns[live] += traj.returns  # NaN where dropped
        # an episode that ended is held at its terminal state
        term = np.asarray(env.reward.terminated(traj.x[:, -1]), dtype=bool) if ends \
            else np.zeros(live.size, dtype=bool)  # fmt: skip
        terminated[live] = term
        used[live] = traj.used
        live = live[~term & traj.used]
        t += h
    rows = np.concatenate([r for r, _ in seen]) if seen else np.zeros(0, dtype=np.int64)
    states = np.concatenate([s for _, s in seen]) if seen else np.zeros((0, x.shape[1]))
    order = np.argsort(rows, kind="stable")  # episode after episode, in time order
    keep = used[rows[order]]
    obs = env.observation(states[order][keep]) if keep.any() else np.zeros((0, env.n_obs))
    return Episodes(
        returns=np.where(used, returns, np.nan), lengths=lengths, terminated=terminated & used,
        used=used, unconverged=unconverged, observations=obs,
    )  # fmt: skip


@dataclass
class ArsState:
    """Everything a training run carries from one iteration to the next (a checkpoint).

    Attributes:
        iteration: iterations done.
        theta: (P,) the policy's parameters (K row-major, of the normalised observation).
        normalizer: the observations' running statistics.
        env_steps: environment steps so far (module docstring).
        episodes: training episodes run so far.
        seconds: wall seconds of training so far.
        rng: the one random generator (directions, reset states).
        rows: the log, one dict per iteration.
    """

    iteration: int
    theta: np.ndarray
    normalizer: RunningMeanStd
    env_steps: int
    episodes: int
    seconds: float
    rng: np.random.Generator
    rows: list = field(default_factory=list)


class ArsTrainer:
    """ARS V2-t on an environment, as the authors run it (module docstring).

    Args:
        env: the :class:`~drake_abs.policy.shac.TrainingEnvironment` (e.g. a locomotion task).
        config: the settings (:meth:`ArsConfig.published` for a task's published ones).
        seed: seeds the one generator (directions, reset states).
        theta0: (P,) initial parameters, P = nu n_obs (default 0, as the paper).
    """

    def __init__(self, env: TrainingEnvironment, config: ArsConfig, seed: int, *, theta0=None):
        if not isinstance(env, TrainingEnvironment):
            raise TypeError(
                "env must have stepper, reward, observation, n_obs, nu, initial_states(rng, M) "
                f"and policy(inner); got {type(env).__name__}"
            )
        if not isinstance(config, ArsConfig):
            raise TypeError(f"config must be an ArsConfig; got {type(config).__name__}")
        check_reward(env.reward, "env.reward")
        self.env, self.config = env, config
        self.seed = as_count(seed, "seed", minimum=0)
        P = NormalizedLinearPolicy(env.n_obs, env.nu).n_params
        theta = np.zeros(P) if theta0 is None else as_finite_array(theta0, "theta0", ndim=(1,))
        if theta.shape != (P,):
            raise ValueError(f"theta0 must have shape (P,) = ({P},) (nu n_obs); got {theta.shape}")
        self.state = ArsState(
            iteration=0, theta=theta.copy(), normalizer=RunningMeanStd(env.n_obs), env_steps=0,
            episodes=0, seconds=0.0, rng=np.random.default_rng(self.seed),
        )  # fmt: skip

    # -- the policy at the current statistics -----------------------------------------------

    def inner_policy(self) -> NormalizedLinearPolicy:
        """The policy of the observation, ``u = K (o - mean) / std``, at the current statistics
        (use it with ``state.theta``)."""
        stats = self.state.normalizer
        return NormalizedLinearPolicy(self.env.n_obs, self.env.nu, stats.mean, stats.std)

    def full_state_policy(self) -> Policy:
        """``env.policy(inner_policy())``: the policy of the full state (for
        :func:`drake_abs.tasks.published_policies.task_policy_file`, with ``state.theta``)."""
        return self.env.policy(self.inner_policy())

    # -- one iteration ----------------------------------------------------------------------

    def iterate(self) -> dict:
        """One iteration (module docstring); returns its log row (also appended to
        ``state.rows``): ``iteration`` (done so far), ``env_steps`` and ``seconds`` (so far),
        ``return_mean`` / ``return_max`` / ``return_min`` (the environment's return of the
        iteration's used episodes), ``objective_mean`` (their training return, shifted),
        ``length_mean``, ``terminated`` (episodes that ended at a terminal state),
        ``iteration_env_steps``, ``episodes``, ``dropped`` (directions left out),
        ``unconverged_steps``, ``sigma_R``, ``step_norm``."""
        s, c, env = self.state, self.config, self.env
        start = time.perf_counter()
        N = c.directions
        delta = s.rng.standard_normal((N, s.theta.size))
        if c.paired_starts:
            x0 = np.repeat(env.initial_states(s.rng, N), 2, axis=0)
        else:
            x0 = env.initial_states(s.rng, 2 * N)
        ep = run_episodes(
            env, self.inner_policy(), perturbations(s.theta, delta, c.noise), x0,
            episode_length=c.episode_length, chunk=c.chunk, on_unconverged=c.on_unconverged,
        )  # fmt: skip
        objective = ep.returns - c.shift * ep.lengths
        usable = ep.used.reshape(N, 2).all(axis=1)
        update = ars_update(s.theta, delta, objective.reshape(N, 2), usable, c.top, c.step_size)

        s.theta = update.theta
        s.normalizer.push(ep.observations)
        steps = int(ep.lengths.sum())
        s.env_steps += steps
        s.episodes += 2 * N
        s.iteration += 1
        s.seconds += time.perf_counter() - start
        R = ep.returns[ep.used]
        row = {
            "iteration": s.iteration,
            "env_steps": s.env_steps,
            "seconds": s.seconds,
            "return_mean": float(R.mean()),
            "return_max": float(R.max()),
            "return_min": float(R.min()),
            "objective_mean": float(objective[ep.used].mean()),
            "length_mean": float(ep.lengths[ep.used].mean()),
            "terminated": int(ep.terminated.sum()),
            "iteration_env_steps": steps,
            "episodes": s.episodes,
            "dropped": int(N - usable.sum()),
            "unconverged_steps": ep.unconverged,
            "sigma_R": update.sigma_R,
            "step_norm": float(np.linalg.norm(update.step)),
        }
        s.rows.append(row)
        return row

    def train(
        self,
        iterations: int,
        *,
        checkpoint: str | Path | None = None,
        checkpoint_every: int = 10,
        max_seconds: float | None = None,
        max_env_steps: int | None = None,
        callback=None,
    ) -> list[dict]:
        """Iterate until ``state.iteration == iterations`` (a resumed run continues to the same
        total), or ``max_seconds`` of wall time in this call have passed, or ``state.env_steps``
        has reached ``max_env_steps`` (each checked after a whole iteration); save a checkpoint
        every ``checkpoint_every`` iterations and at the end (with ``checkpoint``).
        ``callback(row)`` after each iteration. Returns the whole log
        (:func:`~drake_abs.policy.checkpoints.train_resumable`)."""
        return train_resumable(
            self, iterations, checkpoint=checkpoint, checkpoint_every=checkpoint_every,
            max_seconds=max_seconds, max_env_steps=max_env_steps, callback=callback,
        )  # fmt: skip

    # -- checkpoints ------------------------------------------------------------------------

    def save(self, path: str | Path) -> Path:
        """Write the whole training state to ``path`` (:mod:`drake_abs.policy.checkpoints`)."""
        payload = {"config": asdict(self.config), "seed": self.seed, "state": self.state}
        return write_checkpoint(path, payload, kind=CHECKPOINT_FORMAT,
                                version=_CHECKPOINT_VERSION)  # fmt: skip

    @classmethod
    def load(cls, path: str | Path, env: TrainingEnvironment) -> ArsTrainer:
        """A trainer continuing from the checkpoint at ``path`` in ``env`` (the environment the
        run was started in: it is not stored)."""
        payload = read_checkpoint(path, kind=CHECKPOINT_FORMAT, version=_CHECKPOINT_VERSION)
        trainer = cls(env, ArsConfig(**payload["config"]), payload["seed"])
        state = payload["state"]
        if state.theta.shape != trainer.state.theta.shape or state.normalizer.nx != env.n_obs:
            raise ValueError("the checkpoint does not fit env: its policy has other sizes")
        trainer.state = state
        return trainer
