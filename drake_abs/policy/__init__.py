"""Policy gradients through contact: policies, rewards, the batched closed-loop rollout with its
adjoint pass, the estimators (first order, zeroth order, randomised smoothing, ARS, alpha-order),
gradient variance and bias measurement, and training loops.

Drake-free; any batched stepper (an LCS or a rigid-body scene) plugs in.
"""
