"""An MBPO-style model-based baseline: an ensemble of learned dynamics models, short model
rollouts branched from real states, and the policy improved inside the model (after Janner,
Fu, Zhang and Levine 2019, "When to Trust Your Model: Model-Based Policy Optimization",
Algorithm 2).

One iteration (Algorithm 2's outer loop, one "epoch"):

1. collect ``real_rollouts`` rollouts of the current policy (with the objective's exploration
   noise) on the true objective's stepper, and add their transitions (x_t, u_t, x_{t+1}) to the
   real data set D_env (rollouts with an unconverged step are left out);
2. fit the ensemble of E models on D_env (:class:`MlpEnsemble`);
3. ``policy_updates`` times: sample ``branches`` start states uniformly from the states of
   D_env, roll the policy out in the model for ``rollout_length`` = k steps from each (each
   branch in one ensemble member chosen uniformly at random), and take one Adam ascent step
   along the first-order gradient of the branches' mean model return (the engine's adjoint
   pass through the model's Jacobians).

The model. Member e predicts the normalised state change

    ``(x_{t+1} - x_t - m_y) / s_y = W_e z + c_e + MLP_e(z)``

of the normalised input ``z = ((x_t, u_t) - m_z) / s_z`` (means and stds of the fitted data): a
linear part fitted by (ridge) least squares, plus a tanh MLP fitted to what the
linear part leaves, by Adam on the mean squared error; each member on its own bootstrap resample
of D_env and with its own initial weights, and (as in MBPO's model training) with a held-out
part of D_env deciding which weights each member keeps and when to stop. A linear system is
therefore fitted exactly (to the ridge), and the MLP learns the rest.
:class:`EnsembleStepper` steps with it (``contact_free_step``: no contact, and ``converged`` is
"finite").

Branches and the horizon. A branch from a real state x_t (visited at step t of a real rollout)
runs ``L = min(k, H - t)`` model steps and collects the task's stage rewards; if it reaches the
task's horizon (t + L = H) it also gets the terminal reward. Its objective is thus the task's
return-to-go truncated after k steps (no value function bootstraps the rest; see below).

How this differs from MBPO (Janner et al. 2019):

- the policy optimiser is first-order gradients of the model return through the learned model
  (backpropagation through time over the k-step branches, Adam), not Soft Actor-Critic on the
  model's transitions: there is no Q-function, no entropy bonus and no replay of model data;
  with a short k the objective is myopic (the return beyond k steps is not valued);
- the models are deterministic (mean squared error on the state change), not probabilistic
  Gaussian networks trained by likelihood; the ensemble's spread is sampled only by choosing a
  member per branch;
- the models are a linear least-squares part plus a tanh MLP residual (MBPO: swish MLPs);
- the policy is the objective's (any :class:`~drake_abs.engine.Policy`), acting with the
  objective's Gaussian exploration noise in both the real and the model rollouts;
- real data come in whole rollouts per iteration (MBPO: one environment step between updates).

Everything random comes from the Generator given to :func:`mbpo_train`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.contact.step import Step, contact_free_step
from drake_abs.contact.unconverged import UnconvergedStepError
from drake_abs.engine import TransitionReward, rollout
from drake_abs.policy.estimators import PolicyObjective
from drake_abs.policy.training import Adam

__all__ = ["EnsembleStepper", "MbpoConfig", "MbpoRun", "MlpEnsemble", "mbpo_train"]


def _count(value, name: str, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < minimum:
        raise ValueError(f"{name} must be a whole number >= {minimum}; got {value!r}")
    return int(value)


def _positive(value, name: str, *, allow_zero: bool = False) -> float:
    ok = isinstance(value, int | float | np.floating | np.integer) and not isinstance(value, bool)
    if not ok or not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        bound = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name} must be a finite number {bound}; got {value!r}")
    return float(value)


def _safe_std(values: np.ndarray) -> np.ndarray:
    """Column stds, 1 where a column is constant (a constant input carries nothing to scale)."""
    s = values.std(axis=0)
    return np.where(s > 1e-12 * (1.0 + np.abs(values).max(axis=0)), s, 1.0)


class MlpEnsemble:
    """E dynamics models ``x_{t+1} = f_e(x_t, u_t)`` (see the module docstring), batched.

    Args:
        nx, nu: state and input sizes.
        size: E, the number of members.
        hidden: widths of each member's MLP hidden layers (tanh).
        rng: numpy Generator for the initial weights (the last layer starts at zero, so an
            untrained MLP adds nothing to the linear part).
    """

    def __init__(self, nx: int, nu: int, size: int, hidden: tuple[int, ...],
                 rng: np.random.Generator):  # fmt: skip
        self.nx, self.nu = _count(nx, "nx"), _count(nu, "nu")
        self.size = _count(size, "size")
        self.hidden = tuple(_count(h, "hidden width") for h in hidden)
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy Generator; got {type(rng).__name__}")
        d, E = self.nx + self.nu, self.size
        widths = [d, *self.hidden, self.nx]
        self.layers: list[list[np.ndarray]] = []
        for i in range(len(widths) - 1):
            std = np.sqrt(2.0 / (widths[i] + widths[i + 1]))
            last = i == len(widths) - 2
            W = (
                np.zeros((E, widths[i + 1], widths[i]))
                if last
                else std * rng.standard_normal((E, widths[i + 1], widths[i]))
            )
            self.layers.append([W, np.zeros((E, widths[i + 1]))])
        self.W_lin = np.zeros((E, self.nx, d))
        self.b_lin = np.zeros((E, self.nx))
        self.z_mean, self.z_std = np.zeros(d), np.ones(d)
        self.y_mean, self.y_std = np.zeros(self.nx), np.ones(self.nx)
        self.fitted = False
        self._adam: list | None = None
        self._adam_t = 0

    # ----- the model -------------------------------------------------------------------------

    def _inputs(self, x, u) -> np.ndarray:
        x = as_finite_array(x, "x", ndim=(2,))
        u = as_finite_array(u, "u", ndim=(2,))
        if x.shape[1] != self.nx or u.shape != (x.shape[0], self.nu):
            raise ValueError(
                f"x and u must have shapes (B, nx) = (B, {self.nx}) and (B, nu) = (B, {self.nu}) "
                f"with the same B; got {x.shape} and {u.shape}"
            )
        return (np.concatenate([x, u], axis=1) - self.z_mean) / self.z_std

    def _members(self, members, B: int) -> np.ndarray:
        members = np.asarray(members)
        if members.shape != (B,) or not np.issubdtype(members.dtype, np.integer):
            raise ValueError(f"members must be integers of shape (B,) = ({B},); got {members!r}")
        if members.size and (members.min() < 0 or members.max() >= self.size):
            raise ValueError(
                f"members must be in [0, {self.size}); got {members.min()}..{members.max()}"
            )
        return members

    def _mlp(self, e: int, z: np.ndarray, jacobian: bool):
        """Member e's MLP output (n, nx) at z (n, d), and its Jacobian (n, nx, d)."""
        a, J = z, None
        for i, (W, b) in enumerate(self.layers):
            pre = a @ W[e].T + b[e]
            if jacobian:
                J = np.broadcast_to(W[e], (len(z),) + W[e].shape) if J is None else W[e] @ J
            if i < len(self.layers) - 1:
                a = np.tanh(pre)
                if jacobian:
                    J = (1.0 - a**2)[:, :, None] * J
            else:
                a = pre
        return a, J

    def predict(self, x, u, members, *, jacobians: bool = False):
        """Next states (B, nx) of x (B, nx) under u (B, nu), row b by member ``members[b]``;
        with ``jacobians`` also (dx_next/dx (B, nx, nx), dx_next/du (B, nx, nu))."""
        z = self._inputs(x, u)
        B = z.shape[0]
        members = self._members(members, B)
        y = np.empty((B, self.nx))
        J = np.empty((B, self.nx, self.nx + self.nu)) if jacobians else None
        for e in np.unique(members):
            rows = members == e
            out, Jm = self._mlp(int(e), z[rows], jacobians)
            y[rows] = z[rows] @ self.W_lin[e].T + self.b_lin[e] + out
            if jacobians:
                J[rows] = self.W_lin[e] + Jm
        x_next = np.asarray(x, float) + self.y_mean + self.y_std * y
        if not jacobians:
            return x_next
        J = self.y_std[:, None] * J / self.z_std  # back to physical units
        dx_dx = J[:, :, : self.nx] + np.eye(self.nx)
        return x_next, dx_dx, J[:, :, self.nx :].copy()

    def stepper(self, members) -> EnsembleStepper:
        """A :class:`~drake_abs.engine.Stepper` stepping row b with member ``members[b]``."""
        members = np.asarray(members)
        return EnsembleStepper(self, self._members(members, members.size))

    def error(self, x, u, x_next) -> float:
        """Mean over members and rows of the squared prediction error of the normalised state
        change (1 is the error of predicting the data set's mean change)."""
        x_next = as_finite_array(x_next, "x_next", ndim=(2,))
        errs = []
        for e in range(self.size):
            pred = self.predict(x, u, np.full(len(x_next), e))
            errs.append(np.mean(((pred - x_next) / self.y_std) ** 2))
        return float(np.mean(errs))

    # ----- fitting ---------------------------------------------------------------------------

    def fit(
        self,
        x,
        u,
        x_next,
        rng: np.random.Generator,
        *,
        epochs: int = 50,
        batch: int = 256,
        lr: float = 1e-3,
        ridge: float = 1e-6,
        bootstrap: bool = True,
        holdout: float = 0.2,
        patience: int = 5,
    ) -> float:
        """Fit every member to transitions x (n, nx), u (n, nu) -> x_next (n, nx).

        A random ``holdout`` fraction of the transitions is set aside; on the rest: the
        normalisation, each member's linear part by ridge least squares (ridge ``ridge * n`` on
        the normalised inputs), and its MLP by up to ``epochs`` passes of minibatch Adam on what
        the linear part leaves (continuing from the current weights), each member on its own
        bootstrap resample (``bootstrap``) or on all of it. As in MBPO's model training, each
        member keeps the weights of its best held-out error seen (before the first pass
        included), and training stops when no member has improved for ``patience`` passes.
        (Without it Adam, which normalises the gradient's size, keeps moving the MLP by about
        ``lr`` even where there is nothing left to fit, e.g. for a linear system.)
        ``holdout=0``: no held-out set, all ``epochs`` passes, the last weights.

        Returns:
            The mean over members of the kept weights' held-out mean squared error (training
            error with ``holdout=0``), in normalised units.
        """
        epochs, batch = _count(epochs, "epochs", 0), _count(batch, "batch")
        patience = _count(patience, "patience")
        lr, ridge = _positive(lr, "lr"), _positive(ridge, "ridge", allow_zero=True)
        holdout = _positive(holdout, "holdout", allow_zero=True)
        if holdout >= 1:
            raise ValueError(f"holdout must be in [0, 1); got {holdout!r}")
        x = as_finite_array(x, "x", ndim=(2,))
        u = as_finite_array(u, "u", ndim=(2,))
        x_next = as_finite_array(x_next, "x_next", ndim=(2,))
        n_all = x.shape[0]
        n_hold = int(round(holdout * n_all))
        n = n_all - n_hold
        if n < 2 or x_next.shape != x.shape:
            raise ValueError(
                f"fit needs >= 2 training transitions (after the held-out {n_hold}) with x and "
                f"x_next of one shape (n, nx); got {x.shape} and {x_next.shape}"
            )
        order = rng.permutation(n_all) if n_hold else np.arange(n_all)
        train, held = order[n_hold:], order[:n_hold]
        zu = np.concatenate([x, u], axis=1)
        self.z_mean, self.z_std = zu[train].mean(axis=0), _safe_std(zu[train])
        dy = x_next - x
        self.y_mean, self.y_std = dy[train].mean(axis=0), _safe_std(dy[train])
        Z = self._inputs(x, u)
        Y = (dy - self.y_mean) / self.y_std
        E, d = self.size, Z.shape[1]
        idx = train[rng.integers(0, n, size=(E, n))] if bootstrap else np.tile(train, (E, 1))
        R = np.empty((E, n, self.nx))
        R_held = np.empty((E, n_hold, self.nx))
        for e in range(E):
            Ze = np.concatenate([Z[idx[e]], np.ones((n, 1))], axis=1)
            reg = ridge * n * np.eye(d + 1)
            reg[-1, -1] = 0.0
            w = np.linalg.solve(Ze.T @ Ze + reg, Ze.T @ Y[idx[e]])
            self.W_lin[e], self.b_lin[e] = w[:d].T, w[d]
            R[e] = Y[idx[e]] - Ze @ w
            R_held[e] = Y[held] - Z[held] @ w[:d] - w[d]
        Zb = Z[idx]  # (E, n, d)
        Z_held = np.broadcast_to(Z[held], (E, n_hold, d))
        if self._adam is None:
            # per layer: first and second moments of W, then of b
            self._adam = [
                [np.zeros_like(p) for p in layer for _ in (0, 1)] for layer in self.layers
            ]
        best = self._member_mse(Z_held, R_held) if n_hold else None
        kept = [[p.copy() for p in layer] for layer in self.layers]
        bs, waited = min(batch, n), 0
        for _ in range(epochs):
            perm = np.argsort(rng.random((E, n)), axis=1)
            for start in range(0, n - bs + 1, bs):
                sel = perm[:, start : start + bs]
                zb = np.take_along_axis(Zb, sel[:, :, None], axis=1)
                rb = np.take_along_axis(R, sel[:, :, None], axis=1)
                self._adam_step(zb, rb, lr)
            if not n_hold:
                continue
            now = self._member_mse(Z_held, R_held)
            better = now < best
            waited = 0 if better.any() else waited + 1
            best = np.where(better, now, best)
            for layer, keep in zip(self.layers, kept, strict=True):
                for p, k in zip(layer, keep, strict=True):
                    k[better] = p[better]
            if waited >= patience:
                break
        if n_hold:
            self.layers = kept
        self.fitted = True
        return float(best.mean()) if n_hold else float(self._member_mse(Zb, R).mean())

    def _forward_all(self, z: np.ndarray):
        """Every member's MLP on its own batch z (E, n, d): activations per layer."""
        acts = [z]
        for i, (W, b) in enumerate(self.layers):
            pre = np.einsum("end,ehd->enh", acts[-1], W) + b[:, None, :]
            acts.append(np.tanh(pre) if i < len(self.layers) - 1 else pre)
        return acts

    def _member_mse(self, z: np.ndarray, target: np.ndarray) -> np.ndarray:
        """(E,) each member's mean squared error on its batch z (E, n, d), target (E, n, nx)."""
        return np.mean((self._forward_all(z)[-1] - target) ** 2, axis=(1, 2))

    def _adam_step(self, z, target, lr, beta1=0.9, beta2=0.999, eps=1e-8) -> None:
        acts = self._forward_all(z)
        n_out = target.shape[1] * target.shape[2]
        g = 2.0 * (acts[-1] - target) / n_out  # d(mean over the batch and outputs) / d out
        self._adam_t += 1
        t = self._adam_t
        for i in range(len(self.layers) - 1, -1, -1):
            W, _ = self.layers[i]
            grads = [np.einsum("enh,end->ehd", g, acts[i]), g.sum(axis=1)]
            if i > 0:
                g = np.einsum("enh,ehd->end", g, W) * (1.0 - acts[i] ** 2)
            state = self._adam[i]
            for j, grad in enumerate(grads):
                m, v = state[2 * j], state[2 * j + 1]
                m *= beta1
                m += (1 - beta1) * grad
                v *= beta2
                v += (1 - beta2) * grad * grad
                step = lr * (m / (1 - beta1**t)) / (np.sqrt(v / (1 - beta2**t)) + eps)
                self.layers[i][j] = self.layers[i][j] - step


