"""Drake LeafSystems that call the numerical core, double and AutoDiffXd (installed as
``drake_abs.systems``). Systems only: the numerics they run live in ``drake_abs``'s subpackages."""

from drake_abs.systems.complementarity_plant import ComplementarityPlant, ComplementarityPlant_
from drake_abs.systems.contact_visualizer import ContactForceVisualizer, ContactForceVisualizer_
from drake_abs.systems.lcs_plant import LcsPlant, LcsPlant_
from drake_abs.systems.point_visualizer import PointMassVisualizer

__all__ = [
    "ComplementarityPlant",
    "ComplementarityPlant_",
    "ContactForceVisualizer",
    "ContactForceVisualizer_",
    "LcsPlant",
    "LcsPlant_",
    "PointMassVisualizer",
]
