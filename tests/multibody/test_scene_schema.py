"""Scene files read against a typed schema (Drake's ``yaml_load_typed`` with the dataclasses of
:class:`drake_abs.multibody.scene.Scene`): every error from a bad file is a ``ValueError``
naming the file, the line, the key and the expected form; package data is addressed by name
(``Scene.load("box_push")``, ``package://drake_abs/models/...``) from any working directory."""

import dataclasses
import importlib.util
import textwrap

import pytest
from pydrake.common.yaml import yaml_load_data

import drake_abs.multibody.scene as scene_module
from drake_abs.contact.smoothing import ContactAware, Fixed
from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.packages import PACKAGE_DIR, package_folders
from drake_abs.multibody.parsing import resolve_model_file
from drake_abs.multibody.scene import (
    SMOOTHING_KINDS,
    ContactSpec,
    InitialState,
    ModelSpec,
    PairSpec,
    Scene,
    shipped_scenes,
)

# line numbers below count from 1 at "name:"
GOOD = textwrap.dedent("""\
    name: box
    time_step: 0.01
    models:
      - file: package://drake_abs/models/box_planar.sdf
    contacts:
      - body: box
        points: [[-0.2, 0.0, -0.1], [0.2, 0.0, -0.1]]
        friction: 0.5
    friction_directions: 2
    smoothing: {kind: fixed, value: 1.0e-4}
    initial_state: {q: [0.0, 0.1, 0.0], v: [1.0, 0.0, 0.0]}
""")


def _error(tmp_path, text: str, name: str = "bad.yaml") -> tuple[str, str]:
    """The message of the error loading ``text`` from a file, and the file's path."""
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ValueError) as err:
        Scene.from_yaml(path)
    assert type(err.value) is ValueError  # not a subclass from yaml or Drake
    return str(err.value), str(path)


def test_the_good_file_loads_and_equals_the_scene_built_in_python(tmp_path):
    path = tmp_path / "good.yaml"
    path.write_text(GOOD)
    expected = Scene(
        "box",
        (ModelSpec("package://drake_abs/models/box_planar.sdf"),),
        (ContactSpec("box", ((-0.2, 0.0, -0.1), (0.2, 0.0, -0.1)), friction=0.5),),
        friction_directions=2,
        smoothing={"kind": "fixed", "value": 1e-4},
        initial_state={"q": (0.0, 0.1, 0.0), "v": (1.0, 0.0, 0.0)},
    )
    assert Scene.from_yaml(path) == expected
    assert Scene.from_yaml(GOOD) == expected  # YAML text
    assert expected.make_smoothing() == Fixed(1e-4)


def test_the_file_is_read_by_drakes_yaml_load_typed_with_the_schema(monkeypatch):
    original = scene_module.yaml_load_typed
    calls = []

    def spy(**kwargs):
        calls.append(kwargs)
        return original(**kwargs)

    monkeypatch.setattr(scene_module, "yaml_load_typed", spy)
    Scene.from_yaml(GOOD)
    assert len(calls) == 1
    assert calls[0]["schema"] is scene_module._SceneFile
    assert calls[0]["allow_yaml_with_no_schema"] is False
    # the file's data, every key given, the smoothing's kind as the tag of the union's member
    read = yaml_load_data(calls[0]["data"])
    assert read["smoothing"] == {"_tag": "!FixedSmoothingFile", "value": 1e-4,
                                 "reference_time_step": None}  # fmt: skip
    assert read["contacts"][0]["points"] == [[-0.2, 0.0, -0.1], [0.2, 0.0, -0.1]]
    assert read["initial_state"] == {"q": [0.0, 0.1, 0.0], "v": [1.0, 0.0, 0.0]}
    assert set(read) == {f.name for f in dataclasses.fields(Scene)}


def test_keys_left_out_take_the_scene_defaults():
    minimal = "name: m\nmodels: [{file: a.sdf}]\ncontacts: [{body: b, points: [[0, 0, 0]]}]\n"
    assert Scene.from_yaml(minimal) == Scene(
        "m", (ModelSpec("a.sdf"),), (ContactSpec("b", ((0.0, 0.0, 0.0),)),)
    )


