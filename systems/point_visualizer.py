"""Draw point masses in Meshcat (for LCS models whose state starts with positions)."""

from __future__ import annotations

import numpy as np
from pydrake.geometry import Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform
from pydrake.systems.framework import LeafSystem


class PointMassVisualizer(LeafSystem):
    """Publishes a sphere at the position held in the first ``dim`` entries of a state vector.

    .. pydrake_system::

        name: PointMassVisualizer
        input_ports:
        - state

    The last state coordinate is vertical; a 2-D state (horizontal, vertical) is drawn in the
    Meshcat x-z plane at depth ``offset[1]``. The sphere's bottom touches the contact point, so a
    ball resting on the ground is drawn on top of it. Transforms are stamped with the context
    time, so they are recorded when ``meshcat.StartRecording()`` is active.

    Args:
        meshcat: the Meshcat instance (bind it to localhost).
        path: Meshcat path of the sphere, e.g. ``"/balls/exact"``.
        dim: number of position coordinates in the state (1, 2 or 3).
        state_size: size of the input state vector.
        period: publish period in seconds.
        radius: sphere radius in m; rgba: colour; offset: added to the drawn position (m).
    """

    def __init__(
        self,
        meshcat: Meshcat,
        path: str,
        *,
        dim: int,
        state_size: int,
        period: float,
        radius: float = 0.03,
        rgba: Rgba | None = None,
        offset=(0.0, 0.0, 0.0),
    ):
        super().__init__()
        if dim not in (1, 2, 3) or state_size < dim:
            raise ValueError(f"dim must be 1, 2 or 3 and <= state_size; got {dim}, {state_size}")
        self._meshcat, self._path, self._dim, self._radius = meshcat, path, dim, radius
        self._offset = np.asarray(offset, dtype=float)
        meshcat.SetObject(path, Sphere(radius), rgba or Rgba(0.2, 0.4, 0.9, 1.0))
        self.state_port = self.DeclareVectorInputPort("state", state_size)
        self.DeclarePeriodicPublishEvent(period, 0.0, self._Publish)
        self.DeclareForcedPublishEvent(self._Publish)

    def _Publish(self, context):
        x = self.state_port.Eval(context)
        p = np.zeros(3)
        axes = {1: [2], 2: [0, 2], 3: [0, 1, 2]}[self._dim]
        p[axes] = x[: self._dim]
        p[2] += self._radius
        X = RigidTransform(p + self._offset)
        self._meshcat.SetTransform(self._path, X, context.get_time())
