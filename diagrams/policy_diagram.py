"""Plant + policy + reward diagrams, and the return J(theta) with dJ/dtheta of a rollout through
AutoDiffXd.

Any plant of this project (:class:`~drake_abs.systems.LcsPlant`,
:class:`~drake_abs.systems.ComplementarityPlant`) or a diagram holding a Drake MultibodyPlant
(e.g. :func:`~drake_abs.reference.drake_twin.make_drake_twin`) can be closed in the loop: the
builder needs the names of its state output and input ports.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.multibody.plant import MultibodyPlant_
from pydrake.systems.analysis import Simulator, Simulator_
from pydrake.systems.framework import Diagram, DiagramBuilder, System
from pydrake.systems.primitives import LogVectorOutput

from drake_abs.systems import autodiff
from drake_abs.systems.policy_systems import NoiseSource, PolicyController, RewardAccumulator


@dataclass(frozen=True)
class PolicyDiagram:
    """A closed loop: ``diagram`` with subsystems named ``plant``, ``policy``, ``noise`` and
    ``reward``; its exported output ``return`` is the rollout's return so far."""

    diagram: Diagram
    time_step: float
    horizon: int
    monitors_convergence: bool = False  # the plant has a ``converged`` port, logged every step


@dataclass(frozen=True)
class RolloutReturn:
    """The result of :func:`rollout_return`.

    Attributes:
        value: the return J (sum of the stage rewards and the terminal reward).
        gradient: dJ/dtheta (P,), or None when not asked for. NaN when a step did not converge
            and the plant drops such derivatives (its default ``on_unconverged="drop"``).
        converged: whether every step's solve converged; None for a plant that does not say
            (e.g. a Drake MultibodyPlant).
    """

    value: float
    gradient: np.ndarray | None
    converged: bool | None


def build_policy_diagram(
    plant: System,
    policy,
    reward,
    theta,
    noise,
    time_step: float,
    *,
    sigma: float = 0.0,
    state_port: str = "state",
    input_port: str = "actuation",
) -> PolicyDiagram:
    """Close ``plant`` (a System; its ports ``state_port`` (nx) and ``input_port`` (nu)) with
    ``u = pi(x; theta) + sigma xi_t``, xi_t the rows of ``noise`` (H, nu), and accumulate the
    reward. The horizon H is the number of noise rows (at least one). When the plant has a
    ``converged`` output port (the plants of this package), it is logged at every step so that
    :func:`rollout_return` can say whether every solve converged."""
    noise = np.asarray(noise, float)
    if noise.ndim != 2 or noise.shape[0] < 1:
        raise ValueError(
            f"noise must have shape (H, nu) with H >= 1 (the horizon); got {noise.shape}"
        )
    builder = DiagramBuilder()
    builder.AddNamedSystem("plant", plant)
    controller = builder.AddNamedSystem("policy", PolicyController(policy, theta, sigma))
    source = builder.AddNamedSystem("noise", NoiseSource(noise, time_step))
    accumulator = builder.AddNamedSystem("reward", RewardAccumulator(reward, time_step))
    x_port = plant.GetOutputPort(state_port)
    builder.Connect(x_port, controller.state_port)
    builder.Connect(source.get_output_port(), controller.noise_port)
    builder.Connect(controller.u_port, plant.GetInputPort(input_port))
    builder.Connect(x_port, accumulator.state_port)
    builder.Connect(controller.u_port, accumulator.u_port)
    builder.ExportOutput(accumulator.return_port, "return")
    monitors = plant.HasOutputPort("converged")
    if monitors:
        log = LogVectorOutput(plant.GetOutputPort("converged"), builder, float(time_step))
        log.set_name("converged_log")
    return PolicyDiagram(builder.Build(), float(time_step), len(noise), monitors)


def _default_set_state(plant: System, root_context, x0) -> None:
    """x0 into the plant's state: the plants of this package (SetInitialState), or the first
    MultibodyPlant of a diagram (positions and velocities)."""
    if hasattr(plant, "SetInitialState"):
        plant.SetInitialState(plant.GetMyMutableContextFromRoot(root_context), x0)
        return
    for sub in plant.GetSystems() if hasattr(plant, "GetSystems") else ():
        if isinstance(sub, MultibodyPlant_[AutoDiffXd] | MultibodyPlant_[float]):
            sub.SetPositionsAndVelocities(sub.GetMyMutableContextFromRoot(root_context), x0)
            return
    raise TypeError(
        f"cannot set the state of {type(plant).__name__}: pass set_state(plant, root_context, x0)"
    )


def rollout_return(
    pd: PolicyDiagram,
    theta,
    x0,
    *,
    gradient: bool = True,
    set_state: Callable | None = None,
) -> RolloutReturn:
    """The return of H steps from x0 and, with ``gradient``, dJ/dtheta (P,), by simulating the
    diagram converted to AutoDiffXd with theta seeded by the identity.

    Nothing comes back bare: ``converged`` says whether every step's solve converged (for the
    plants that report it); a non-finite return or gradient from steps that all converged
    raises ``FloatingPointError``."""
    set_state = set_state or _default_set_state
    theta = np.asarray(theta, float)
    x0 = np.asarray(x0, float)
    if gradient:
        diagram = pd.diagram.ToAutoDiffXd()
        simulator = Simulator_[AutoDiffXd](diagram)
        th = InitializeAutoDiff(theta.reshape(-1, 1)).ravel()
        x = autodiff.join(x0, np.zeros((x0.size, theta.size)))
    else:
        diagram, simulator, th, x = pd.diagram, Simulator(pd.diagram), theta, x0
    context = simulator.get_mutable_context()
    plant = diagram.GetSubsystemByName("plant")
    controller = diagram.GetSubsystemByName("policy")
    controller.SetTheta(controller.GetMyMutableContextFromRoot(context), th)
    set_state(plant, context, x)
    simulator.Initialize()
    # periodic events fire at t = 0, h, ..., the one at t = H h is not taken by AdvanceTo(H h)
    simulator.AdvanceTo(pd.horizon * pd.time_step)
    J = diagram.GetOutputPort("return").Eval(context)
    converged = None
    if pd.monitors_convergence:
        logger = diagram.GetSubsystemByName("converged_log")
        flags = np.asarray(logger.FindLog(context).data()).ravel()
        flags = np.array([f.value() if isinstance(f, AutoDiffXd) else f for f in flags], float)
        converged = bool(np.all(flags >= 0.5))
    if gradient:
        (value,), (grad,) = autodiff.split([J])
        value, grad = float(value[0]), grad[0]
    else:
        value, grad = float(J[0]), None
    finite = np.isfinite(value) and (grad is None or np.all(np.isfinite(grad)))
    if not finite and converged is not False:
        raise FloatingPointError(
            f"rollout_return: non-finite return {value!r} or gradient from a rollout whose "
            "steps all converged (the state left the finite numbers?)"
        )
    return RolloutReturn(value, grad, converged)
