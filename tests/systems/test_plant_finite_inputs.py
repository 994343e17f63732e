"""A non-finite discrete state or actuation in a plant's Context is refused naming the plant, the
entry and its value (issue 35, item 6)."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from drake_abs import ContactAware, point_mass_lcs
from drake_abs.diagrams import AddComplementarityPlantSceneGraph
from drake_abs.systems import LcsPlant


def test_an_lcs_plant_names_the_bad_state_entry():
    plant = LcsPlant(point_mass_lcs(2, time_step=0.01), ContactAware(1e-2, 0.05))
    context = plant.CreateDefaultContext()
    context.SetDiscreteState([0.0, np.nan, 1.0, 0.0])
    plant.get_input_port(0).FixValue(context, [0.0, 0.0])
    with pytest.raises(ValueError, match=r"^LcsPlant: the discrete state x must be finite; "
                       r"x\[1\] is nan$"):  # fmt: skip
        Simulator(plant, context).AdvanceTo(0.05)


def test_a_complementarity_plant_names_the_bad_actuation_entry():
    builder = DiagramBuilder()
    plant, _ = AddComplementarityPlantSceneGraph(builder, "box_push", plant_name="box")
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    u = np.zeros(plant.get_input_port(0).size())
    u[-1] = np.inf
    plant.get_input_port(0).FixValue(plant.GetMyContextFromRoot(context), u)
    with pytest.raises(ValueError, match=rf"^ComplementarityPlant 'box': the actuation input u "
                       rf"must be finite; u\[{u.size - 1}\] is inf$"):  # fmt: skip
        Simulator(diagram, context).AdvanceTo(0.05)