def test_the_schema_is_the_scene_and_each_key_is_documented_once():
    # Drake's reader fills in a twin made from the Scene's own fields
    names = [f.name for f in dataclasses.fields(scene_module._SceneFile)]
    assert names == [f.name for f in dataclasses.fields(Scene)]
    # each kind of smoothing takes its policy's parameters, and the reference time step
    assert sorted(SMOOTHING_KINDS) == ["contact_aware", "exact", "fixed", "gaussian_matched"]
    for member in SMOOTHING_KINDS.values():
        own = {f.name for f in dataclasses.fields(member)} - {"reference_time_step"}
        assert own == {f.name for f in dataclasses.fields(member.smoothing_type) if f.name != "g"}
    # every key has its form and is listed, with it, in its class's docstring (the API reference)
    for schema in (Scene, ModelSpec, ContactSpec, PairSpec, InitialState,
                   *SMOOTHING_KINDS.values()):  # fmt: skip
        for f in dataclasses.fields(schema):
            assert f.metadata["form"], (schema.__name__, f.name)
            assert f"    {f.name}: {f.metadata['form']}" in schema.__doc__, (schema, f.name)


def test_a_mistyped_key_is_named_with_its_line_and_the_key_meant(tmp_path):
    message, path = _error(tmp_path, GOOD.replace("time_step:", "time_stpe:"))
    assert message.startswith(f"{path}, line 2: unknown key 'time_stpe'")
    assert "(did you mean 'time_step'?)" in message
    message, _ = _error(tmp_path, GOOD.replace("    friction: 0.5", "    frction: 0.5"))
    assert "line 8: unknown key 'contacts[0].frction' (did you mean 'contacts[0].friction'?)" in (
        message
    )


def test_a_point_of_two_coordinates_is_named_with_the_form_expected(tmp_path):
    message, path = _error(tmp_path, GOOD.replace("[0.2, 0.0, -0.1]]", "[0.2, 0.0]]"))
    assert message == (
        f"{path}, line 7: contacts[0].points[1] must be a point [x, y, z]: 3 numbers (m, in the "
        "body's frame); got a list of 2: [0.2, 0.0]"
    )


@pytest.mark.parametrize(
    ("old", "new", "line", "key", "form"),
    [
        ("time_step: 0.01", "time_step: fast", 2, "time_step", "a number > 0: the time step (s)"),
        ("time_step: 0.01", "time_step: '0.01'", 2, "time_step", "a number > 0"),  # quoted
        ("time_step: 0.01", "time_step: yes", 2, "time_step", "a number > 0"),  # a boolean
        ("friction: 0.5", "friction: high", 8, "contacts[0].friction", "a number >= 0"),
        ("[0.2, 0.0, -0.1]]", "[0.2, '0', -0.1]]", 7, "contacts[0].points[1]",
         "a point [x, y, z]: 3 numbers"),
        ("friction_directions: 2", "friction_directions: 2.5", 9, "friction_directions",
         "an integer >= 2"),
        ("value: 1.0e-4", "value: small", 10, "smoothing.value", "a number >= 0"),
        ("q: [0.0, 0.1, 0.0]", "q: [0.0, x, 0.0]", 11, "initial_state.q", "a list of numbers"),
    ],
)  # fmt: skip
def test_a_string_where_a_number_is_expected_is_named(tmp_path, old, new, line, key, form):
    assert old in GOOD
    message, path = _error(tmp_path, GOOD.replace(old, new))
    assert message.startswith(f"{path}, line {line}: {key} must be {form}")
    assert "; got " in message


def test_a_missing_required_key_is_named_with_its_form(tmp_path):
    text = GOOD.replace("models:\n  - file: package://drake_abs/models/box_planar.sdf\n", "")
    message, path = _error(tmp_path, text)
    assert message.startswith(f"{path}: models is missing")
    assert "a list of model entries, each {file: package://<package>/<path>" in message
    message, _ = _error(tmp_path, GOOD.replace("  - body: box\n    points", "  - points"))
    assert "line 6: contacts[0].body is missing: contacts[0] needs it, as a body's name" in (
        message
    )


@pytest.mark.parametrize(
    ("old", "new", "line", "key", "form"),
    [
        ("smoothing: {kind: fixed, value: 1.0e-4}", "smoothing: [fixed, 1.0e-4]", 10,
         "smoothing", "a mapping {kind: one of"),
        ("initial_state: {q:", "initial_state: [{q:", 11, "initial_state",
         "a mapping {q: [...], v: [...]}"),
        ("  - file: package://drake_abs/models/box_planar.sdf",
         "  - [package://drake_abs/models/box_planar.sdf]", 4, "models[0]",
         "a model entry: a mapping {file: ..."),
        ("models:\n  - file: package://drake_abs/models/box_planar.sdf",
         "models:\n  file: package://drake_abs/models/box_planar.sdf", 3, "models",
         "a list of model entries"),
    ],
)  # fmt: skip
def test_a_list_where_a_mapping_is_expected_is_named(tmp_path, old, new, line, key, form):
    assert old in GOOD
    text = GOOD.replace(old, new)
    if new.endswith("[{q:"):
        text = text.replace("0.0]}\n", "0.0]}]\n")
    message, path = _error(tmp_path, text)
    assert message.startswith(f"{path}, line {line}: {key} must be {form}")


