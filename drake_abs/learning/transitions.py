"""Recorded transitions ``(x, u) -> x_next`` of a simulator, grouped in episodes, for fitting a
model's parameters (e.g. our scenes in Drake's MultibodyPlant under SAP and in MuJoCo,
:mod:`drake_abs.reference.scene_sources`) and for measuring its one-step and k-step prediction
errors.

A :class:`Transitions` holds N transitions in the coordinates of one of our scenes: x = (q, v)
(nx = nq + nv), u the scene's input (nu: joint torques or forces, the stepper's units), x_next
the state one ``time_step`` later. Rows of one episode are stored in order (``t`` = 0, 1, ...
counts the steps within the episode), so consecutive rows of an episode chain: x_next of row i
is x of row i + 1 (not enforced: a source records what it simulated).
:meth:`Transitions.from_trajectory` makes them from an engine run (one rollout per episode).

Everything here is numerics: no simulator, no Drake. :func:`one_step_predictions` steps any
batched stepper (an object with ``step(x, u, jacobians=False)``, such as
:class:`~drake_abs.multibody.stepper.ComplementarityStepper`) from the recorded states;
:func:`one_step_errors` splits a scene stepper's errors by contact and joint limits.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from drake_abs.engine.closed_loop import Trajectory

__all__ = [
    "CLEARANCE",
    "NEAR_LIMIT",
    "Transitions",
    "error_summary",
    "one_step_errors",
    "one_step_predictions",
]


def _rng(rng) -> np.random.Generator:
    """A numpy Generator from ``rng`` (a Generator, or an int / sequence of ints seed)."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, bool):
        raise ValueError(f"rng must be a numpy Generator or an integer seed; got {rng!r}")
    try:
        return np.random.default_rng(rng)
    except (TypeError, ValueError) as err:
        raise ValueError(f"rng must be a numpy Generator or an integer seed; got {rng!r}") from err


