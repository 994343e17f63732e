"""Drake's model-file parser warnings are reported once per file and process, with what
drake-abs does about each ignored part, and a scene's model files are parsed once per process by
the tasks built on it (issue 35, item 5: a test-size ``drake-abs experiment locomotion`` printed
430 such warnings, 13 per parse of gymnasium's hopper.xml and 30 of half_cheetah.xml)."""

from __future__ import annotations

import logging
from collections import OrderedDict

import pytest

from drake_abs.multibody import build_scene_model, builder, parser_messages
from drake_abs.multibody.parser_messages import summarise_parser_messages
from drake_abs.multibody.scene import Scene
from drake_abs.tasks.locomotion import locomotion_task

REPORTER = "drake_abs.multibody.parser_messages"

# a slider whose MJCF file carries parts Drake ignores: a solver option, a light, a joint spring
MODEL = """<mujoco model="slider">
  <option timestep="0.002"/>
  <worldbody>
    <light pos="0 0 3"/>
    <body name="block">
      <joint name="lift" type="slide" axis="0 0 1" stiffness="{stiffness}"/>
      <geom type="box" size="0.1 0.1 0.1" mass="1" condim="1"/>
    </body>
  </worldbody>
</mujoco>
"""


@pytest.fixture
def fresh_process(monkeypatch):
    """As in a new process: nothing reported yet, no scene model shared yet, and Drake's logger
    at its default level (another test in the same worker may have raised it)."""
    monkeypatch.setattr(parser_messages, "_REPORTED", {})
    drake_logger = logging.getLogger("drake")
    monkeypatch.setattr(drake_logger, "level", logging.NOTSET)
    monkeypatch.setattr(builder, "_SHARED", OrderedDict())


def _scene(tmp_path, stiffness: float = 5.0) -> Scene:
    path = tmp_path / "slider.xml"
    path.write_text(MODEL.format(stiffness=stiffness))
    return Scene.from_dict({
        "name": "slider", "time_step": 0.01, "models": [{"file": str(path), "weld": None}],
        "contacts": [{"body": "block", "points": [[0.0, 0.0, -0.1]], "radius": 0.0}],
    })  # fmt: skip


def _drake_warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == "drake" and r.levelno >= 30]


def _reports(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == REPORTER]


def test_locomotion_tasks_parse_each_file_once_and_report_it_once(
    fresh_process, caplog, capfd, monkeypatch
):
    """Tasks as a test-size locomotion run builds them (one per method and seed, on both
    scenes): Drake's own warnings are held back, and each file gets one report."""
    caplog.set_level(logging.WARNING)
    parsed = []
    real = builder.build_scene_model
    monkeypatch.setattr(
        builder, "build_scene_model", lambda scene: parsed.append(scene.name) or real(scene)
    )
    for name in ("hopper", "half_cheetah", "hopper", "half_cheetah", "hopper"):
        locomotion_task(name)
    assert sorted(parsed) == ["gym_half_cheetah", "gym_hopper"]  # once each
    assert _drake_warnings(caplog) == []
    assert "warning:" not in capfd.readouterr().err  # nothing printed around logging either
    reports = _reports(caplog)
    assert len(reports) == 2
    hopper, cheetah = sorted(reports, key=lambda r: "half_cheetah" in r)
    assert "hopper.xml (13 warnings" in hopper and "half_cheetah.xml (30 warnings" in cheetah
    # what drake-abs does about each ignored part, stated once
    assert "'stiffness' (3 warnings): read by drake-abs" in hopper
    assert "0 with stiffness > 0 in this file" in hopper
    assert "6 with stiffness > 0 in this file" in cheetah
    assert "torsional and rolling friction (8 warnings): not modelled by drake-abs" in cheetah
    assert "condim=1" in hopper and "the scene's declared candidates" in hopper
    assert "<option> attributes: 'timestep', 'integrator'" in hopper
    assert "visual only, no effect on the dynamics: texture, light, camera, visual" in hopper


def test_every_parse_is_summarised_once_per_file(fresh_process, caplog, tmp_path):
    """build_scene_model parses afresh every time; the report is still given once."""
    caplog.set_level(logging.WARNING)
    scene = _scene(tmp_path)
    for _ in range(3):
        build_scene_model(scene)
    assert _drake_warnings(caplog) == []
    (report,) = _reports(caplog)
    assert "slider.xml (4 warnings" in report
    assert "'stiffness' (1 warning): read by drake-abs" in report
    assert "1 with stiffness > 0 in this file" in report
    assert "'timestep'" in report and "light" in report and "condim=1" in report


def test_drakes_own_messages_when_asked(fresh_process, caplog, tmp_path, monkeypatch):
    monkeypatch.setattr(parser_messages, "REPORT_ONCE", False)
    caplog.set_level(logging.WARNING)
    build_scene_model(_scene(tmp_path))
    assert len(_drake_warnings(caplog)) == 4 and _reports(caplog) == []


def test_shared_scene_model_is_built_once_and_again_for_an_edited_file(fresh_process, tmp_path):
    scene = _scene(tmp_path)
    first = builder.shared_scene_model(scene)
    assert builder.shared_scene_model(Scene.from_dict(scene.to_dict())) is first
    steppers = [first.stepper(), builder.shared_scene_model(scene).stepper()]
    assert steppers[0] is not steppers[1]  # each its own stepper on the shared model
    _scene(tmp_path, stiffness=7.0)  # the same path, edited
    second = builder.shared_scene_model(scene)
    assert second is not first
    assert second.model_report()["joints"][0]["stiffness"] == 7.0


def test_unknown_messages_are_kept_verbatim_once():
    messages = [
        "/tmp/copy/a.xml:3: warning: Something new that Drake ignores.",
        "/tmp/copy/a.xml:9: warning: Something new that Drake ignores.",
        "/tmp/copy/a.xml:4: warning: The attribute 'frictionloss' found in a 'joint' tag is "
        "currently unsupported and will be ignored.",
    ]
    report = summarise_parser_messages("a.xml", messages, springs=0, friction=2)
    assert report.count("Something new that Drake ignores.") == 1
    assert "/tmp/copy" not in report  # a temporary copy's path is not the file's
    assert "'frictionloss' (1 warning): read by drake-abs: dry joint friction" in report
    assert "(2 with frictionloss > 0 in this file)" in report


def test_a_dropped_attribute_is_not_claimed_as_modelled():
    message = (
        "a.xml:4: warning: The attribute 'stiffness' found in a 'joint' tag is currently "
        "unsupported and will be ignored."
    )
    dropped = ("joint 'j': stiffness=5 (a joint spring)",)
    report = summarise_parser_messages("a.xml", [message], springs=0, dropped=dropped)
    assert "(none here: the scene's ignore lists joint.stiffness)" in report
    assert "in this file" not in report
