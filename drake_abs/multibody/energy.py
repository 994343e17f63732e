"""The mechanical energy of a MultibodyPlant's states: kinetic plus potential (gravity and any
force element's stored energy, as Drake's ``CalcPotentialEnergy`` counts it), in joules."""

from __future__ import annotations

import numpy as np

__all__ = ["mechanical_energy"]


def mechanical_energy(plant, xs) -> np.ndarray:
    """Kinetic plus potential energy (J) of states ``xs`` (N, nq + nv) or one state (nq + nv,)
    of a finalized double ``MultibodyPlant`` (positions, then velocities, Drake's order); returns
    (N,) (or a 0-d array for one state)."""
    xs = np.asarray(xs, dtype=float)
    nx = plant.num_positions() + plant.num_velocities()
    if xs.ndim not in (1, 2) or xs.shape[-1] != nx:
        raise ValueError(f"xs must be (N, nx) or (nx,) states with nx = {nx}; got {xs.shape}")
    context = plant.CreateDefaultContext()
    out = np.empty(xs.shape[:-1])
    for k, x in enumerate(xs.reshape(-1, nx)):
        plant.SetPositionsAndVelocities(context, x)
        out.flat[k] = plant.CalcKineticEnergy(context) + plant.CalcPotentialEnergy(context)
    return out