def test_an_unknown_smoothing_kind_is_named_with_the_kinds(tmp_path):
    message, path = _error(tmp_path, GOOD.replace("kind: fixed", "kind: magic"))
    assert message == (
        f"{path}, line 10: smoothing.kind must be one of ['contact_aware', 'exact', 'fixed', "
        "'gaussian_matched']; got 'magic' (text)"
    )
    # a parameter of another kind is named with the kind's own ones
    message, _ = _error(tmp_path, GOOD.replace("value: 1.0e-4", "length: 0.1"))
    assert "line 10: smoothing: bad smoothing parameters {'length': 0.1} for kind 'fixed', " in (
        message
    )
    assert "which takes ['value']" in message


@pytest.mark.parametrize(
    ("old", "new", "line"),
    [
        ("[0.2, 0.0, -0.1]]", "[0.2, 0.0, -0.1]", 8),  # an unclosed list: found at the next key
        ("friction: 0.5", "friction: 0.5\n   oops: : 1", 9),
        ("name: box", "name: box\n\tmodels: 1", 2),  # a tab
    ],
)
def test_malformed_yaml_is_named_with_its_line(tmp_path, old, new, line):
    message, path = _error(tmp_path, GOOD.replace(old, new))
    assert message.startswith(f"{path}, line {line}, column ")
    assert ": not valid YAML: " in message
    assert "Traceback" not in message


def test_values_the_scene_refuses_are_named_with_file_and_line(tmp_path):
    message, path = _error(tmp_path, GOOD.replace("time_step: 0.01", "time_step: -1"))
    assert message == f"{path}, line 2: time_step must be a number > 0 (s); got -1.0"
    message, _ = _error(tmp_path, GOOD.replace("friction: 0.5", "friction: .nan"))
    assert message.startswith(f"{path}, line 8: contacts[0].friction must be a finite number")
    message, _ = _error(tmp_path, GOOD.replace("friction: 0.5", "radius: -0.1"))
    assert message.startswith(f"{path}, line 8: contacts[0].radius must be a finite number >= 0")


def test_duplicate_keys_tags_and_other_roots_are_refused(tmp_path):
    message, path = _error(tmp_path, GOOD + "time_step: 0.02\n")
    assert message == f"{path}, line 12: time_step is given twice (also at line 2)"
    message, _ = _error(tmp_path, GOOD.replace("smoothing: {", "smoothing: !Fixed {"))
    assert message.startswith(f"{path}, line 10: smoothing has the YAML tag '!Fixed'")
    message, _ = _error(tmp_path, "- name: box\n")
    assert message.startswith(f"{path}: a scene must be a mapping {{name: ..., models: [...]")
    message, _ = _error(tmp_path, "# empty\n")
    assert message.endswith("got null")


def test_yaml_anchors_and_underscore_keys_are_read():
    text = "_corner: &c [0.2, 0.0, -0.1]\n" + GOOD.replace("[0.2, 0.0, -0.1]]", "*c]")
    assert Scene.from_yaml(text) == Scene.from_yaml(GOOD)


def test_errors_in_yaml_text_and_shipped_scenes_name_their_source(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match=r"^scene YAML text, line 2: unknown key 'time_stpe'"):
        Scene.from_yaml(GOOD.replace("time_step:", "time_stpe:"))
    (tmp_path / "broken.yaml").write_text(GOOD.replace("kind: fixed", "kind: magic"))
    monkeypatch.setattr(scene_module, "SCENES_DIR", tmp_path)
    assert shipped_scenes() == ["broken"]
    with pytest.raises(ValueError) as err:
        Scene.load("broken")
    assert str(err.value).startswith(
        f"shipped scene 'broken' ({tmp_path / 'broken.yaml'}), line 10: smoothing.kind must be"
    )


