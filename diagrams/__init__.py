"""Diagram builders composing this package's systems (installed as ``drake_abs.diagrams``)."""

from drake_abs.diagrams.lcs_simulation import (
    DiagramGradient,
    add_lcs_plant,
    make_lcs_diagram,
    simulate_with_gradient,
)
from drake_abs.diagrams.scene_plant import AddComplementarityPlantSceneGraph

__all__ = [
    "AddComplementarityPlantSceneGraph",
    "DiagramGradient",
    "add_lcs_plant",
    "make_lcs_diagram",
    "simulate_with_gradient",
]

# Scene-level builders import heavier modules; import them explicitly:
#   drake_abs.multibody.builder (build_scene_model), drake_abs.reference.drake_twin
#   (make_drake_twin), drake_abs.diagrams.scene_visualization (record_scene, record_rollout_html)