@dataclass(frozen=True, eq=False)
class EnsembleStepper:
    """The learned model as a :class:`~drake_abs.engine.Stepper`: a batch of B states, row b
    stepped by member ``members[b]`` (fixed for the stepper's life, so one rollout stays in
    one member)."""

    ensemble: MlpEnsemble
    members: np.ndarray

    parameter_names = ()

    def step(self, x, u, *, jacobians: bool = True, parameters: bool = False) -> Step:
        """x (B, nx), u (B, nu) -> :class:`~drake_abs.contact.step.Step` without contact."""
        if parameters:
            raise ValueError("parameters=True: EnsembleStepper names no model parameters")
        if jacobians:
            return contact_free_step(*self.ensemble.predict(x, u, self.members, jacobians=True))
        return contact_free_step(self.ensemble.predict(x, u, self.members))


@dataclass(frozen=True)
class _StageOnly:
    """A reward's stage part, without its terminal reward (for a branch that ends before the
    task's horizon)."""

    reward: object

    def stage(self, x, u):
        return self.reward.stage(x, u)

    def terminal(self, x):
        return np.zeros(len(x)), np.zeros_like(x)


@dataclass(frozen=True)
class _TransitionOnly:
    """A reward of transitions without its terminal reward (as :class:`_StageOnly`); an
    episode still ends where the reward says so."""

    reward: object

    def transition(self, x, u, x_next):
        return self.reward.transition(x, u, x_next)

    def terminal(self, x):
        return np.zeros(len(x)), np.zeros_like(x)

    def terminated(self, x_next):
        ends = getattr(self.reward, "terminated", None)
        return np.zeros(len(x_next), dtype=bool) if ends is None else ends(x_next)


