"""Thin Drake systems that call the numerical core (installed as ``drake_abs.systems``)."""

from drake_abs.systems.complementarity_plant import (
    ComplementarityPlant,
    ComplementarityPlant_,
    ComplementarityStepper,
    StepOverflowWarning,
)
from drake_abs.systems.lcs_plant import LcsPlant, LcsPlant_
from drake_abs.systems.point_visualizer import PointMassVisualizer

__all__ = [
    "ComplementarityPlant",
    "ComplementarityPlant_",
    "ComplementarityStepper",
    "LcsPlant",
    "LcsPlant_",
    "PointMassVisualizer",
    "StepOverflowWarning",
]
