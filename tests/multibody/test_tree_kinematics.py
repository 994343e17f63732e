"""The compiled tree kinematics (drake_abs/multibody/tree_kinematics.py) against pinocchio's own
forwardKinematics: every joint of every shipped scene the batched pinocchio path serves, at
random configurations, and trees of pinocchio's axis-aligned joints."""

from __future__ import annotations

import logging
import warnings

import numpy as np
import pinocchio as pin
import pytest

from drake_abs import Exact
from drake_abs.multibody.builder import build_scene_model
from drake_abs.multibody.scene import Scene, shipped_scenes
from drake_abs.multibody.tree_kinematics import TreeKinematics


def _pinocchio_placements(model: pin.Model, q: np.ndarray) -> np.ndarray:
    data = model.createData()
    out = np.empty((len(q), model.njoints, 4, 4))
    for b, qb in enumerate(q):
        pin.forwardKinematics(model, data, qb)
        for j in range(model.njoints):
            out[b, j] = data.oMi[j].homogeneous
    return out


def _models():
    for name in shipped_scenes():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            logging.disable(logging.WARNING)
            try:
                model = build_scene_model(Scene.load(name)).stepper(smoothing=Exact()).model
            finally:
                logging.disable(logging.NOTSET)
        if getattr(model, "pin_model", None) is not None and model._coords is None:
            yield name, model


@pytest.mark.parametrize("name", [name for name, _ in _models()])
def test_every_joint_matches_pinocchio_on_shipped_scenes(name):
    model = dict(_models())[name]
    tree = TreeKinematics.of(model.pin_model)
    assert tree is not None
    rng = np.random.default_rng(7)
    q = rng.uniform(-3.0, 3.0, size=(16, model.pin_model.nq))
    ids = np.arange(model.pin_model.njoints)
    ours = tree.placements(q, ids)
    np.testing.assert_allclose(ours, _pinocchio_placements(model.pin_model, q), rtol=0, atol=1e-13)
    # and the contact model uses them: its distances are pinocchio's
    centres = model._batch_centres(_pinocchio_placements(model.pin_model, q)[:, model._carriers])
    expected = centres @ model.normal - model._radius - model.ground.height
    np.testing.assert_allclose(model.distances(q), expected, rtol=0, atol=1e-13)


def test_axis_aligned_and_prismatic_joints():
    model = pin.buildSampleModelManipulator()  # RX, RY, RZ joints
    placement = pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.5])), np.array([0.1, 0.2, -0.3]))
    j = model.addJoint(model.njoints - 1, pin.JointModelPY(), placement, "py")
    model.addJoint(j, pin.JointModelPrismaticUnaligned(np.array([0.0, 0.6, 0.8])), placement, "pu")
    tree = TreeKinematics.of(model)
    q = np.random.default_rng(1).uniform(-2.0, 2.0, size=(5, model.nq))
    ids = np.arange(model.njoints)
    np.testing.assert_allclose(
        tree.placements(q, ids), _pinocchio_placements(model, q), rtol=0, atol=1e-13
    )


def test_a_free_flyer_is_not_handled():
    model = pin.Model()
    model.addJoint(0, pin.JointModelFreeFlyer(), pin.SE3.Identity(), "base")
    assert TreeKinematics.of(model) is None
