"""The Ray rollout runner: an estimator's rollouts split over Ray actors.

:class:`RayRunner` implements :class:`~drake_abs.policy.rollouts.Runner`, so every estimator of
:mod:`drake_abs.policy.estimators` takes it as ``runner=`` (or as the default, through
:func:`~drake_abs.policy.rollouts.use_runner`)::

    from drake_abs.parallel import RayRunner, connect
    connect()                                   # a local cluster on 127.0.0.1; or connect("auto")
    with RayRunner() as runner:                 # one actor per CPU of the cluster
        est = first_order(objective, theta, rng, M=1024, runner=runner)

How the work is split: the jobs' rollouts (in job order) are cut into tasks of at most
``chunk_size`` rollouts, by default ``ceil(total / workers)``: one task per actor, which keeps
each rollout batch as large as possible (the step is batched over rollouts) and pays the per-task
overhead once per actor (``benchmarks/bench_ray.py`` measures it: about a millisecond here, against
tens of milliseconds for even a small batch of rollouts). Tasks go to the actors in turn.

What is sent: the objective (dynamics, policy, reward, x0, horizon, sigma) is pickled once per
objective and put in Ray's object store; each actor unpickles it the first time a task names it,
which rebuilds its stepper from the scene description (a
:class:`~drake_abs.multibody.stepper.ComplementarityStepper` pickles as its scene and settings),
and keeps it for the next calls. A task carries theta, the noise key and a range of rollout
indices; its noise comes from the seed tree (:mod:`drake_abs.policy.rollouts`), so the numbers do
not depend on the split. It returns per-rollout returns, gradients and scores, not trajectories.

Faults: an actor whose process dies is restarted by Ray (``max_retries`` times) and its
unfinished tasks are run again; a task is a pure function of its inputs, so the result is
unchanged. An exception raised by the rollouts themselves (bad input, ``on_unconverged="raise"``)
is not retried: it reaches the caller as that exception.
"""

from __future__ import annotations

import hashlib
import math
import os
import time
import warnings
from collections import OrderedDict
from collections.abc import Sequence

import numpy as np

from drake_abs.parallel.cluster import cluster_cpus, connect, require_ray
from drake_abs.policy.rollouts import RolloutJob, RolloutStats, rollout_stats

#: Objectives an actor keeps (least recently used dropped first).
KEPT_OBJECTIVES = 4


class _RolloutWorker:
    """One Ray actor: keeps the objectives it was sent (each with its rebuilt stepper) and runs
    rollout pieces on them."""

    def __init__(self):
        self._objectives: OrderedDict[str, object] = OrderedDict()
        self.built = 0  # objectives unpickled (steppers rebuilt) by this process

    def pid(self) -> int:
        return os.getpid()

    def ping(self) -> float:
        return time.perf_counter()

    def _objective(self, key: str, holder: list):
        obj = self._objectives.get(key)
        if obj is None:
            import ray
            from ray import cloudpickle

            obj = cloudpickle.loads(ray.get(holder[0]))
            self.built += 1
            self._objectives[key] = obj
            while len(self._objectives) > KEPT_OBJECTIVES:
                self._objectives.popitem(last=False)
        self._objectives.move_to_end(key)
        return obj

    def built_count(self) -> int:
        return self.built

    def run(
        self, key: str, holder: list, pieces: list[RolloutJob], gradient: bool, score: bool
    ) -> list[RolloutStats]:
        obj = self._objective(key, holder)
        out = []
        for piece in pieces:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                stats = rollout_stats(obj, piece, gradient=gradient, score=score)
            found = tuple((w.category, str(w.message)) for w in caught)
            out.append(RolloutStats(**{**_fields(stats), "warnings": found}))
        return out


def _fields(stats: RolloutStats) -> dict:
    return {name: getattr(stats, name) for name in RolloutStats.__dataclass_fields__}


def plan_tasks(jobs: Sequence[RolloutJob], chunk_size: int) -> list[list[tuple[int, RolloutJob]]]:
    """Cut the jobs' rollouts, in job order, into tasks of at most ``chunk_size`` rollouts:
    each task a list of (job index, piece of that job)."""
    tasks, current, room = [], [], chunk_size
    for j, job in enumerate(jobs):
        start = job.start
        while start < job.stop:
            take = min(room, job.stop - start)
            current.append((j, RolloutJob(job.theta, job.key, start, start + take)))
            start += take
            room -= take
            if room == 0:
                tasks.append(current)
                current, room = [], chunk_size
    if current:
        tasks.append(current)
    return tasks