def _float_2d(value, name: str, rows: int | None, cols: int | None, form: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=np.float64)  # a copy: the stored arrays are made read-only
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name} must be a real numeric array {form}; got {type(value)}") from err
    if arr.ndim != 2:
        raise ValueError(f"{name} must have shape {form}; got shape {arr.shape}")
    if (rows is not None and arr.shape[0] != rows) or (cols is not None and arr.shape[1] != cols):
        want = (rows if rows is not None else "N", cols if cols is not None else "?")
        raise ValueError(f"{name} must have shape {form} = {want}; got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(arr))[0])
        raise ValueError(f"{name} contains NaN or inf (first at index {bad})")
    return arr


def _int_1d(value, name: str, rows: int) -> np.ndarray:
    arr = np.asarray(value)
    if arr.shape != (rows,):
        raise ValueError(f"{name} must have shape (N,) = ({rows},); got {arr.shape}")
    if arr.size and not np.issubdtype(arr.dtype, np.integer):
        if not (np.issubdtype(arr.dtype, np.floating) and np.all(arr == np.round(arr))):
            raise ValueError(f"{name} must hold integers; got dtype {arr.dtype}")
    arr = arr.astype(np.int64)
    if np.any(arr < 0):
        raise ValueError(f"{name} must be >= 0; got a minimum of {int(arr.min())}")
    return arr


@dataclass(frozen=True, eq=False)
class Transitions:
    """N recorded transitions x -> x_next under input u, in episodes.

    Attributes:
        x: (N, nx) states (q, v) at the start of each transition (our scene's coordinates).
        u: (N, nu) inputs applied over the step (the scene's units; nu may be 0).
        x_next: (N, nx) states one ``time_step`` later.
        episode: (N,) integer episode ids (>= 0); an episode's rows are stored in order.
        t: (N,) the step index of each transition within its episode (0, 1, ...).
        source: what produced the data (e.g. ``"drake-sap:gym_hopper"``).
        time_step: seconds between x and x_next.
        contact: (N,) bool or None: whether the source simulator had contact at x or at
            x_next (its own contact model; None when unknown). The free transitions
            (``~contact``) are where a different contact model should agree.

    The constructor checks shapes and values and raises ``ValueError`` naming the argument.
    """

    x: np.ndarray
    u: np.ndarray
    x_next: np.ndarray
    episode: np.ndarray
    t: np.ndarray
    source: str
    time_step: float
    contact: np.ndarray | None = None

    def __post_init__(self):
        x = _float_2d(self.x, "x", None, None, "(N, nx)")
        n, nx = x.shape
        if nx < 1:
            raise ValueError(f"x must have at least one column (nx >= 1); got shape {x.shape}")
        u = self.u
        if np.ndim(u) == 1 and np.size(u) == 0 and n == 0:
            u = np.zeros((0, 0))
        u = _float_2d(u, "u", n, None, "(N, nu)")
        x_next = _float_2d(self.x_next, "x_next", n, nx, "(N, nx)")
        episode = _int_1d(self.episode, "episode", n)
        t = _int_1d(self.t, "t", n)
        if not isinstance(self.source, str):
            raise ValueError(f"source must be a string; got {type(self.source).__name__}")
        try:
            time_step = float(self.time_step)
        except (TypeError, ValueError) as err:
            raise ValueError(f"time_step must be a number (s); got {self.time_step!r}") from err
        if not (np.isfinite(time_step) and time_step > 0):
            raise ValueError(f"time_step must be finite and > 0 (s); got {self.time_step!r}")
        contact = None
        if self.contact is not None:
            contact = np.array(self.contact)
            if contact.shape != (n,):
                raise ValueError(f"contact must have shape (N,) = ({n},); got {contact.shape}")
            if contact.dtype != bool:
                if not np.all(np.isin(contact, (0, 1))):
                    raise ValueError("contact must hold booleans (or 0 / 1)")
                contact = contact.astype(bool)
        # within an episode, rows in order of t (the windows and the chaining rely on it)
        same = episode[1:] == episode[:-1]
        if np.any(same & (t[1:] <= t[:-1])):
            i = int(np.flatnonzero(same & (t[1:] <= t[:-1]))[0])
            raise ValueError(
                f"t must increase within an episode (rows stored in order); rows {i} and {i + 1} "
                f"of episode {int(episode[i])} have t = {int(t[i])}, {int(t[i + 1])}"
            )
        for name, value in (("x", x), ("u", u), ("x_next", x_next), ("episode", episode),
                            ("t", t), ("time_step", time_step), ("contact", contact)):  # fmt: skip
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def from_trajectory(
        cls,
        trajectory: Trajectory,
        *,
        source: str,
        time_step: float,
        in_contact: Callable[[np.ndarray], np.ndarray] | None = None,
        terminated: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> Transitions:
        """The transitions of an engine run (a :class:`~drake_abs.engine.Trajectory` of
        :func:`~drake_abs.engine.open_loop` or :func:`~drake_abs.engine.rollout`: x (M, H + 1,
        nx), u (M, H, nu)): rollout m is episode m, its step t the row (x_t, u_t, x_{t+1}).

        Args:
            trajectory: the run (its ``x`` and ``u``).
            source, time_step: what simulated it, and seconds per step.
            in_contact: states (N, nx) -> (N,) bool, whether the simulator has contact at each
                state; a transition's ``contact`` is its value at x_t or at x_{t+1} (None: no
                contact flags).
            terminated: states (N, nx) -> (N,) bool; an episode ends with its first step whose
                x_{t+1} is terminal (e.g. gymnasium's Hopper falling), its later steps left out
                (None: every episode has its H steps).
        """
        x = np.asarray(trajectory.x, dtype=float)
        u = np.asarray(trajectory.u, dtype=float)
        if x.ndim != 3 or u.ndim != 3 or u.shape[:2] != (x.shape[0], x.shape[1] - 1):
            raise ValueError(
                "trajectory must have x (M, H + 1, nx) and u (M, H, nu); got x "
                f"{x.shape}, u {u.shape}"
            )
        M, H, nx = u.shape[0], u.shape[1], x.shape[2]

        def flags(fn, states: np.ndarray, name: str) -> np.ndarray:
            out = np.asarray(fn(states.reshape(-1, nx)))
            if out.shape != (states.shape[0] * states.shape[1],):
                raise ValueError(f"{name}(states (N, nx)) must return (N,) flags; got {out.shape}")
            return out.astype(bool).reshape(states.shape[:2])

        lengths = np.full(M, H)
        if terminated is not None:
            ended = flags(terminated, x[:, 1:], "terminated")
            lengths = np.where(ended.any(axis=1), ended.argmax(axis=1) + 1, H)
        keep = np.arange(H)[None, :] < lengths[:, None]  # (M, H)
        contact = None
        if in_contact is not None:
            touching = flags(in_contact, x, "in_contact")
            contact = (touching[:, :-1] | touching[:, 1:])[keep]
        return cls(
            x=x[:, :-1][keep], u=u[keep], x_next=x[:, 1:][keep],
            episode=np.repeat(np.arange(M), lengths), t=np.nonzero(keep)[1], source=source,
            time_step=time_step, contact=contact,
        )  # fmt: skip

    # ------------------------------------------------------------------------------ sizes

    def __len__(self) -> int:
        return self.x.shape[0]

    @property
    def nx(self) -> int:
        return self.x.shape[1]

    @property
    def nu(self) -> int:
        return self.u.shape[1]

    @property
    def episode_ids(self) -> np.ndarray:
        """The distinct episode ids, in order of first appearance."""
        ids, first = np.unique(self.episode, return_index=True)
        return ids[np.argsort(first)]

    @property
    def n_episodes(self) -> int:
        return int(np.unique(self.episode).size)

    def __repr__(self) -> str:
        return (
            f"Transitions({len(self)} transitions, {self.n_episodes} episodes, nx={self.nx}, "
            f"nu={self.nu}, time_step={self.time_step:g} s, source={self.source!r})"
        )

    # ------------------------------------------------------------------------- selection

    def select(self, rows) -> Transitions:
        """The transitions at ``rows`` (indices or a boolean mask), in that order."""
        rows = np.asarray(rows)
        if rows.dtype == bool:
            if rows.shape != (len(self),):
                raise ValueError(f"rows as a mask must have shape ({len(self)},); got {rows.shape}")
            rows = np.flatnonzero(rows)
        return replace(
            self, x=self.x[rows], u=self.u[rows], x_next=self.x_next[rows],
            episode=self.episode[rows], t=self.t[rows],
            contact=None if self.contact is None else self.contact[rows],
        )  # fmt: skip

    def _episode_rows(self, ids) -> np.ndarray:
        """The rows of the episodes ``ids``, episode after episode (in the order of ``ids``)."""
        if len(ids) == 0:
            return np.zeros(0, dtype=np.int64)
        return np.concatenate([np.flatnonzero(self.episode == e) for e in ids])

    def split(self, fraction: float, rng) -> tuple[Transitions, Transitions]:
        """(train, test) by whole episodes: a random ``fraction`` of the episodes (rounded, at
        least one on each side) for training, the rest for testing; no episode is in both.
        ``rng``: a numpy Generator or an integer seed."""
        try:
            fraction = float(fraction)
        except (TypeError, ValueError) as err:
            raise ValueError(f"fraction must be a number in (0, 1); got {fraction!r}") from err
        if not 0.0 < fraction < 1.0:
            raise ValueError(f"fraction must be in (0, 1) (the training share); got {fraction!r}")
        ids = self.episode_ids
        if ids.size < 2:
            raise ValueError(
                f"split needs at least 2 episodes (it splits by episode); this data has {ids.size}"
            )
        order = _rng(rng).permutation(ids)
        n_train = min(max(int(round(fraction * ids.size)), 1), ids.size - 1)
        keep = np.isin(self.episode, order[:n_train])
        return self.select(keep), self.select(~keep)

    def subset(self, n: int, rng=None) -> Transitions:
        """``n`` transitions taken by whole episodes: the first episodes (``rng`` None) or
        episodes in a random order (``rng`` a Generator or an integer seed), each whole, the
        last one cut to its first steps so that exactly ``n`` are taken."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 0 <= n <= len(self):
            raise ValueError(f"n must be an integer in 0 .. {len(self)}; got {n!r}")
        ids = self.episode_ids if rng is None else _rng(rng).permutation(self.episode_ids)
        return self.select(self._episode_rows(ids)[: int(n)])

    def concatenate(self, *others: Transitions) -> Transitions:
        """These transitions followed by ``others`` (``Transitions.concatenate(a, b, c)`` or
        ``a.concatenate(b, c)``): the same nx, nu and time step; episode ids renumbered so that
        episodes of different parts stay apart (part k's ids shifted past part k-1's); the
        source is the parts' common source or their sources joined by ``+``; ``contact`` kept
        when every part has it."""
        parts = (self, *others)
        for k, p in enumerate(parts):
            if not isinstance(p, Transitions):
                raise ValueError(f"others[{k - 1}] must be Transitions; got {type(p).__name__}")
            if (p.nx, p.nu) != (self.nx, self.nu):
                raise ValueError(
                    f"others[{k - 1}] has (nx, nu) = {(p.nx, p.nu)}; expected {(self.nx, self.nu)}"
                )
            if not np.isclose(p.time_step, self.time_step, rtol=1e-12, atol=0.0):
                raise ValueError(
                    f"others[{k - 1}] has time_step {p.time_step}; expected {self.time_step}"
                )
        episodes, offset = [], 0
        for p in parts:
            episodes.append(p.episode + offset)
            offset += int(p.episode.max()) + 1 if len(p) else 0
        sources = list(dict.fromkeys(p.source for p in parts))
        contact = None
        if all(p.contact is not None for p in parts):
            contact = np.concatenate([p.contact for p in parts])
        return Transitions(
            x=np.concatenate([p.x for p in parts]), u=np.concatenate([p.u for p in parts]),
            x_next=np.concatenate([p.x_next for p in parts]), episode=np.concatenate(episodes),
            t=np.concatenate([p.t for p in parts]), source="+".join(sources),
            time_step=self.time_step, contact=contact,
        )  # fmt: skip

    def windows(self, horizon: int) -> np.ndarray:
        """Start rows i whose ``horizon`` transitions i, ..., i + horizon - 1 are consecutive
        steps of one episode (same id, t increasing by one): the starts of k-step predictions
        (x of row i, the inputs of the rows, compared with x_next of row i + horizon - 1)."""
        if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
            raise ValueError(f"horizon must be an integer >= 1; got {horizon!r}")
        n = len(self)
        if n < horizon:
            return np.zeros(0, dtype=np.int64)
        # link[i]: row i + 1 is the step after row i
        link = (self.episode[1:] == self.episode[:-1]) & (self.t[1:] == self.t[:-1] + 1)
        # a start is valid when the horizon - 1 links after it all hold
        broken = np.concatenate([[0], np.cumsum(~link)])  # breaks among links 0 .. i - 1
        starts = np.arange(n - horizon + 1)
        ok = broken[starts + horizon - 1] - broken[starts] == 0
        return starts[ok]

    # ------------------------------------------------------------------------------ files

    def save(self, path) -> Path:
        """Write an ``.npz`` (numpy's, no pickles) at ``path``; returns the path written."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        extra = {} if self.contact is None else {"contact": self.contact}
        np.savez(
            path, x=self.x, u=self.u, x_next=self.x_next, episode=self.episode, t=self.t,
            source=np.array(self.source), time_step=np.array(self.time_step), **extra,
        )  # fmt: skip
        return path

    @classmethod
    def load(cls, path) -> Transitions:
        """The transitions :meth:`save` wrote at ``path``."""
        with np.load(Path(path), allow_pickle=False) as f:
            missing = {"x", "u", "x_next", "episode", "t", "source", "time_step"} - set(f.files)
            if missing:
                raise ValueError(f"{path} is not a Transitions file: missing {sorted(missing)}")
            return cls(
                x=f["x"], u=f["u"], x_next=f["x_next"], episode=f["episode"], t=f["t"],
                source=str(f["source"]), time_step=float(f["time_step"]),
                contact=f["contact"] if "contact" in f.files else None,
            )  # fmt: skip

    def equals(self, other: Transitions) -> bool:
        """Whether every array, the source and the time step are identical."""
        if not isinstance(other, Transitions):
            return False
        same = (self.source == other.source and self.time_step == other.time_step
                and (self.contact is None) == (other.contact is None))  # fmt: skip
        arrays = ("x", "u", "x_next", "episode", "t") + (("contact",) if self.contact is not None
                                                         else ())  # fmt: skip
        return same and all(np.array_equal(getattr(self, a), getattr(other, a)) for a in arrays)


# ------------------------------------------------------------------------------ predictions


def one_step_predictions(stepper, data: Transitions, *, batch: int = 1):
    """x_next (N, nx) predicted by ``stepper`` (``step(x, u, jacobians=False)`` returning an
    object with ``x_next`` and ``converged``) from each recorded (x, u), ``batch`` states per
    call; and the (N,) converged flags (all True when the stepper gives none).

    One state per call by default: a stepper's batched call must give each state's own step,
    which the pinocchio-backed scene steppers of damped scenes (gym_hopper, gym_half_cheetah)
    did not at the time of writing (their batched contact rows were read from stale
    kinematics); a larger ``batch`` is faster where that holds."""
    if isinstance(batch, bool) or not isinstance(batch, (int, np.integer)) or batch < 1:
        raise ValueError(f"batch must be an integer >= 1; got {batch!r}")
    preds, flags = [], []
    for start in range(0, len(data), batch):
        rows = slice(start, start + batch)
        step = stepper.step(data.x[rows], data.u[rows], jacobians=False)
        x_next = np.asarray(step.x_next, dtype=float).reshape(-1, data.nx)
        preds.append(x_next)
        conv = getattr(step, "converged", None)
        flags.append(np.ones(len(x_next), bool) if conv is None else np.asarray(conv, bool))
    if not preds:
        return np.zeros((0, data.nx)), np.zeros(0, bool)
    return np.concatenate(preds), np.concatenate(flags)


def error_summary(data: Transitions, x_pred, nq: int, parts: dict | None = None) -> dict:
    """One-step prediction errors of ``x_pred`` (N, nx) against ``data.x_next``, per part:
    ``"all"``, and with ``data.contact`` known ``"free"`` (no contact in the source at x nor at
    x_next) and ``"contact"``, and any further ``parts`` ({name: (N,) bool mask}). Each part:
    ``n``, and for positions (the first ``nq`` entries of x: m or rad) and velocities (m/s or
    rad/s) the mean and the max over transitions of the largest absolute entry error
    (``q_mean``, ``q_max``, ``v_mean``, ``v_max``); None values where a part is empty."""
    x_pred = _float_2d(x_pred, "x_pred", len(data), data.nx, "(N, nx)")
    if isinstance(nq, bool) or not isinstance(nq, (int, np.integer)) or not 0 < nq < data.nx:
        raise ValueError(f"nq must be an integer in 1 .. nx - 1 = {data.nx - 1}; got {nq!r}")
    err = np.abs(x_pred - data.x_next)
    q_err, v_err = err[:, :nq].max(axis=1), err[:, nq:].max(axis=1)
    extra, parts = parts, {"all": np.ones(len(data), bool)}
    if data.contact is not None:
        parts |= {"free": ~data.contact, "contact": data.contact.copy()}
    for name, mask in (extra or {}).items():
        mask = np.asarray(mask)
        if mask.shape != (len(data),) or mask.dtype != bool:
            raise ValueError(f"parts[{name!r}] must be a bool mask of shape ({len(data)},)")
        parts[name] = mask
    out = {}
    for name, mask in parts.items():
        n = int(mask.sum())
        stats = {"n": n}
        for key, e in (("q", q_err), ("v", v_err)):
            stats[f"{key}_mean"] = float(e[mask].mean()) if n else None
            stats[f"{key}_max"] = float(e[mask].max()) if n else None
        out[name] = stats
    return out


#: A transition is "near a joint limit" when a limited joint is within this (rad or m) of its
#: limit at x or at x_next (the scenes' activation distance): a scene stepper's limits are hard,
#: Drake's (SAP constraints, which act before the limit at speed) and MuJoCo's soft.
NEAR_LIMIT = 0.1
#: ... and "clear of the ground" when every contact point is at least this (m) above it at x
#: and at x_next: closer, a speculative contact may hold a point the source lets sink.
CLEARANCE = 1e-3


def one_step_errors(
    stepper, data: Transitions, *, near_limit: float = NEAR_LIMIT, clearance: float = CLEARANCE
) -> dict:
    """A scene stepper's one-step prediction errors on ``data``: ``stepper`` (a
    :class:`~drake_abs.multibody.stepper.ComplementarityStepper`: its ``sizes``, ``limits`` and
    ``model.distances`` are read) from each recorded (x, u), one state per call
    (:func:`one_step_predictions`), against the recorded x_next.

    Returns :func:`error_summary`'s parts (``all``; ``free`` and ``contact`` by the source's
    contact flag; ``smooth``: free, every contact point clear of the ground by ``clearance`` m
    and no joint within ``near_limit`` of a limit, at x and at x_next, where a rigid and a
    compliant model step the same smooth dynamics), plus ``unconverged`` (steps whose contact
    solve did not converge), ``seconds``, and per transition (N,) the errors ``q_err``,
    ``v_err`` (the largest absolute entry error in q and in v) and the masks ``near_limit``,
    ``clear``."""
    start = time.perf_counter()
    x_pred, converged = one_step_predictions(stepper, data)
    nq = int(stepper.sizes[0])
    q, q_next = data.x[:, :nq], data.x_next[:, :nq]
    near = np.zeros(len(data), bool)
    limits = getattr(stepper, "limits", None)
    if limits is not None and limits.size:
        near = np.minimum(limits.distances(q), limits.distances(q_next)).min(axis=1) < near_limit
    distances = stepper.model.distances
    clear = np.minimum(distances(q), distances(q_next)).min(axis=1) >= clearance
    parts = {} if data.contact is None else {"smooth": ~data.contact & ~near & clear}
    out = error_summary(data, x_pred, nq, parts)
    err = np.abs(x_pred - data.x_next)
    out["unconverged"] = int((~converged).sum())
    out["seconds"] = time.perf_counter() - start
    out["q_err"], out["v_err"] = err[:, :nq].max(axis=1), err[:, nq:].max(axis=1)
    out["near_limit"], out["clear"] = near, clear
    return out
