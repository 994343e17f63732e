"""The one closed-loop engine: the stepper, policy and reward protocols, batched rollouts
(closed loop, or open loop with given inputs) and their reverse (adjoint) pass, for policy
gradients, MPC tuning and model learning alike.

Drake-free; any batched stepper (an LCS, a rigid-body scene, a quadcopter) plugs in.
"""

from drake_abs.engine.adjoint import Adjoints, reverse_pass
from drake_abs.engine.closed_loop import (
    Trajectory,
    open_loop,
    record,
    rollout,
    rollout_memory_bytes,
)
from drake_abs.engine.protocols import (
    Policy,
    PullbackPolicy,
    Reward,
    Stepper,
    TimeVaryingPolicy,
    TransitionReward,
)
from drake_abs.engine.steppers import LinearStepper, ModelJacobians, ZeroOrderHold

__all__ = [
    "Adjoints",
    "LinearStepper",
    "ModelJacobians",
    "Policy",
    "PullbackPolicy",
    "Reward",
    "Stepper",
    "TimeVaryingPolicy",
    "Trajectory",
    "TransitionReward",
    "ZeroOrderHold",
    "open_loop",
    "record",
    "reverse_pass",
    "rollout",
    "rollout_memory_bytes",
]