class RayRunner:
    """Runs estimators' rollout jobs on ``workers`` Ray actors (one CPU each).

    Args:
        workers: actors to start, a whole number from 1 to the cluster's CPUs (default: the
            cluster's CPUs; more is a ValueError, as each actor holds one CPU and the extra ones
            would never start). Each keeps the objectives it is sent, with their steppers.
        chunk_size: most rollouts per task (default: ``ceil(total / workers)``, one task per
            actor). Smaller chunks balance uneven machines at a per-task overhead.
        max_retries: restarts of a dead actor, and re-runs of its unfinished tasks.
        address: joins this cluster if Ray is not initialised yet (None: a local cluster on
            127.0.0.1; see :func:`~drake_abs.parallel.cluster.connect`).
    """

    def __init__(
        self,
        workers: int | None = None,
        *,
        chunk_size: int | None = None,
        max_retries: int = 3,
        address: str | None = None,
    ):
        # every argument is checked before a cluster is started or joined
        for name, value in (("workers", workers), ("chunk_size", chunk_size)):
            if value is not None and (isinstance(value, bool) or not isinstance(value, int)
                                      or value < 1):  # fmt: skip
                raise ValueError(f"{name} must be a whole number >= 1 or None; got {value!r}")
        if isinstance(max_retries, bool) or not isinstance(max_retries, int) or max_retries < 0:
            raise ValueError(f"max_retries must be a whole number >= 0; got {max_retries!r}")
        if address is not None and (not isinstance(address, str) or not address.strip()):
            raise ValueError(
                "address must be None (a local cluster), 'auto', 'HOST:PORT' or "
                f"'ray://HOST:PORT'; got {address!r}"
            )
        ray = require_ray()
        if not ray.is_initialized():
            connect(address)
        cpus = cluster_cpus()
        if cpus < 1:
            raise ValueError(
                "the Ray cluster has no CPU, so no worker can start (each takes one); start it "
                "with num_cpus >= 1"
            )
        if workers is not None and workers > cpus:
            # each actor holds one CPU: the actors beyond the cluster's CPUs would never start,
            # and the tasks sent to them would wait for ever
            raise ValueError(
                f"workers must be at most the cluster's CPUs ({cpus}), one CPU per worker; got "
                f"{workers} (give workers=None to use them all)"
            )
        self.workers = workers if workers is not None else cpus
        self.chunk_size = chunk_size
        self.max_retries = max_retries
        actor = ray.remote(_RolloutWorker).options(
            num_cpus=1, max_restarts=max_retries, max_task_retries=max_retries
        )
        self._actors = [actor.remote() for _ in range(self.workers)]
        self._sent: tuple[object, str, object] | None = None  # (objective, key, object ref)
        self.tasks_sent = 0

    # ------------------------------------------------------------------------------ the runner

    def run(
        self, objective, jobs: Sequence[RolloutJob], *, gradient: bool, score: bool
    ) -> list[RolloutStats]:
        """One :class:`RolloutStats` per job, in order (see the module doc for the split)."""
        ray = require_ray()
        jobs = list(jobs)
        if not jobs:
            return []
        self._check_open()
        key, ref = self._objective_ref(objective)
        total = sum(j.size for j in jobs)
        chunk = self.chunk_size or math.ceil(total / self.workers)
        tasks = plan_tasks(jobs, chunk)
        futures = [
            self._actors[i % self.workers].run.remote(
                key, [ref], [piece for _, piece in task], gradient, score
            )
            for i, task in enumerate(tasks)
        ]
        self.tasks_sent += len(futures)
        results = ray.get(futures)
        pieces: list[list[RolloutStats]] = [[] for _ in jobs]
        for task, stats in zip(tasks, results, strict=True):
            for (j, _), s in zip(task, stats, strict=True):
                pieces[j].append(s)
        return [RolloutStats.concatenate(p) for p in pieces]

    def _objective_ref(self, objective) -> tuple[str, object]:
        """The objective's content key and its object-store reference (pickled once per
        objective: the last one is remembered by identity)."""
        if self._sent is not None and self._sent[0] is objective:
            return self._sent[1], self._sent[2]
        ray = require_ray()
        from ray import cloudpickle

        try:
            data = cloudpickle.dumps(objective)
        except Exception as err:
            raise TypeError(
                f"the objective cannot be sent to Ray workers ({type(err).__name__}: {err}); "
                "its stepper, policy and reward must pickle (build a rigid-body stepper from a "
                "scene: make_stepper(scene, ...))"
            ) from err
        key = hashlib.sha256(data).hexdigest()
        ref = ray.put(data)
        self._sent = (objective, key, ref)
        return key, ref

    # ------------------------------------------------------------------------------ inspection

    def pids(self) -> list[int]:
        """The process ids of the actors (in actor order)."""
        ray = require_ray()
        self._check_open()
        return ray.get([a.pid.remote() for a in self._actors])

    def objectives_built(self) -> list[int]:
        """How many objectives (steppers) each actor has unpickled since it (re)started."""
        ray = require_ray()
        self._check_open()
        return ray.get([a.built_count.remote() for a in self._actors])

    def task_overhead(self, repeats: int = 50) -> float:
        """Seconds of one empty task's round trip to an actor (the median of ``repeats``)."""
        ray = require_ray()
        self._check_open()
        ray.get([a.ping.remote() for a in self._actors])  # warm
        times = []
        for k in range(repeats):
            start = time.perf_counter()
            ray.get(self._actors[k % self.workers].ping.remote())
            times.append(time.perf_counter() - start)
        return float(np.median(times))

    # ------------------------------------------------------------------------------- lifetime

    def _check_open(self) -> None:
        if self._actors is None:
            raise RuntimeError("this RayRunner was closed")

    def close(self) -> None:
        """Stop the actors (the cluster stays up)."""
        if self._actors is None:
            return
        ray = require_ray()
        if ray.is_initialized():
            for a in self._actors:
                ray.kill(a, no_restart=True)
        self._actors = None
        self._sent = None

    def __enter__(self) -> RayRunner:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"RayRunner(workers={self.workers}, chunk_size={self.chunk_size})"