def _without_terminal(reward):
    return _TransitionOnly(reward) if isinstance(reward, TransitionReward) else _StageOnly(reward)


@dataclass(frozen=True)
class MbpoConfig:
    """Settings of :func:`mbpo_train` (see the module docstring for the loop).

    Attributes:
        iterations: outer iterations ("epochs" of Janner et al., Algorithm 2).
        real_rollouts: real rollouts (H steps each) collected per iteration.
        ensemble_size: E models.
        hidden: widths of each model's hidden layers.
        model_epochs, model_batch, model_lr: the most Adam passes over D_env per fit,
            minibatch size, step size (normalised units).
        model_holdout, model_patience: the fraction of D_env held out per fit, and the passes
            without improvement on it after which a fit stops (each member keeps its best
            weights; :meth:`MlpEnsemble.fit`).
        ridge: ridge weight of the models' linear least-squares part.
        bootstrap: each member fits its own bootstrap resample of D_env.
        rollout_length: k, model steps per branch.
        branches: model rollouts per policy update.
        policy_updates: G, Adam steps on the policy per iteration.
        policy_lr: the policy's Adam step size (units of theta).
    """

    iterations: int = 10
    real_rollouts: int = 8
    ensemble_size: int = 5
    hidden: tuple[int, ...] = (32, 32)
    model_epochs: int = 30
    model_batch: int = 256
    model_lr: float = 1e-3
    model_holdout: float = 0.2
    model_patience: int = 5
    ridge: float = 1e-6
    bootstrap: bool = True
    rollout_length: int = 5
    branches: int = 64
    policy_updates: int = 20
    policy_lr: float = 1e-2

    def __post_init__(self):
        for name in ("iterations", "real_rollouts", "ensemble_size", "model_batch",
                     "rollout_length", "branches", "policy_updates", "model_patience"):  # fmt: skip
            _count(getattr(self, name), name)
        _count(self.model_epochs, "model_epochs", 0)
        for name in ("model_lr", "policy_lr"):
            _positive(getattr(self, name), name)
        _positive(self.ridge, "ridge", allow_zero=True)
        if not 0 <= _positive(self.model_holdout, "model_holdout", allow_zero=True) < 1:
            raise ValueError(f"model_holdout must be in [0, 1); got {self.model_holdout!r}")
        if not isinstance(self.hidden, tuple) or not all(
            isinstance(h, int) and not isinstance(h, bool) and h >= 1 for h in self.hidden
        ):
            raise ValueError(f"hidden must be a tuple of whole numbers >= 1; got {self.hidden!r}")


