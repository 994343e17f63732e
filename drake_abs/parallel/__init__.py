"""Scale-out on Ray: a rollout runner that splits an estimator's rollouts over Ray actors (each
rebuilds the objective's stepper from its scene description once and keeps it), experiment sweeps
(seeds x configurations) as Ray tasks, and starting or joining a Ray cluster.

Ray is an optional dependency (``pip install 'drake-abs[ray]'``); it is imported only when a Ray
runner or a Ray sweep is asked for. Every number a distributed run returns is the one the
single-process run returns for the same seed: the noise of rollout m comes from the seed tree
(:mod:`drake_abs.policy.rollouts`), not from the worker that happens to run it.
"""

from drake_abs.parallel.cluster import connect, shutdown
from drake_abs.parallel.runner import RayRunner
from drake_abs.parallel.sweep import SweepResult, run_sweep

__all__ = ["RayRunner", "SweepResult", "connect", "run_sweep", "shutdown"]
