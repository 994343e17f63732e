"""Diagram builders composing this package's systems (installed as ``drake_abs.diagrams``)."""

from drake_abs.diagrams.lcs_simulation import (
    DiagramGradient,
    add_lcs_plant,
    make_lcs_diagram,
    simulate_with_gradient,
)

__all__ = ["DiagramGradient", "add_lcs_plant", "make_lcs_diagram", "simulate_with_gradient"]