@dataclass(frozen=True)
class MbpoRun:
    """The result of :func:`mbpo_train`.

    Attributes:
        theta: (P,) final policy parameters.
        ensemble: the final :class:`MlpEnsemble`.
        rows: one dict per iteration: ``iteration``, ``real_return`` (mean return of this
            iteration's real rollouts, i.e. of theta_j with exploration noise),
            ``real_steps`` (this iteration's), ``total_real_steps``, ``transitions`` (size of
            D_env), ``model_error`` (the previous models' error on the new transitions, before
            refitting; None at first), ``model_loss`` (the fit's held-out error),
            ``model_return`` (mean branch return at the last policy update), ``grad_norm``,
            ``dropped`` (real rollouts left out), ``seconds``; then a final row with
            ``eval_return``, the final theta's mean return on ``real_rollouts`` real rollouts
            (not counted in ``total_real_steps``).
    """

    theta: np.ndarray
    ensemble: MlpEnsemble
    rows: list[dict]


def mbpo_train(obj: PolicyObjective, theta0, config: MbpoConfig,
               rng: np.random.Generator, callback=None) -> MbpoRun:  # fmt: skip
    """Train the objective's policy MBPO-style (see the module docstring).

    Args:
        obj: the true objective: its stepper makes the real data; its policy, reward, x0,
            horizon H and sigma are used in both the real and the model rollouts.
        theta0: (P,) initial policy parameters.
        config: :class:`MbpoConfig`.
        rng: numpy Generator (all randomness: noise, bootstrap, model weights, branches).
        callback: ``callback(j, theta, row)`` after iteration j's policy updates (e.g. to
            evaluate the policy elsewhere); its return value is ignored.

    Returns:
        :class:`MbpoRun` with the logs (real env steps used, returns).
    """
    if not isinstance(obj, PolicyObjective):
        raise ValueError(f"obj must be a PolicyObjective; got {type(obj).__name__}")
    if not isinstance(config, MbpoConfig):
        raise ValueError(f"config must be an MbpoConfig; got {type(config).__name__}")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy Generator; got {type(rng).__name__}")
    theta = as_finite_array(theta0, "theta0", ndim=(1,)).copy()
    if theta.shape != (obj.policy.n_params,):
        raise ValueError(
            f"theta0 must have shape (P,) = ({obj.policy.n_params},); got {theta.shape}"
        )
    nx, nu = obj.policy.nx, obj.policy.nu
    ensemble = MlpEnsemble(nx, nu, config.ensemble_size, config.hidden, rng)
    data = {"x": np.empty((0, nx)), "u": np.empty((0, nu)), "xn": np.empty((0, nx)),
            "t": np.empty(0, dtype=np.int64)}  # fmt: skip
    optimizer = Adam(lr=config.policy_lr)
    rows, total = [], 0
    for j in range(config.iterations):
        start = time.perf_counter()
        traj = obj.rollout(theta, obj.noise(rng, config.real_rollouts), gradient=False)
        steps = int(traj.alive.sum())  # fewer than real_rollouts * H where episodes ended
        total += steps
        if not traj.used.any():
            raise UnconvergedStepError(
                f"mbpo_train: iteration {j}: every real rollout took an unconverged step"
            )
        new = _transitions(traj)
        model_error = ensemble.error(new["x"], new["u"], new["xn"]) if ensemble.fitted else None
        data = {k: np.concatenate([data[k], new[k]]) for k in data}
        loss = ensemble.fit(
            data["x"], data["u"], data["xn"], rng, epochs=config.model_epochs,
            batch=config.model_batch, lr=config.model_lr, ridge=config.ridge,
            bootstrap=config.bootstrap, holdout=config.model_holdout,
            patience=config.model_patience,
        )  # fmt: skip
        model_return = grad_norm = None
        for _ in range(config.policy_updates):
            grad, model_return = _model_gradient(obj, ensemble, theta, data, config, rng)
            grad_norm = float(np.linalg.norm(grad))
            theta = optimizer.step(theta, grad)
        rows.append({
            "iteration": j,
            "real_return": float(traj.returns[traj.used].mean()),
            "real_steps": steps,
            "total_real_steps": total,
            "transitions": int(data["x"].shape[0]),
            "model_error": model_error,
            "model_loss": loss,
            "model_return": model_return,
            "grad_norm": grad_norm,
            "dropped": int((~traj.used).sum()),
            "seconds": time.perf_counter() - start,
        })  # fmt: skip
        if callback is not None:
            callback(j, theta, rows[-1])
    final = obj.rollout(theta, obj.noise(rng, config.real_rollouts), gradient=False)
    rows.append({"iteration": config.iterations,
                 "eval_return": float(final.returns[final.used].mean()),
                 "total_real_steps": total})  # fmt: skip
    return MbpoRun(theta, ensemble, rows)


