"""A learned state-value function (a critic) for short-horizon policy learning: a small MLP
``V(z; phi)`` of the normalised observation z, its TD(lambda) targets, and its fit by minibatch
Adam on the squared error, as the critic of SHAC (Xu et al. 2022, "Accelerated Policy Learning
with Parallel Differentiable Simulation").

- :class:`ValueFunction`: ``V(z) = W_L tanh(... tanh(W_1 z + b_1) ...) + b_L`` (one output);
  the network and its backpropagation are :class:`~drake_abs.policy.policies.MLPPolicy`'s with
  one output, so ``dV/dz`` and ``dV/dphi`` come from the same vector-Jacobian product.
- :func:`td_lambda_targets`: the TD(lambda) return of every step of a window of M sequences of
  different lengths L_m, bootstrapped from the value at the end unless the episode terminated::

      G_t = r_t + gamma ((1 - lambda) V_{t+1} + lambda G_{t+1}),   t = L - 1, ..., 0
      G_L = V_L = V(x_L) if the episode goes on after step L, 0 if it terminated there

  (lambda = 1: the discounted sum of the rewards plus gamma^(L - t) V(x_L); lambda = 0: one-step
  TD targets r_t + gamma V(x_{t+1})).
- :meth:`ValueFunction.fit`: ``epochs`` passes over the samples in ``minibatches`` random
  minibatches, each an Adam step on ``mean (V(z) - G)^2``.
- :class:`StateValue`: the value of a full state x through an observation map and a normaliser,
  ``V(x) = V((obs(x) - mean) / std)``, with dV/dx (the tail of a differentiable window).

Units: V in the reward's units (a discounted sum of rewards); z dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drake_abs._validation import as_count, as_finite_array
from drake_abs.policy.policies import MLPPolicy
from drake_abs.policy.training import Adam

__all__ = ["StateValue", "ValueFunction", "td_lambda_targets"]


@dataclass(frozen=True)
class ValueFunction:
    """An MLP state-value function of n inputs (tanh hidden layers, linear output).

    Args:
        n: the input's size (the normalised observation's).
        hidden: the hidden layers' widths.
    """

    n: int
    hidden: tuple[int, ...] = (64, 64)

    def __post_init__(self):
        as_count(self.n, "n", minimum=1)
        if not self.hidden or any(int(h) < 1 for h in self.hidden):
            raise ValueError(f"hidden must be one or more widths >= 1; got {self.hidden!r}")

    @property
    def network(self) -> MLPPolicy:
        """The MLP (n inputs, one output)."""
        return MLPPolicy(self.n, 1, tuple(int(h) for h in self.hidden))

    @property
    def n_params(self) -> int:
        return self.network.n_params

    def init(self, rng: np.random.Generator) -> np.ndarray:
        """(P,) Glorot-style random weights, zero biases."""
        return self.network.init(rng)

    def __call__(self, phi, z) -> np.ndarray:
        """V (M,) at inputs z (M, n)."""
        return self.network.act(phi, z)[:, 0]

    def value_and_input_gradient(self, phi, z) -> tuple[np.ndarray, np.ndarray]:
        """(V (M,), dV/dz (M, n)) at inputs z (M, n)."""
        net = self.network
        z = as_finite_array(z, "z", ndim=(2,))
        g_z, _ = net.vjp(phi, z, np.ones((z.shape[0], 1)))
        return net.act(phi, z)[:, 0], g_z

    def loss_and_gradient(self, phi, z, targets) -> tuple[float, np.ndarray]:
        """(mean (V(z) - G)^2, its gradient in phi (P,)) for inputs z (M, n), targets G (M,)."""
        net = self.network
        z = as_finite_array(z, "z", ndim=(2,))
        targets = as_finite_array(targets, "targets", ndim=(1,))
        if targets.shape != (z.shape[0],):
            raise ValueError(f"targets must have shape (M,) = ({z.shape[0]},); got {targets.shape}")
        error = net.act(phi, z)[:, 0] - targets
        M = z.shape[0]
        _, g_phi = net.vjp_sum(phi, z, (2.0 / M) * error[:, None])
        return float(np.mean(error * error)), g_phi

    def fit(
        self,
        phi,
        z,
        targets,
        optimizer: Adam,
        rng: np.random.Generator,
        *,
        epochs: int,
        minibatches: int,
    ) -> tuple[np.ndarray, float]:
        """Fit V to the targets: ``epochs`` passes over the M samples, each in ``minibatches``
        random minibatches (a permutation from ``rng``), one Adam step per minibatch on the mean
        squared error (``optimizer`` ascends, so it is given minus the gradient; its state is
        updated). Returns (phi (P,), the mean squared error of the last epoch's minibatches)."""
        phi = as_finite_array(phi, "phi", ndim=(1,)).copy()
        z = as_finite_array(z, "z", ndim=(2,))
        targets = as_finite_array(targets, "targets", ndim=(1,))
        epochs = as_count(epochs, "epochs", minimum=1)
        minibatches = as_count(minibatches, "minibatches", minimum=1)
        M = z.shape[0]
        if M == 0:
            raise ValueError("z must hold at least one sample to fit")
        losses = []
        for _ in range(epochs):
            order = rng.permutation(M)
            losses = []
            for idx in np.array_split(order, min(minibatches, M)):
                loss, grad = self.loss_and_gradient(phi, z[idx], targets[idx])
                phi = optimizer.step(phi, -grad)
                losses.append(loss)
        return phi, float(np.mean(losses))


def td_lambda_targets(
    rewards,
    values,
    lengths,
    bootstrap,
    gamma: float,
    lam: float,
) -> np.ndarray:
    """TD(lambda) targets of a window of M sequences (the module docstring has the recursion).

    Args:
        rewards: (M, H) r_t; entries at t >= L_m are ignored.
        values: (M, H + 1) V(x_t) (t = 0 .. H); entries at t > L_m are ignored.
        lengths: (M,) L_m in 0 .. H, the steps of each sequence.
        bootstrap: (M,) bool: the episode goes on after step L_m (V(x_L) is its tail); False:
            it terminated there (tail 0).
        gamma: discount in [0, 1]; lam: lambda in [0, 1].

    Returns:
        (M, H) G_t for t < L_m, 0 elsewhere.
    """
    rewards = as_finite_array(rewards, "rewards", ndim=(2,))
    M, H = rewards.shape
    values = as_finite_array(values, "values", ndim=(2,))
    if values.shape != (M, H + 1):
        raise ValueError(f"values must have shape (M, H + 1) = ({M}, {H + 1}); got {values.shape}")
    lengths = np.asarray(lengths)
    if lengths.shape != (M,) or not np.issubdtype(lengths.dtype, np.integer):
        raise ValueError(f"lengths must be whole numbers of shape (M,) = ({M},)")
    if np.any((lengths < 0) | (lengths > H)):
        raise ValueError(f"lengths must be in 0 .. H = {H}")
    bootstrap = np.asarray(bootstrap)
    if bootstrap.shape != (M,) or bootstrap.dtype != bool:
        raise ValueError(f"bootstrap must be a bool array of shape (M,) = ({M},)")
    for name, v in (("gamma", gamma), ("lam", lam)):
        if not (np.isfinite(v) and 0 <= v <= 1):
            raise ValueError(f"{name} must be in [0, 1]; got {v!r}")
    rows = np.arange(M)
    tail = np.where(bootstrap, values[rows, lengths], 0.0)
    v_next = values.copy()
    v_next[rows, lengths] = tail
    G = np.zeros((M, H + 1))
    G[rows, lengths] = tail
    for t in range(H - 1, -1, -1):
        step = rewards[:, t] + gamma * ((1 - lam) * v_next[:, t + 1] + lam * G[:, t + 1])
        G[:, t] = np.where(t < lengths, step, G[:, t])
    G[rows, lengths] = 0.0
    return G[:, :H]


@dataclass(frozen=True, eq=False)
class StateValue:
    """``V(x) = critic((obs(x) - mean) / std; phi)`` of full states x, with dV/dx.

    Args:
        critic: the :class:`ValueFunction` (its n is the observation's size).
        phi: (P,) its parameters.
        observation: the observation map: ``observation(x (M, nx)) -> (M, n)`` and
            ``observation.vjp(x, g_o (M, n)) -> (M, nx)`` (e.g. a locomotion task's).
        mean, std: (n,) the normaliser (std > 0).
    """

    critic: ValueFunction
    phi: np.ndarray
    observation: object
    mean: np.ndarray
    std: np.ndarray

    def __post_init__(self):
        phi = as_finite_array(self.phi, "phi", ndim=(1,))
        if phi.shape != (self.critic.n_params,):
            raise ValueError(f"phi must have shape ({self.critic.n_params},); got {phi.shape}")
        object.__setattr__(self, "phi", phi)
        for name in ("mean", "std"):
            arr = as_finite_array(getattr(self, name), name, ndim=(1,))
            if arr.shape != (self.critic.n,):
                raise ValueError(f"{name} must have shape ({self.critic.n},); got {arr.shape}")
            object.__setattr__(self, name, arr)
        if np.any(self.std <= 0):
            raise ValueError("std must be > 0 in every entry")

    def normalized(self, x) -> np.ndarray:
        """z (M, n) of states x (M, nx)."""
        return (self.observation(x) - self.mean) / self.std

    def __call__(self, x) -> np.ndarray:
        """V (M,) at states x (M, nx)."""
        return self.critic(self.phi, self.normalized(x))

    def value_and_gradient(self, x) -> tuple[np.ndarray, np.ndarray]:
        """(V (M,), dV/dx (M, nx)) at states x (M, nx)."""
        x = as_finite_array(x, "x", ndim=(2,))
        v, g_z = self.critic.value_and_input_gradient(self.phi, self.normalized(x))
        return v, self.observation.vjp(x, g_z / self.std)
