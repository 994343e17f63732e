"""A diagram that runs several smoothing designs on the same point-mass LCS side by side, with
logging and (optionally) Meshcat drawing: the bouncing ball of Zhang et al. 2023, Figure 1a."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.geometry import Box, Meshcat, Rgba
from pydrake.math import RigidTransform
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput, VectorLogSink

from drake_abs.contact.lcs import LCS
from drake_abs.contact.smoothing import Smoothing
from drake_abs.diagrams.lcs_simulation import add_lcs_plant
from drake_abs.systems import LcsPlant, PointMassVisualizer

_PALETTE = [
    (0.1, 0.1, 0.1),
    (0.12, 0.47, 0.71),
    (0.17, 0.63, 0.17),
    (0.58, 0.40, 0.74),
    (0.84, 0.15, 0.16),
    (1.0, 0.50, 0.05),
    (0.55, 0.34, 0.29),
    (0.09, 0.75, 0.81),
]


@dataclass(frozen=True)
class PointMassScene:
    """Handles into the built diagram, one entry per case name."""

    diagram: Diagram
    plants: dict[str, LcsPlant]
    state_logs: dict[str, VectorLogSink]
    lam_logs: dict[str, VectorLogSink]


def make_point_mass_scene(
    lcs: LCS,
    cases: dict[str, Smoothing],
    *,
    dim: int,
    u=None,
    meshcat: Meshcat | None = None,
    spacing: float = 0.12,
    radius: float = 0.03,
) -> PointMassScene:
    """One LcsPlant (stepped every ``lcs.time_step`` s) per entry of ``cases`` (name ->
    smoothing), all fed the same constant input ``u`` (zero by default), each logged
    every step; with ``meshcat``, a ground slab and one coloured ball per case, spaced
    ``spacing`` m apart in depth."""
    if not cases:
        raise ValueError("cases must name at least one smoothing")
    time_step = lcs.time_step
    if time_step is None:
        raise ValueError("lcs.time_step is None: build the LCS with its time step")
    nx, nu, _ = lcs.dims
    u = np.zeros(nu) if u is None else np.asarray(u, dtype=float)
    builder = DiagramBuilder()
    plants, state_logs, lam_logs = {}, {}, {}
    if meshcat is not None:
        meshcat.SetObject(
            "/ground", Box(4.0, spacing * (len(cases) + 1), 0.01), Rgba(0.7, 0.7, 0.7, 1)
        )
        meshcat.SetTransform("/ground", RigidTransform([1.0, 0.0, -0.005]))
    for i, (name, smoothing) in enumerate(cases.items()):
        plant = add_lcs_plant(builder, lcs, smoothing, u=u, name=name)
        plants[name] = plant
        state_logs[name] = LogVectorOutput(plant.state_port, builder, time_step)
        lam_logs[name] = LogVectorOutput(plant.impulse_port, builder, time_step)
        if meshcat is not None:
            depth = (i - 0.5 * (len(cases) - 1)) * spacing
            vis = PointMassVisualizer(
                meshcat,
                f"/balls/{name}",
                dim=dim,
                state_size=nx,
                period=time_step,
                radius=radius,
                rgba=Rgba(*_PALETTE[i % len(_PALETTE)], 1.0),
                offset=(0.0, depth, 0.0),
            )
            builder.AddNamedSystem(f"{name}.visualizer", vis)
            builder.Connect(plant.state_port, vis.state_port)
    diagram = builder.Build()
    diagram.set_name("point_mass_scene")
    return PointMassScene(diagram, plants, state_logs, lam_logs)


def palette(i: int) -> tuple[float, float, float]:
    """The colour of case ``i`` (matplotlib and Meshcat use the same)."""
    return _PALETTE[i % len(_PALETTE)]
