"""Meshcat recording of quadcopter flights with the hector quadrotor (example-robot-data),
Meshcat bound to localhost, written as a self-contained HTML page."""

import re

import numpy as np
import pytest
from pydrake.geometry import Meshcat, MeshcatParams

from drake_abs.diagrams.quadcopter_visualization import hector_urdf, record_quadcopter_html


@pytest.fixture(scope="module")
def meshcat():
    return Meshcat(MeshcatParams(host="localhost"))


def flight(n=6):
    x = np.zeros((n, 12))
    x[:, 0] = np.linspace(0.0, -1.0, n)
    x[:, 6] = np.linspace(0.0, 0.2, n)  # roll
    return x


def test_hector_model_is_installed():
    text = hector_urdf().read_text()
    assert "quadrotor_base.dae" in text


def test_recording_is_a_self_contained_page(meshcat, tmp_path):
    assert "localhost" in meshcat.web_url()
    path = record_quadcopter_html(
        {"a": flight(), "b": flight(4) + 0.5},
        tmp_path / "flights.html",
        target=[-1.0, 0.0, 0.0],
        meshcat=meshcat,
    )
    html = path.read_text()
    assert len(html) > 100_000  # the meshes and the animation are embedded
    assert not re.findall(r"<script[^>]+src=\"https?://", html)  # nothing fetched online
    assert "animation" in html


def test_bad_trajectories_raise(meshcat, tmp_path):
    with pytest.raises(ValueError, match="shape"):
        record_quadcopter_html({"a": np.zeros((3, 11))}, tmp_path / "x.html", meshcat=meshcat)
    with pytest.raises(ValueError, match="finite"):
        record_quadcopter_html(
            {"a": np.full((3, 12), np.nan)}, tmp_path / "x.html", meshcat=meshcat
        )
    with pytest.raises(ValueError, match="entries"):
        record_quadcopter_html({}, tmp_path / "x.html", meshcat=meshcat)
