"""Contact steps of Drake MultibodyPlant models: the full step Jacobian (through dM/dq, dJ/dq,
dphi/dq, dN/dq from AutoDiffXd) against central finite differences of the whole step."""

import numpy as np
import pytest
from numdiff import central_difference
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import BaseBodyJointType, MultibodyPlant

from drake_abs import ContactAware, Exact, Fixed
from drake_abs.contact.contact_lcp import contact_step
from drake_abs.multibody.drake_dynamics import (
    GroundPlane,
    MultibodyContactModel,
    PointContact,
)

H = 0.01


def load(path):
    plant = MultibodyPlant(0.0)
    plant.SetBaseBodyJointType(BaseBodyJointType.kRpyFloatingJoint)
    Parser(plant).AddModels(path)
    plant.Finalize()
    return plant


def box_corners(friction):
    return [
        PointContact("box", (sx * 0.2, 0.0, sz * 0.1), 0.0, friction)
        for sx in (-1, 1)
        for sz in (-1, 1)
    ]


SCENES = {
    # a spinning ball landing with friction (floating base, rpy)
    "ball": (
        "drake_abs/models/ball.sdf",
        [PointContact("ball", (0.0, 0.0, 0.0), 0.05, 0.5)],
        4,
        np.array([0.1, 0.2, 0.3, 0.0, 0.0, 0.051]),
        np.array([0.5, -0.3, 0.2, 1.0, 0.2, -1.0]),
    ),
    # the planar box, pushed while landing tilted; friction in its plane only (k = 2)
    "box": (
        "drake_abs/models/box_planar.sdf",
        box_corners(0.6),
        2,
        np.array([0.0, 0.1005, 0.05]),
        np.array([1.0, -0.5, 0.3]),
    ),
    "box_frictionless": (
        "drake_abs/models/box_planar.sdf",
        box_corners(None),
        2,
        np.array([0.0, 0.1005, 0.05]),
        np.array([1.0, -0.5, 0.3]),
    ),
}


@pytest.mark.parametrize("scene", SCENES, ids=SCENES.keys())
@pytest.mark.parametrize("policy", [Exact(), Fixed(1e-5), ContactAware(1e-3, 0.02, 1e-9)], ids=repr)
@pytest.mark.parametrize("friction", ["stewart_trinkle", "anitescu"])
def test_multibody_step_jacobian_matches_finite_differences(scene, policy, friction):
    path, contacts, k, q, v = SCENES[scene]
    model = MultibodyContactModel(load(path), contacts, GroundPlane(), H, directions=k)
    model.cone = model.cone.with_formulation(friction)
    nq, nv, nu = model.nq, model.nv, model.nu
    u = np.full(nu, 2.0)
    r = contact_step(
        model.quantities(q[None], v[None], u[None]), model.cone, H, policy, gradient="total"
    )
    assert r.converged.all()
    assert r.lam[0, : len(contacts)].max() > 1e-3  # the step makes contact

    def step(p):
        quant = model.quantities(p[None, :nq], p[None, nq : nq + nv], p[None, nq + nv :])
        out = contact_step(quant, model.cone, H, policy)
        return np.concatenate([out.q_next[0], out.v_next[0]])

    fd = central_difference(step, np.concatenate([q, v, u]), eps=1e-7)
    analytic = np.concatenate([r.dx_dx[0], r.dx_du[0]], axis=1)
    np.testing.assert_allclose(analytic, fd, atol=1e-6 * (1 + np.abs(fd).max()))
