"""ARS V2-t, Augmented Random Search on state-normalised linear policies, as a training loop
(Mania, Guy and Recht 2018, "Simple random search provides a competitive approach to
reinforcement learning", Algorithm 2, versions V2 and V2-t).

One iteration j (Algorithm 2, lines 4-8):

1. draw N directions delta_k (P,) with standard-normal entries;
2. roll out the 2N policies ``theta_j +- nu delta_k`` (each on ``rollouts_per_direction`` rollouts
   of the objective, the + and - policy of a direction on the same exploration noise), all with
   the normaliser (mu_j, Sigma_j) frozen;
3. keep the b = ``top`` directions with the largest ``max(r_k+, r_k-)`` ("-t");
4. step ``theta_{j+1} = theta_j + alpha / (b sigma_R) sum_top (r_k+ - r_k-) delta_k``, with
   sigma_R the standard deviation of the 2b returns used (not divided by nu, as in the paper);
5. ("V2") set mu_{j+1}, Sigma_{j+1} to the mean and (diagonal) covariance of every state the
   training rollouts have visited since the start (the states at which the policy acted,
   x_0 .. x_{H-1}; evaluation rollouts do not count, as in the authors' code).

The policy is :class:`NormalizedLinearPolicy`, ``u = K diag(Sigma)^{-1/2} (x - mu)`` (no bias
by default, as in the paper), with mu and Sigma held as attributes.

The update (steps 3-4) is :func:`ars_update` and the perturbations :func:`perturbations`, shared
with :class:`drake_abs.policy.ars_trainer.ArsTrainer`, which runs ARS as the authors' code runs it
on gymnasium's tasks (the policy of the observation, every rollout an episode from the reset
noise ended at termination, the survival shift). :func:`ars_v2_train` is the setting of the
papers' figures: a :class:`~drake_abs.policy.estimators.PolicyObjective` (one initial state,
a fixed horizon).

Batched: by default the 2N perturbed policies (and the unperturbed one, when evaluated) run as
one engine rollout: a policy wrapper gives each block of rollouts its own parameters
(``batch_directions=False`` runs one ``obj.rollout`` per policy instead, with the same numbers).

Differences from the paper and the authors' code (github.com/modestyachts/ARS):

- the return is the objective's (its stage and terminal rewards over the fixed horizon H); the
  MuJoCo tasks' early termination and the survival-bonus "shift" are not modelled, so the env
  steps logged are those that counted (``H`` per rollout unless an episode ended);
- exploration noise ``obj.sigma`` on the actions is kept if the objective has it (the paper's
  rollouts use deterministic policies; set ``sigma=0`` for that);
- the state std is the population std (ddof 0) of the states visited; coordinates whose std is
  below ``min_std`` get weight 0, as in the authors' filter (which sets such a std to infinity);
- the top b are exactly b (the authors' code keeps ties at the percentile).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.contact.unconverged import UnconvergedStepError
from drake_abs.policy.estimators import PolicyObjective
from drake_abs.policy.observation_normalizer import RunningMeanStd

__all__ = [
    "PUBLISHED_SETTINGS",
    "SURVIVAL_SHIFT",
    "ArsRun",
    "ArsUpdate",
    "NormalizedLinearPolicy",
    "ParameterBlocks",
    "RunningMeanStd",
    "ars_update",
    "ars_v2_train",
    "perturbations",
]

#: ARS V2-t hyperparameters for the MuJoCo locomotion tasks, as in the appendix table of Mania
#: et al. 2018 that goes with their Table 1 (Table 9 of arXiv:1803.07055). Keys are
#: :func:`ars_v2_train`'s arguments: step size alpha (``step_size``), directions N
#: (``directions``), top b (``top``) and exploration noise nu (``noise``, units of the normalised
#: policy's entries). The paper's table itself was not read here; every row equals the RL
#: Baselines3 Zoo's ``hyperparams/ars.yml`` rows for the same body, which the zoo marks as the
#: settings closest to the original paper (``Hopper-v3``, ``HalfCheetah-v3``, ``Walker2d-v3``,
#: ``Ant-v3``: learning_rate, n_delta, n_top, delta_std). Further checks:
#:
#: - Hopper: also agrees with a third-party script running the authors' code (step 0.01,
#:   8 directions, 4 used, delta_std 0.025).
#: - HalfCheetah: step size 0.02 and noise 0.03 agree with the HalfCheetah example in the README
#:   of the authors' code (github.com/modestyachts/ARS; it runs 8 directions, all used).
#:
#: The survival shift of each task is :data:`SURVIVAL_SHIFT`.
PUBLISHED_SETTINGS: dict[str, dict[str, float | int]] = {
    "Hopper-v1": {"step_size": 0.01, "directions": 8, "top": 4, "noise": 0.025},
    "HalfCheetah-v1": {"step_size": 0.02, "directions": 32, "top": 4, "noise": 0.03},
    "Walker2d-v1": {"step_size": 0.03, "directions": 40, "top": 30, "noise": 0.025},
    "Ant-v1": {"step_size": 0.015, "directions": 60, "top": 20, "noise": 0.025},
}

#: The survival "shift" the authors' code subtracts from every training step's reward (not from
#: evaluation), per task: 1 (the alive bonus) for Hopper, Walker2d and Ant, 0 for HalfCheetah
#: (the comment on ``--shift`` in ``code/ars.py`` of github.com/modestyachts/ARS; the RL
#: Baselines3 Zoo's ``alive_bonus_offset`` is the same, with the opposite sign).
SURVIVAL_SHIFT: dict[str, float] = {
    "Hopper-v1": 1.0,
    "HalfCheetah-v1": 0.0,
    "Walker2d-v1": 1.0,
    "Ant-v1": 1.0,
}


def _check_vector(value, name: str, n: int) -> np.ndarray:
    arr = as_finite_array(value, name, ndim=(1,))
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape (nx,) = ({n},); got {arr.shape}")
    return arr


@dataclass(frozen=True, eq=False)
class NormalizedLinearPolicy:
    """``u = K z + k`` on the normalised state ``z = (x - mean) / std`` (ARS V2).

    theta = K row-major (nu nx), then k (nu) when ``bias``. ``mean`` and ``std`` (nx,) are the
    normaliser (units of x), frozen in the policy (:meth:`with_stats` makes the next one);
    coordinates with ``std < min_std`` get weight 0 (z = 0), as in the ARS authors' filter.

    Args:
        nx, nu: state and input sizes.
        mean: (nx,) state mean (default 0).
        std: (nx,) state standard deviation, >= 0 (default 1).
        bias: add the offset k (the paper's policies have none).
        min_std: a std below this drops its coordinate.
    """

    nx: int
    nu: int
    mean: np.ndarray | None = None
    std: np.ndarray | None = None
    bias: bool = False
    min_std: float = 1e-7

    def __post_init__(self):
        if self.nx < 1 or self.nu < 1:
            raise ValueError(f"nx and nu must be >= 1; got {self.nx}, {self.nu}")
        mean = np.zeros(self.nx) if self.mean is None else self.mean
        std = np.ones(self.nx) if self.std is None else self.std
        mean, std = _check_vector(mean, "mean", self.nx), _check_vector(std, "std", self.nx)
        if np.any(std < 0):
            raise ValueError("std must be >= 0 in every coordinate")
        if not (np.isfinite(self.min_std) and self.min_std > 0):
            raise ValueError(f"min_std must be a finite number > 0; got {self.min_std!r}")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "std", std)

    @property
    def n_params(self) -> int:
        return self.nu * self.nx + (self.nu if self.bias else 0)

    @property
    def scale(self) -> np.ndarray:
        """(nx,) ``1 / std``, 0 where ``std < min_std``."""
        keep = self.std >= self.min_std
        return np.where(keep, 1.0 / np.where(keep, self.std, 1.0), 0.0)

    def with_stats(self, mean, std) -> NormalizedLinearPolicy:
        """The same policy with normaliser (mean, std)."""
        return dataclasses.replace(self, mean=mean, std=std)

    def normalize(self, x) -> np.ndarray:
        """z = (x - mean) / std (M, nx)."""
        return (np.asarray(x, float) - self.mean) * self.scale

    def _split(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        K = theta[..., : self.nu * self.nx].reshape(theta.shape[:-1] + (self.nu, self.nx))
        k = (
            theta[..., self.nu * self.nx :]
            if self.bias
            else np.zeros(theta.shape[:-1] + (self.nu,))
        )
        return K, k

    def _check(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        theta = as_finite_array(theta, "theta", ndim=(1,))
        if theta.shape != (self.n_params,):
            raise ValueError(f"theta must have shape (P,) = ({self.n_params},); got {theta.shape}")
        x = as_finite_array(x, "x", ndim=(2,))
        if x.shape[1] != self.nx:
            raise ValueError(f"x must have shape (M, nx) = (M, {self.nx}); got {x.shape}")
        return theta, x

    def act(self, theta, x) -> np.ndarray:
        theta, x = self._check(theta, x)
        K, k = self._split(theta)
        return self.normalize(x) @ K.T + k

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        theta, x = self._check(theta, x)
        K, _ = self._split(theta)
        M, z = x.shape[0], self.normalize(x)
        du_dx = np.broadcast_to(K * self.scale, (M, self.nu, self.nx)).copy()
        du_dth = np.zeros((M, self.nu, self.n_params))
        for i in range(self.nu):
            du_dth[:, i, i * self.nx : (i + 1) * self.nx] = z
            if self.bias:
                du_dth[:, i, self.nu * self.nx + i] = 1.0
        return du_dx, du_dth

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        theta, x = self._check(theta, x)
        K, _ = self._split(theta)
        g_u = np.asarray(g_u, float)
        g_th = np.einsum("mi,mj->mij", g_u, self.normalize(x)).reshape(x.shape[0], -1)
        if self.bias:
            g_th = np.concatenate([g_th, g_u], axis=1)
        return (g_u @ K) * self.scale, g_th


@dataclass(frozen=True, eq=False)
class ParameterBlocks:
    """``copies`` parameter vectors of one :class:`NormalizedLinearPolicy` in one theta
    (copies P,), each row of a batch acting with its own block: lets the 2N perturbed policies
    of an ARS iteration run as one batched engine rollout (each row is its own rollout).

    Which block a row uses: without ``owner``, a batch of M = copies m rows is cut into
    ``copies`` consecutive blocks of m, block c acting with parameters c; with ``owner`` (M,)
    whole numbers in [0, copies), row r acts with block ``owner[r]`` (a batch from which some
    rollouts have left, e.g. ended episodes).
    """

    policy: NormalizedLinearPolicy
    copies: int
    owner: np.ndarray | None = None

    def __post_init__(self):
        if self.owner is not None:
            owner = np.asarray(self.owner)
            if (owner.ndim != 1 or not np.issubdtype(owner.dtype, np.integer)
                    or np.any(owner < 0) or np.any(owner >= self.copies)):  # fmt: skip
                raise ValueError(
                    f"owner must be whole numbers (M,) in [0, copies = {self.copies}); got "
                    f"{self.owner!r}"
                )
            object.__setattr__(self, "owner", owner.copy())

    @property
    def nx(self) -> int:
        return self.policy.nx

    @property
    def nu(self) -> int:
        return self.policy.nu

    @property
    def n_params(self) -> int:
        return self.copies * self.policy.n_params

    def _check(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        theta = as_finite_array(theta, "theta", ndim=(1,))
        if theta.shape != (self.n_params,):
            raise ValueError(f"theta must have shape (P,) = ({self.n_params},); got {theta.shape}")
        x = as_finite_array(x, "x", ndim=(2,))
        if self.owner is None:
            if x.shape[1] != self.nx or x.shape[0] % self.copies:
                raise ValueError(
                    f"x must have shape (copies m, nx) with copies = {self.copies}, "
                    f"nx = {self.nx}; got {x.shape}"
                )
        elif x.shape != (self.owner.size, self.nx):
            raise ValueError(
                f"x must have shape (M, nx) = ({self.owner.size}, {self.nx}) (one row per "
                f"owner); got {x.shape}"
            )
        return theta, x

    def _blocks(self, theta, x):
        theta, x = self._check(theta, x)
        m = x.shape[0] // self.copies
        K, k = self.policy._split(theta.reshape(self.copies, self.policy.n_params))
        z = self.policy.normalize(x).reshape(self.copies, m, self.nx)
        return K, k, z

    def _rows(self, theta, x):
        theta, x = self._check(theta, x)
        K, k = self.policy._split(theta.reshape(self.copies, self.policy.n_params))
        return K[self.owner], k[self.owner], self.policy.normalize(x)

    def act(self, theta, x) -> np.ndarray:
        if self.owner is not None:
            K, k, z = self._rows(theta, x)
            return np.einsum("mij,mj->mi", K, z) + k
        K, k, z = self._blocks(theta, x)
        return (np.einsum("cij,cmj->cmi", K, z) + k[:, None, :]).reshape(-1, self.nu)

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        P = self.policy.n_params
        if self.owner is not None:
            K, _, z = self._rows(theta, x)
            g = np.asarray(g_u, float).reshape(z.shape[0], self.nu)
            own = np.einsum("mi,mj->mij", g, z).reshape(z.shape[0], -1)
            if self.policy.bias:
                own = np.concatenate([own, g], axis=1)
            g_th = np.zeros((z.shape[0], self.copies, P))
            g_th[np.arange(z.shape[0]), self.owner] = own
            g_x = np.einsum("mi,mij->mj", g, K) * self.policy.scale
            return g_x, g_th.reshape(z.shape[0], -1)
        K, _, z = self._blocks(theta, x)
        c, m = self.copies, z.shape[1]
        g = np.asarray(g_u, float).reshape(c, m, self.nu)
        g_x = np.einsum("cmi,cij->cmj", g, K) * self.policy.scale
        own = np.einsum("cmi,cmj->cmij", g, z).reshape(c, m, -1)
        if self.policy.bias:
            own = np.concatenate([own, g], axis=2)
        g_th = np.zeros((c, m, c, P))
        g_th[np.arange(c), :, np.arange(c)] = own
        return g_x.reshape(-1, self.nx), g_th.reshape(c * m, -1)

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        rows = [self.vjp(theta, x, np.broadcast_to(e, (len(x), self.nu))) for e in np.eye(self.nu)]
        return np.stack([r[0] for r in rows], 1), np.stack([r[1] for r in rows], 1)


def perturbations(theta, delta, noise: float) -> np.ndarray:
    """(2N, P) the perturbed parameters of one ARS iteration: row 2k is ``theta + nu delta_k``,
    row 2k + 1 ``theta - nu delta_k`` (theta (P,), delta (N, P), nu = ``noise``)."""
    theta = np.asarray(theta, dtype=float)
    thetas = np.repeat(theta[None], 2 * len(delta), axis=0)
    thetas[0::2] += noise * delta
    thetas[1::2] -= noise * delta
    return thetas


@dataclass(frozen=True)
class ArsUpdate:
    """One ARS V2-t update (:func:`ars_update`).

    Attributes:
        theta: (P,) the updated parameters.
        step: (P,) ``theta_new - theta``.
        best: (b,) the directions used, best first.
        sigma_R: the standard deviation of the 2b returns used (1 where they are all equal).
    """

    theta: np.ndarray
    step: np.ndarray
    best: np.ndarray
    sigma_R: float


def ars_update(theta, delta, returns, usable, top: int, step_size: float) -> ArsUpdate:
    """The ARS V2-t update (Mania et al. 2018, Algorithm 2, lines 6-7; the module docstring's
    steps 3-4): of the usable directions, the b = ``top`` with the largest ``max(r_k+, r_k-)``
    (ties broken by the lower index), and::

        theta_new = theta + alpha / (b sigma_R) sum_top (r_k+ - r_k-) delta_k

    with sigma_R the (population) standard deviation of the 2b returns used.

    Args:
        theta: (P,) parameters.
        delta: (N, P) the directions.
        returns: (N, 2) the returns ``r_k+`` (column 0) and ``r_k-`` (column 1).
        usable: (N,) bool: directions whose rollouts may be used.
        top: b, directions used.
        step_size: alpha.

    Raises:
        UnconvergedStepError: fewer than b usable directions.
    """
    R = np.asarray(returns, dtype=float)
    ok = np.asarray(usable, dtype=bool)
    b = int(top)
    if int(ok.sum()) < b:
        raise UnconvergedStepError(
            f"ars_update: only {int(ok.sum())} direction(s) without unconverged steps, top = "
            f"{b} needed"
        )
    idx = np.flatnonzero(ok)
    best = idx[np.argsort(-R[idx].max(axis=1), kind="stable")[:b]]
    sigma_R = float(R[best].std())
    sigma_R = sigma_R if sigma_R > 0 else 1.0
    step = step_size / (b * sigma_R) * ((R[best, 0] - R[best, 1]) @ delta[best])
    return ArsUpdate(theta + step, step, best, sigma_R)


@dataclass(frozen=True)
class ArsRun:
    """The result of :func:`ars_v2_train`.

    Attributes:
        theta: (P,) final parameters.
        policy: the :class:`NormalizedLinearPolicy` with the final normaliser (use it with
            ``theta``).
        normalizer: the :class:`RunningMeanStd` of the states visited in training.
        rows: one dict per iteration: ``iteration``, ``return_mean`` and ``return_max`` of the
            training rollouts used, ``eval_return`` (mean return of the unperturbed policy
            theta_j on ``rollouts_per_direction`` rollouts; None without ``evaluate``),
            ``env_steps`` (this iteration's training steps, 2 N m H), ``total_env_steps``,
            ``eval_steps``, ``dropped`` (directions left out for unconverged steps),
            ``sigma_R``, ``step_norm``, ``seconds``; then a final row with the last
            ``eval_return`` (with ``evaluate``).
    """

    theta: np.ndarray
    policy: NormalizedLinearPolicy
    normalizer: RunningMeanStd
    rows: list[dict]


def _count(value, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be a whole number >= {minimum}; got {value!r}")
    return int(value)


def _positive(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating | np.integer):
        raise ValueError(f"{name} must be a finite number > 0; got {value!r}")
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0; got {value!r}")
    return float(value)


def ars_v2_train(
    obj: PolicyObjective,
    theta0,
    *,
    iterations: int,
    directions: int,
    top: int,
    step_size: float,
    noise: float,
    rng: np.random.Generator,
    rollouts_per_direction: int = 1,
    normalize: bool = True,
    evaluate: bool = True,
    batch_directions: bool = True,
    callback=None,
) -> ArsRun:
    """Train with ARS V2-t (Mania et al. 2018, Algorithm 2); see the module docstring.

    Args:
        obj: the objective; its policy must be a :class:`NormalizedLinearPolicy` (its mean and
            std are the starting normaliser).
        theta0: (P,) initial parameters (the paper starts from 0).
        iterations: updates j = 0 .. iterations-1.
        directions: N, directions sampled per iteration.
        top: b in [1, N], the best directions used.
        step_size: alpha.
        noise: nu, the std of the parameter perturbations (units of theta).
        rng: numpy Generator: the directions and every rollout's noise come from it.
        rollouts_per_direction: m, rollouts averaged per policy evaluation.
        normalize: V2 (update the normaliser; default) or V1 (keep the policy's).
        evaluate: also roll out theta_j each iteration (logged, not counted as env steps, and
            not pushed to the normaliser), and theta at the end.
        batch_directions: run all of an iteration's policies as one batched engine rollout.
        callback: ``callback(j, theta, policy, row)`` after iteration j's update (e.g. to
            evaluate the new policy elsewhere); its return value is ignored.

    Returns:
        :class:`ArsRun`.
    """
    if not isinstance(obj, PolicyObjective):
        raise ValueError(f"obj must be a PolicyObjective; got {type(obj).__name__}")
    policy = obj.policy
    if not isinstance(policy, NormalizedLinearPolicy):
        raise ValueError(
            "obj.policy must be a NormalizedLinearPolicy (ARS V2 acts on normalised states); got "
            f"{type(policy).__name__}"
        )
    iterations = _count(iterations, "iterations", 0)
    N = _count(directions, "directions")
    b = _count(top, "top")
    if b > N:
        raise ValueError(f"top must be in [1, directions = {N}]; got {top}")
    alpha, nu = _positive(step_size, "step_size"), _positive(noise, "noise")
    m = _count(rollouts_per_direction, "rollouts_per_direction")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy Generator; got {type(rng).__name__}")
    theta = as_finite_array(theta0, "theta0", ndim=(1,)).copy()
    if theta.shape != (policy.n_params,):
        raise ValueError(f"theta0 must have shape (P,) = ({policy.n_params},); got {theta.shape}")
    stats = RunningMeanStd(policy.nx)
    H = int(obj.horizon)
    rows: list[dict] = []
    total = 0
    for j in range(iterations):
        start = time.perf_counter()
        delta = rng.standard_normal((N, theta.size))
        thetas = perturbations(theta, delta, nu)
        noises = [obj.noise(rng, m) for _ in range(N)]  # common to + and -
        noises = [xi for xi in noises for _ in (0, 1)]
        if evaluate:
            thetas = np.concatenate([thetas, theta[None]])
            noises.append(obj.noise(rng, m))
        returns, used, states, alive = _evaluate(obj, policy, thetas, noises, batch_directions)
        R = returns[: 2 * N].reshape(N, 2, m).mean(axis=2)  # (N, 2): r+, r-
        ok = used[: 2 * N].reshape(N, 2 * m).all(axis=1)
        try:
            update = ars_update(theta, delta, R, ok, b, alpha)
        except UnconvergedStepError as err:
            raise UnconvergedStepError(f"ars_v2_train: iteration {j}: {err}") from err
        theta, step, sigma_R = update.theta, update.step, update.sigma_R
        train_used = used[: 2 * N]
        counted = alive[: 2 * N]  # steps before an episode ended
        if normalize:
            stats.push(states[: 2 * N][train_used][counted[train_used]].reshape(-1, policy.nx))
            policy = policy.with_stats(stats.mean, stats.std)
        steps = int(counted.sum())
        total += steps
        train_returns = returns[: 2 * N][train_used].reshape(-1)
        rows.append({
            "iteration": j,
            "return_mean": float(train_returns.mean()),
            "return_max": float(train_returns.max()),
            "eval_return": float(returns[2 * N][used[2 * N]].mean()) if evaluate else None,
            "env_steps": steps,
            "total_env_steps": total,
            "eval_steps": m * H if evaluate else 0,
            "dropped": int(N - ok.sum()),
            "sigma_R": sigma_R,
            "step_norm": float(np.linalg.norm(step)),
            "seconds": time.perf_counter() - start,
        })  # fmt: skip
        if callback is not None:
            callback(j, theta, policy, rows[-1])
    if evaluate:
        returns, used, _, _ = _evaluate(
            obj, policy, theta[None], [obj.noise(rng, m)], batch_directions
        )
        rows.append({"iteration": iterations, "eval_return": float(returns[0][used[0]].mean()),
                     "total_env_steps": total, "eval_steps": m * H})  # fmt: skip
    return ArsRun(theta, policy, stats, rows)


def _evaluate(obj, policy, thetas, noises, batched):
    """Roll out policy with each of thetas (C, P) on its noise (m, H, nu): returns (C, m),
    used (C, m), the states where the policy acted (C, m, H, nx), and whether each step counted
    (C, m, H: False after an episode ended)."""
    C, m = len(thetas), noises[0].shape[0]
    if batched:
        o = dataclasses.replace(obj, policy=ParameterBlocks(policy, C))
        traj = o.rollout(thetas.reshape(-1), np.concatenate(noises), gradient=False)
        x = traj.x[:, :-1]
        return (traj.returns.reshape(C, m), traj.used.reshape(C, m),
                x.reshape(C, m, *x.shape[1:]), traj.alive.reshape(C, m, -1))  # fmt: skip
    o = dataclasses.replace(obj, policy=policy)
    trajs = [o.rollout(th, xi, gradient=False) for th, xi in zip(thetas, noises, strict=True)]
    return (np.array([t.returns for t in trajs]), np.array([t.used for t in trajs]),
            np.array([t.x[:, :-1] for t in trajs]), np.array([t.alive for t in trajs]))  # fmt: skip
