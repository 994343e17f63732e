"""Keyword arguments that a stepper does not take are refused when the plant or the stepper is
built, naming the argument and where the setting belongs (issue 35, item 1)."""

import pytest
from pydrake.systems.framework import DiagramBuilder

from drake_abs.diagrams import AddComplementarityPlantSceneGraph
from drake_abs.multibody import Scene, build_scene_model
from drake_abs.multibody.builder import make_stepper

SCENE_SETTING = r"time_step is a setting of the scene 'box_push'"
HOW = r"Scene\.from_dict\(\{\*\*Scene\.load\('box_push'\)\.to_dict\(\), 'time_step': "


def test_a_scene_setting_given_to_the_diagram_builder_is_refused_at_build_time():
    builder = DiagramBuilder()
    with pytest.raises(ValueError, match=rf"AddComplementarityPlantSceneGraph: .*{SCENE_SETTING}"):
        AddComplementarityPlantSceneGraph(builder, "box_push", time_step=0.001)
    assert not builder.GetSystems()  # refused before anything was added
    with pytest.raises(ValueError, match=HOW + r"0\.001\}\)"):
        AddComplementarityPlantSceneGraph(DiagramBuilder(), "box_push", time_step=0.001)


def test_a_scene_setting_given_to_a_stepper_is_refused_naming_the_scene_key():
    model = build_scene_model("box_push")
    with pytest.raises(ValueError, match=rf"SceneModel\.stepper: .*{SCENE_SETTING}.*{HOW}-0\.01"):
        model.stepper(time_step=-0.01)
    with pytest.raises(
        ValueError, match=r"make_stepper: .*friction_model.*keyword argument friction"
    ):
        make_stepper("box_push", friction_model="anitescu")
    # the suggested form builds the scene with the setting changed
    changed = Scene.from_dict({**Scene.load("box_push").to_dict(), "time_step": 0.001})
    assert make_stepper(changed).model.h == pytest.approx(0.001)


def test_a_misspelt_keyword_is_refused_with_the_accepted_names():
    with pytest.raises(
        ValueError, match=r"unknown stepper option\(s\) \['smothing'\].*'smoothing'"
    ):
        make_stepper("box_push", smothing=None)
    scene = Scene.from_dict({**Scene.load("box_push").to_dict(), "name": "my_box"})
    with pytest.raises(
        ValueError, match=r"scene 'my_box'.*\{\*\*scene\.to_dict\(\), 'ground_height'"
    ):
        build_scene_model(scene).stepper(ground_height=0.1)
