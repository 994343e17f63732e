"""Scripted inputs: seeded open-loop input schedules for :func:`drake_abs.engine.open_loop`, and
control laws of the step index and the state as time-varying engine policies.

- :func:`held_random_inputs`: inputs drawn uniformly at random from a seeded generator, each
  held for ``hold`` steps (an open-loop excitation, e.g. of gymnasium's MuJoCo models in ctrl
  units).
- :class:`TimeVaryingController`: any law ``u = control(t, x)`` (a servo, a gait, a schedule
  indexed by t) as a :class:`~drake_abs.engine.protocols.TimeVaryingPolicy`, which
  :func:`drake_abs.engine.rollout` runs forward (``gradient=False``).
- Per-episode schedules for recording data, each drawn from its episode's own seed
  (:func:`episode_seed`; e.g. ``seed=(run seed, episode seed)``): :func:`uniform_inputs` (a new
  uniform draw every step), :func:`sinusoid_inputs` (a gait with seeded phases) and
  :func:`push_inputs` (a train of sin^2 pushes with seeded amplitudes).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drake_abs._validation import as_count

__all__ = [
    "TimeVaryingController",
    "episode_seed",
    "held_random_inputs",
    "push_inputs",
    "sinusoid_inputs",
    "uniform_inputs",
]


def held_random_inputs(
    steps: int, nu: int, *, scale: float = 0.5, hold: int = 5, seed: int = 0
) -> np.ndarray:
    """Seeded piecewise-constant random inputs (steps, nu): blocks drawn uniformly in
    ``[-scale, scale]`` (the input's units) by ``numpy.random.default_rng(seed)``, each held for
    ``hold`` steps. The blocks are drawn row by row, so the first k rows do not depend on
    ``steps`` (a longer schedule continues a shorter one)."""
    steps = as_count(steps, "steps")
    nu = as_count(nu, "nu", minimum=1)
    hold = as_count(hold, "hold", minimum=1)
    if not (np.isfinite(scale) and scale >= 0):
        raise ValueError(f"scale must be a finite number >= 0; got {scale!r}")
    rng = np.random.default_rng(seed)
    blocks = rng.uniform(-scale, scale, (-(-steps // hold), nu))
    return np.repeat(blocks, hold, axis=0)[:steps]


class TimeVaryingController:
    """A control law of the step index and the state as an engine policy (forward only).

    Args:
        control: ``control(t, x) -> u``: t the step index (int, from 0), x (M, nx) the batch of
            states, u (M, nu) or (nu,) (one input for every state).
        nx, nu: the state's and the input's sizes.

    ``act(theta, x, t)`` ignores theta (pass an empty array to the engine).
    """

    time_varying = True

    def __init__(self, control: Callable[[int, np.ndarray], np.ndarray], nx: int, nu: int):
        if not callable(control):
            raise TypeError(f"control must be callable as control(t, x); got {type(control)}")
        self.control = control
        self.nx = as_count(nx, "nx", minimum=1)
        self.nu = as_count(nu, "nu", minimum=1)

    def act(self, theta, x: np.ndarray, t: int) -> np.ndarray:
        """The inputs (M, nu) at step t for the states x (M, nx)."""
        x = np.asarray(x, dtype=float)
        u = np.asarray(self.control(t, x), dtype=float)
        if u.shape not in ((self.nu,), (x.shape[0], self.nu)):
            raise ValueError(
                f"control(t, x) must return (nu,) or (M, nu) with nu = {self.nu}, "
                f"M = {x.shape[0]}; got shape {u.shape}"
            )
        return np.broadcast_to(u, (x.shape[0], self.nu))


# ------------------------------------------ per-episode inputs (seeded by the episode's key)


def episode_seed(seed: int, episode: int) -> int:
    """The seed of episode ``episode`` (0, 1, ...) of a run seeded ``seed``: a 32-bit integer
    from ``numpy.random.SeedSequence([seed, episode])`` (for ``env.reset(seed=...)``, an
    episode's initial-state noise, its inputs), so that an episode's randomness depends on its
    own index only, not on how many episodes run beside it."""
    seed = as_count(seed, "seed")
    episode = as_count(episode, "episode")
    return int(np.random.SeedSequence([seed, episode]).generate_state(1)[0])


def _generator(seed) -> np.random.Generator:
    try:
        return np.random.default_rng(seed)
    except (TypeError, ValueError) as err:
        raise ValueError(
            f"seed must be an integer >= 0 or a sequence of them (numpy's seed); got {seed!r}"
        ) from err


def uniform_inputs(steps: int, low, high, *, seed) -> np.ndarray:
    """(steps, nu) inputs uniform in [low, high] (each (nu,) or a scalar, the input's units), a
    new draw every step, from ``numpy.random.default_rng(seed)`` (``seed`` an integer or a
    sequence of them, e.g. ``(run seed, episode seed)``). Row t is the generator's t-th draw of
    nu values, so a longer schedule continues a shorter one."""
    steps = as_count(steps, "steps")
    low, high = np.broadcast_arrays(np.atleast_1d(np.asarray(low, dtype=float)),
                                    np.atleast_1d(np.asarray(high, dtype=float)))  # fmt: skip
    if low.ndim != 1 or not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))):
        raise ValueError(f"low and high must be finite scalars or (nu,); got {low}, {high}")
    if np.any(low > high):
        raise ValueError(f"low must be <= high entry by entry; got low {low}, high {high}")
    return _generator(seed).uniform(low, high, size=(steps, low.size))


def sinusoid_inputs(
    steps: int, amplitude, frequency: float, time_step: float, *, seed, offset=0.0
) -> np.ndarray:
    """(steps, nu) inputs of a gait: ``u_t = offset + amplitude sin(2 pi frequency t time_step
    + phase)`` per input, ``amplitude`` (nu,) in the input's units, ``frequency`` in Hz,
    ``time_step`` in s, the phases (nu,) uniform in [0, 2 pi) from
    ``numpy.random.default_rng(seed)``."""
    steps = as_count(steps, "steps")
    amplitude = np.atleast_1d(np.asarray(amplitude, dtype=float))
    if amplitude.ndim != 1 or not np.all(np.isfinite(amplitude)):
        raise ValueError(f"amplitude must be finite, a scalar or (nu,); got {amplitude}")
    offset = np.broadcast_to(np.asarray(offset, dtype=float), amplitude.shape)
    if not (np.isfinite(frequency) and np.isfinite(time_step) and time_step > 0):
        raise ValueError(
            f"frequency (Hz) must be finite and time_step (s) finite and > 0; got "
            f"{frequency!r}, {time_step!r}"
        )
    phases = _generator(seed).uniform(0.0, 2 * np.pi, amplitude.size)
    t = np.arange(steps)[:, None]
    return offset + amplitude * np.sin(2 * np.pi * frequency * t * time_step + phases)


def push_inputs(steps: int, max_push: float, *, seed, on: int = 30, off: int = 20) -> np.ndarray:
    """(steps, 1) a train of pushes: pulse k lasts ``on`` steps with the profile ``a_k
    sin^2(pi s / on)`` (s its step), then ``off`` steps of zero; the amplitudes a_k uniform in
    [-max_push, max_push] (the input's units), 64 of them (then repeated) from
    ``numpy.random.default_rng(seed)``."""
    steps = as_count(steps, "steps")
    on, off = as_count(on, "on", minimum=1), as_count(off, "off")
    if not (np.isfinite(max_push) and max_push >= 0):
        raise ValueError(f"max_push must be a finite number >= 0; got {max_push!r}")
    amplitudes = _generator(seed).uniform(-max_push, max_push, 64)
    pulse, s = np.divmod(np.arange(steps), on + off)
    push = amplitudes[pulse % amplitudes.size] * np.sin(np.pi * s / on) ** 2
    return np.where(s < on, push, 0.0)[:, None]
