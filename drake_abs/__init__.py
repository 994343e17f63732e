"""drake-abs: adaptive barrier smoothing for first-order gradients through contact.

The numerical core, one subpackage per concept, each layer importing only the ones above it in
this list (``docs/architecture.md``; ``tests/test_layers.py`` holds the table):

- :mod:`drake_abs.lcp`: the softened LCP, its interior-point solver and Jacobians;
- :mod:`drake_abs.contact`: smoothing designs, linear complementarity systems, the rigid-body
  time-stepping LCP, the one step record;
- :mod:`drake_abs.engine`: the one closed-loop engine (stepper, policy and reward protocols,
  batched rollouts and their reverse pass);
- :mod:`drake_abs.policy`: policies, rewards, gradient estimators (and the baselines PIPPS,
  ARS V2-t, an MBPO-style loop), training;
- :mod:`drake_abs.mpc`: differentiable QP-MPC and gray-box tuning;
- :mod:`drake_abs.learning`: learning contact models from data (the violation-implicit loss,
  the ground-height toy of Bianchini et al. 2022, generalisation bounds);
- :mod:`drake_abs.multibody`: scenes, MultibodyPlant/pinocchio dynamics, the batched rigid-body
  step (the only core subpackage that needs pydrake and pinocchio);
- :mod:`drake_abs.tasks`: the point mass, the translating box, the quadcopter, and gymnasium's
  Hopper-v5 and HalfCheetah-v5 on our plant with a ``gymnasium.Env`` (builds scenes when asked);
- :mod:`drake_abs.parallel`: Ray: the rollout runner, sweeps, starting or joining a cluster.

On top: Drake systems in :mod:`drake_abs.systems`, diagram builders in :mod:`drake_abs.diagrams`,
experiments and the CLI in :mod:`drake_abs.experiments`. The names below are the most used ones.

Direction of smoothing, everywhere in this package: **a larger mu means more smoothing**;
``mu = 0`` is hard contact.

gymnasium: when it is installed, importing this package registers the locomotion tasks'
environments (``gymnasium.make("drake_abs/Hopper-v0")``; :mod:`drake_abs.tasks.gym_registration`),
and ``gymnasium.make("drake_abs:drake_abs/Hopper-v0")`` works with no import of this package.

Threads: the core solves many small dense systems, where a multi-threaded BLAS only adds
overhead and, on a machine whose cores are busy, stalls badly (measured here: a 128 x 128
inverse took 150 ms with two OpenBLAS threads on two shared cores, 1 ms with one). Importing
this package before numpy therefore defaults ``OPENBLAS_NUM_THREADS`` to 1; a value you set
yourself is kept. Batches are where the core's parallelism lives.
"""

import os
import sys

if "numpy" not in sys.modules:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from drake_abs.contact import (
    LCS,
    ContactAware,
    Exact,
    Fixed,
    GaussianMatched,
    LcsStepper,
    Smoothing,
    Step,
    TimeStepScaled,
)
from drake_abs.engine import (
    Adjoints,
    LinearStepper,
    ModelJacobians,
    Policy,
    PullbackPolicy,
    Reward,
    Stepper,
    TimeVaryingPolicy,
    Trajectory,
    TransitionReward,
    ZeroOrderHold,
    open_loop,
    record,
    reverse_pass,
    rollout,
    rollout_memory_bytes,
)
from drake_abs.lcp import (
    LCPConvergenceError,
    LCPConvergenceWarning,
    LCPRegularizationWarning,
    LCPResult,
    LCPStatus,
    MatrixClass,
    softened_lcp_1d,
    solve_lcp,
)
from drake_abs.tasks.gym_registration import register_if_installed as _register_gym_envs
from drake_abs.tasks.point_mass import point_mass_lcs

# gymnasium.make("drake_abs/Hopper-v0") after this import, with no call (gymnasium 1.x loads no
# plugins; the ids are registered with string entry points: no Drake import here)
_register_gym_envs()

__all__ = [
    "LCS",
    "Adjoints",
    "LcsStepper",
    "LinearStepper",
    "ModelJacobians",
    "Policy",
    "PullbackPolicy",
    "Reward",
    "Step",
    "Stepper",
    "TimeVaryingPolicy",
    "Trajectory",
    "TransitionReward",
    "ZeroOrderHold",
    "open_loop",
    "reverse_pass",
    "rollout_memory_bytes",
    "ContactAware",
    "Exact",
    "Fixed",
    "GaussianMatched",
    "LCPConvergenceError",
    "LCPConvergenceWarning",
    "LCPRegularizationWarning",
    "LCPResult",
    "LCPStatus",
    "MatrixClass",
    "Smoothing",
    "TimeStepScaled",
    "point_mass_lcs",
    "record",
    "rollout",
    "softened_lcp_1d",
    "solve_lcp",
]
