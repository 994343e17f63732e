"""Model parameters changed in a Context are simulated (issue 35, item 3): the plant rebuilds its
stepper for the new values, once per distinct value, and the simulation agrees with a plant built
directly with them (a re-written scene or model file)."""

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractValue
from pydrake.systems.analysis import Simulator, Simulator_
from scene_variants import with_friction, with_mass

from drake_abs import ContactAware
from drake_abs.multibody import Scene, build_scene_model
from drake_abs.systems import ComplementarityPlant

T_END = 0.3


@pytest.fixture(scope="module")
def scene():
    return Scene.load("box_push")


def _plant(scene, **options):
    model = build_scene_model(scene)
    return ComplementarityPlant(model.stepper(**options), initial_state=model.x0)


def _simulate(plant, model_values=None, smoothing_values=None, u=3.0):
    context = plant.CreateDefaultContext()
    if model_values is not None:
        context.get_mutable_numeric_parameter(plant.model_parameter_index).SetFromVector(
            model_values
        )
    if smoothing_values is not None:
        context.get_mutable_numeric_parameter(plant.smoothing_parameter_index).SetFromVector(
            smoothing_values
        )
    plant.get_actuation_input_port().FixValue(context, [u])
    Simulator(plant, context).AdvanceTo(T_END)
    return plant.GetPositionsAndVelocities(context)


def _changed(plant, **values):
    names = plant.stepper.parameter_names
    out = plant.stepper.parameter_values().copy()
    for pattern, value in values.items():
        hits = [j for j, n in enumerate(names) if n.startswith(pattern)]
        assert hits, pattern
        out[hits] = value
    return out


def test_changed_friction_is_simulated_as_a_scene_built_with_it(scene):
    plant = _plant(scene)
    direct = _plant(with_friction(scene, 0, -0.2))  # 0.5 -> 0.3 on every corner
    x = _simulate(plant, _changed(plant, friction=0.3))
    np.testing.assert_allclose(x, _simulate(direct), rtol=1e-12, atol=1e-15)
    assert abs(x[0] - _simulate(plant)[0]) > 0.01  # the box does slide farther


def test_changed_mass_is_simulated_as_a_model_file_with_it(scene, tmp_path):
    plant = _plant(scene)
    direct = _plant(with_mass(scene, "box", 2.0, tmp_path))
    mass = plant.stepper.parameter_values()[plant.stepper.parameter_names.index("mass[box]")]
    x = _simulate(plant, _changed(plant, **{"mass[box]": 2.0 * mass}))
    np.testing.assert_allclose(x, _simulate(direct), rtol=1e-12, atol=1e-14)
    assert abs(x[0] - _simulate(plant)[0]) > 0.01  # the same push moves it less


def test_the_rebuilt_stepper_is_cached_by_value(scene, monkeypatch):
    plant = _plant(scene)
    calls = []
    rebuild = plant.stepper.with_parameters

    def spy(values):
        calls.append(np.array(values))
        return rebuild(values)

    monkeypatch.setattr(plant.stepper, "with_parameters", spy)
    light = _changed(plant, friction=0.3)
    x = _simulate(plant, light)  # 30 steps, one rebuild
    assert len(calls) == 1
    np.testing.assert_array_equal(calls[0], light)
    np.testing.assert_array_equal(_simulate(plant, light), x)  # a new Context, same values
    assert len(calls) == 1
    _simulate(plant)  # the built values: the built stepper
    assert len(calls) == 1
    _simulate(plant, _changed(plant, friction=0.2))
    assert len(calls) == 2


def test_smoothing_and_model_changes_share_one_model_rebuild(scene, monkeypatch):
    policy = ContactAware(1e-3, 0.02, 1e-6)
    plant = _plant(scene, smoothing=policy)
    calls = []
    rebuild = plant.stepper.with_parameters
    monkeypatch.setattr(plant.stepper, "with_parameters", lambda v: calls.append(1) or rebuild(v))
    light = _changed(plant, friction=0.3)
    s0 = policy.parameter_values()
    # mu_min: the smoothing of the sliding box, every contact of its LCP in contact
    a = _simulate(plant, light, s0 * np.array([1.0, 1.0, 2.0]))
    b = _simulate(plant, light, s0 * np.array([1.0, 1.0, 4.0]))
    assert len(calls) == 1  # one model rebuild for both smoothings
    assert not np.array_equal(a, b)
    direct = _plant(with_friction(scene, 0, -0.2), smoothing=policy.with_parameters(s0 * [1, 1, 2]))
    np.testing.assert_allclose(a, _simulate(direct), rtol=1e-12, atol=1e-15)


def test_a_refused_value_is_named(scene):
    plant = _plant(scene)
    with pytest.raises(
        ValueError,
        match=r"^ComplementarityPlant: the model parameters in the Context .*"
        r"values\['mass\[box\]'\] must be > 0",
    ):
        _simulate(plant, _changed(plant, **{"mass[box]": -1.0}))


def test_autodiff_context_uses_the_changed_values(scene):
    plant = _plant(scene)
    light = _changed(plant, friction=0.3)
    ad = plant.ToAutoDiffXd()
    context = ad.CreateDefaultContext()
    context.get_mutable_numeric_parameter(ad.model_parameter_index).SetFromVector(light)
    ad.get_actuation_input_port().FixValue(context, [3.0])
    Simulator_[AutoDiffXd](ad, context).AdvanceTo(T_END)
    x = ExtractValue(ad.GetPositionsAndVelocities(context)).ravel()
    np.testing.assert_allclose(x, _simulate(plant, light), rtol=1e-12, atol=1e-15)
