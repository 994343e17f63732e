"""Errors that name what is wrong and where (issue 35, item 6): a non-finite state or actuation
names its entry; a body, frame, joint or model file that a scene file names and its models do
not have names the scene file, the key's line and the key."""

import dataclasses

import numpy as np
import pytest

from drake_abs.multibody import Scene, build_scene_model
from drake_abs.multibody.builder import make_stepper

BOX = Scene.load("box_push").to_yaml()


def _scene_file(tmp_path, text: str):
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    return path


def _line(text: str, needle: str) -> int:
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


def test_a_wrong_body_names_the_scene_file_line_and_key(tmp_path):
    text = BOX.replace("body: box", "body: boxx")
    path = _scene_file(tmp_path, text)
    line = _line(text, "body: boxx")
    with pytest.raises(ValueError) as err:
        build_scene_model(Scene.load(path))
    message = str(err.value)
    assert message.startswith(f"{path}, line {line}: contacts[0].body: no body 'boxx'")
    assert "(did you mean 'box'?)" in message
    # a scene made in Python has no file: the scene's name and the key
    scene = Scene.from_dict(Scene.load(path).to_dict())
    with pytest.raises(ValueError, match=r"^scene 'box_push': contacts\[0\]\.body: no body"):
        build_scene_model(scene)


def test_a_wrong_model_instance_weld_frame_or_actuated_joint_is_named(tmp_path):
    text = BOX.replace("  model: null\n  geometry", "  model: boxes\n  geometry")
    path = _scene_file(tmp_path, text)
    with pytest.raises(ValueError, match=r"line \d+: contacts\[0\]\.model: no model instance"):
        build_scene_model(Scene.load(path))
    scene = Scene.load("box_push")
    model = dataclasses.replace(scene.models[0], weld="nowhere")
    with pytest.raises(ValueError, match=r"^scene 'box_push': models\[0\]\.weld: .* no frame"):
        build_scene_model(dataclasses.replace(scene, models=(model,)))
    model = dataclasses.replace(scene.models[0], actuate=("x", "wheel"))
    with pytest.raises(ValueError, match=r"models\[0\]\.actuate\[1\]: .* no joint 'wheel'"):
        build_scene_model(dataclasses.replace(scene, models=(model,)))


def test_a_missing_model_file_names_the_scene_file_line_and_key(tmp_path):
    text = BOX.replace("models/box_planar.sdf", "models/nope.sdf")
    path = _scene_file(tmp_path, text)
    line = _line(text, "nope.sdf")
    with pytest.raises(FileNotFoundError) as err:
        build_scene_model(Scene.load(path))
    assert str(err.value).startswith(
        f"{path}, line {line}: models[0].file: model file 'package://drake_abs/models/nope.sdf' "
        "not found"
    )
    shipped = Scene.load("box_push").locate("contacts[0].body")
    assert shipped.startswith("shipped scene 'box_push' (") and ", line " in shipped


def test_a_non_finite_state_or_actuation_names_its_entry():
    stepper = make_stepper("box_push")
    nq, nv, nu, _ = stepper.sizes
    x = np.zeros((3, nq + nv))
    x[2, 4] = np.nan
    x[1, 5] = np.inf
    with pytest.raises(ValueError, match=r"^x must be finite; x\[1, 5\] is inf \(batch row 1, "
                       r"column 5\); 2 non-finite entries in all$"):  # fmt: skip
        stepper.step(x, np.zeros(nu))
    u = np.zeros(nu)
    u[-1] = -np.inf
    with pytest.raises(ValueError, match=rf"^u must be finite; u\[{nu - 1}\] is -inf$"):
        stepper.step(np.zeros((3, nq + nv)), u)  # one u for the batch: named as given
    with pytest.raises(ValueError, match=r"^x must be finite; x\[4\] is nan$"):
        stepper.penetration(x[2])