def _transitions(traj) -> dict[str, np.ndarray]:
    """The (x_t, u_t, x_{t+1}, t) of a trajectory's used rollouts, flattened: the steps that
    counted (after an episode ended, the held states are not transitions of the system)."""
    x, u, alive = traj.x[traj.used], traj.u[traj.used], traj.alive[traj.used]
    n, H = u.shape[:2]
    keep = alive.reshape(-1)
    return {
        "x": x[:, :-1].reshape(-1, x.shape[-1])[keep],
        "u": u.reshape(-1, u.shape[-1])[keep],
        "xn": x[:, 1:].reshape(-1, x.shape[-1])[keep],
        "t": np.tile(np.arange(H), n)[keep],
    }


def _model_gradient(obj, ensemble, theta, data, config, rng) -> tuple[np.ndarray, float]:
    """The gradient (P,) of the mean return of ``branches`` model rollouts branched from real
    states, and that mean return. Branches are grouped by length L = min(k, H - t)."""
    H, k = int(obj.horizon), config.rollout_length
    pick = rng.integers(0, data["x"].shape[0], size=config.branches)
    members = rng.integers(0, ensemble.size, size=config.branches)
    noise = obj.noise(rng, config.branches)
    x0, t0 = data["x"][pick], data["t"][pick]
    lengths = np.minimum(k, H - t0)
    ends = t0 + lengths == H  # the branch reaches the task's horizon: it gets the terminal reward
    grad_sum, ret_sum, n_used = np.zeros(theta.size), 0.0, 0
    for L, end in sorted({(int(a), bool(b)) for a, b in zip(lengths, ends, strict=True)}):
        rows = (lengths == L) & (ends == end)
        traj = rollout(
            ensemble.stepper(members[rows]), obj.policy, theta, x0[rows], noise[rows, :L],
            obj.reward if end else _without_terminal(obj.reward), sigma=obj.sigma, gradient=True,
            on_unconverged="drop",
        )  # fmt: skip
        grad_sum += traj.grad[traj.used].sum(axis=0)
        ret_sum += float(traj.returns[traj.used].sum())
        n_used += int(traj.used.sum())
    if n_used == 0:
        raise UnconvergedStepError("mbpo_train: every model rollout left the finite numbers")
    return grad_sum / n_used, ret_sum / n_used