def test_unknown_packages_are_named_with_file_key_and_the_known_packages(tmp_path):
    text = GOOD.replace("package://drake_abs/", "package://drake_abz/")
    message, path = _error(tmp_path, text)
    assert message.startswith(f"{path}, line 4: models[0].file: unknown package 'drake_abz' in ")
    assert "(did you mean 'drake_abs'?)" in message
    assert "known package: drake_abs" in message
    message, _ = _error(tmp_path, GOOD.replace("package://drake_abs/models/box_planar.sdf",
                                               "package://drake_abs"))  # fmt: skip
    assert (
        "models[0].file: 'package://drake_abs' is not of the form package://<package>/<path>"
        in (message)
    )
    # a scene built in Python: refused when its plant is built, naming scene and key
    scene = Scene.from_yaml(GOOD)
    bad = dataclasses.replace(scene, models=(ModelSpec("package://nowhere/box.sdf"),))
    with pytest.raises(ValueError, match=r"^scene 'box': models\[0\].file: unknown package"):
        build_scene_model(bad)


def test_a_missing_packaged_file_is_file_not_found():
    spec = ModelSpec("package://drake_abs/models/none.sdf")
    with pytest.raises(FileNotFoundError, match="model file 'package://drake_abs/models/none.sdf'"):
        resolve_model_file(spec)


def test_shipped_scenes_load_by_name_and_uri_from_any_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    for name in shipped_scenes():
        scene = Scene.load(name)
        assert scene.name == name
        assert Scene.load(f"package://drake_abs/scenes/{name}.yaml") == scene
    model = build_scene_model("box_push")  # its model file by package URI, from tmp_path
    assert model.plant.num_positions() == 3
    # a repository-relative path does not load from elsewhere, and says what does
    with pytest.raises(FileNotFoundError, match=r"Scene.load\('box_push'\)"):
        Scene.load("drake_abs/scenes/box_push.yaml")


def test_package_uris_resolve_through_the_package_map_to_the_installed_files():
    box = resolve_model_file(ModelSpec("package://drake_abs/models/box_planar.sdf"))
    assert box == PACKAGE_DIR / "models" / "box_planar.sdf"
    folders = package_folders()
    assert folders["drake_abs"] == PACKAGE_DIR
    if "example-robot-data" in folders:
        go1 = "go1_description/urdf/go1.urdf"
        by_uri = resolve_model_file(ModelSpec(f"package://example-robot-data/robots/{go1}"))
        by_robot = resolve_model_file(ModelSpec(f"package://{go1}"))
        assert by_uri == by_robot == folders["example-robot-data"] / "robots" / go1
        assert by_uri.is_file()
    if importlib.util.find_spec("gymnasium") is not None:
        hopper = resolve_model_file(ModelSpec("package://gymnasium/hopper.xml"))
        assert hopper.name == "hopper.xml" and hopper.parent.name == "assets"


@pytest.mark.parametrize(
    ("alias", "uri", "package"),
    [
        ("drake_abs:models/box_planar.sdf", "package://drake_abs/models/box_planar.sdf", None),
        (
            "example-robot-data:ur_description/urdf/ur5_robot.urdf",
            "package://example-robot-data/robots/ur_description/urdf/ur5_robot.urdf",
            "example-robot-data",
        ),
        ("gymnasium:hopper.xml", "package://gymnasium/hopper.xml", "gymnasium"),
    ],
)
def test_the_old_prefixes_are_aliases_of_the_package_uris(alias, uri, package):
    # both are installed by the project's set-up (a dependency, and the dev extra): a missing
    # one is a broken install, not a reason to skip
    assert package is None or package in package_folders(), package
    assert resolve_model_file(ModelSpec(alias)) == resolve_model_file(ModelSpec(uri))
    # and a scene file may still use them
    text = GOOD.replace("package://drake_abs/models/box_planar.sdf", alias)
    assert Scene.from_yaml(text).models[0].file == alias


def test_from_dict_checks_against_the_same_schema():
    data = Scene.from_yaml(GOOD).to_dict()
    assert Scene.from_dict(data) == Scene.from_yaml(GOOD)
    data["contacts"][0]["points"] = [[0.1, 0.2]]
    with pytest.raises(ValueError, match=r"^scene 'box': contacts\[0\].points\[0\] must be a "):
        Scene.from_dict(data)
    with pytest.raises(ValueError, match=r"did you mean 'smoothing.length'"):
        Scene.from_dict({
            **Scene.from_yaml(GOOD).to_dict(),
            "smoothing": {"kind": "contact_aware", "mu_max": 1.0, "lenght": 0.1},
        })  # fmt: skip
    ok = {**Scene.from_yaml(GOOD).to_dict(),
          "smoothing": {"kind": "contact_aware", "mu_max": 1.0, "length": 0.1}}  # fmt: skip
    assert Scene.from_dict(ok).make_smoothing() == ContactAware(1.0, 0.1)
