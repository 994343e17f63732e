"""Diagrams around :class:`~drake_abs.systems.LcsPlant`, and their gradients through AutoDiffXd."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.autodiffutils import AutoDiffXd, InitializeAutoDiff
from pydrake.systems.analysis import Simulator_
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from drake_abs.contact.lcs import LCS, GradientMode
from drake_abs.contact.smoothing import Smoothing
from drake_abs.systems import LcsPlant, autodiff


def add_lcs_plant(
    builder: DiagramBuilder,
    lcs: LCS,
    smoothing: Smoothing | None = None,
    *,
    gradient: GradientMode = "total",
    u=None,
    name: str = "lcs",
) -> LcsPlant:
    """Add an LcsPlant named ``name`` to ``builder`` (stepped every ``lcs.time_step`` s); with
    ``u`` given, feed it a constant input (a ConstantVectorSource named ``name + ".u"``),
    otherwise leave its ``actuation`` port to the caller."""
    plant = builder.AddNamedSystem(name, LcsPlant(lcs, smoothing, gradient))
    if u is not None:
        source = builder.AddNamedSystem(f"{name}.u", ConstantVectorSource(np.asarray(u, float)))
        builder.Connect(source.get_output_port(), plant.actuation_port)
    return plant


def make_lcs_diagram(
    lcs: LCS,
    smoothing: Smoothing | None = None,
    *,
    gradient: GradientMode = "total",
    u=None,
    name: str = "lcs",
) -> Diagram:
    """A diagram of one LcsPlant. Exported ports, namespaced by ``name``: outputs
    ``name.state``, ``name.impulse``, ``name.mu``, ``name.converged``; input
    ``name.actuation`` unless a constant ``u`` is given."""
    builder = DiagramBuilder()
    plant = add_lcs_plant(builder, lcs, smoothing, gradient=gradient, u=u, name=name)
    if u is None:
        builder.ExportInput(plant.actuation_port, f"{name}.actuation")
    for port in (plant.state_port, plant.impulse_port, plant.mu_port, plant.converged_port):
        builder.ExportOutput(port, f"{name}.{port.get_name()}")
    diagram = builder.Build()
    diagram.set_name(f"{name}_diagram")
    return diagram


@dataclass(frozen=True)
class DiagramGradient:
    """Final state of an AutoDiffXd simulation and its Jacobian w.r.t. the initial state."""

    x_final: np.ndarray  # (dx,)
    dx_final_dx0: np.ndarray  # (dx, dx)


def simulate_with_gradient(
    diagram: Diagram, x0, num_steps: int, *, plant_name: str = "lcs"
) -> DiagramGradient:
    """Convert ``diagram`` to AutoDiffXd, seed the LcsPlant's state with the identity, simulate
    ``num_steps`` periodic steps with ``Simulator_[AutoDiffXd]`` and return x_N and dx_N/dx_0."""
    if int(num_steps) < 0:
        raise ValueError(f"num_steps must be >= 0; got {num_steps!r}")
    ad = diagram.ToAutoDiffXd()
    plant = ad.GetSubsystemByName(plant_name)
    x0 = np.asarray(x0, dtype=float)
    simulator = Simulator_[AutoDiffXd](ad)
    context = simulator.get_mutable_context()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetInitialState(plant_context, InitializeAutoDiff(x0.reshape(-1, 1)).ravel())
    simulator.Initialize()
    # periodic events fire at t = 0, h, 2h, ...; the one at t = N h is not taken by AdvanceTo(N h)
    simulator.AdvanceTo(num_steps * plant.time_step)
    x = plant.state_port.Eval(plant_context)
    (value,), (grad,) = autodiff.split([x])
    return DiagramGradient(value, grad)
