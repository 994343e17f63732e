"""Policy files (drake_abs.policy.policy_files): the published npz format of a policy of an
observation.

Round trips keep every array and the metadata; bad files are refused with a ValueError naming
the key; a linear file's action is clip(W (o - obs_mean) / obs_std + b) and an MLP's the layers
written out here; this package's policies convert to files that act as they do; FilePolicy's
Jacobians match central differences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from drake_abs.engine.protocols import Policy
from drake_abs.policy.ars_v2 import NormalizedLinearPolicy
from drake_abs.policy.policies import LinearPolicy, MLPPolicy
from drake_abs.policy.policy_files import (
    ACTIVATIONS,
    FilePolicy,
    PolicyFile,
    is_policy_file,
    load_policy_file,
    published_path,
    to_policy_file,
)


def _linear(rng, n_obs=5, nu=3, **metadata) -> PolicyFile:
    return PolicyFile.linear(
        rng.standard_normal((nu, n_obs)), rng.standard_normal(nu), rng.standard_normal(n_obs),
        rng.uniform(0.5, 2.0, n_obs), **metadata,
    )  # fmt: skip


def _mlp(rng, activation="tanh", sizes=(5, 4, 6, 2), **metadata) -> PolicyFile:
    layers = [(0.7 * rng.standard_normal((m, n)), 0.1 * rng.standard_normal(m))
              for n, m in zip(sizes[:-1], sizes[1:], strict=True)]  # fmt: skip
    return PolicyFile.mlp(layers, activation, rng.standard_normal(sizes[0]),
                          rng.uniform(0.5, 2.0, sizes[0]), **metadata)  # fmt: skip


def _arrays(file: PolicyFile, **changes) -> dict:
    arrays = file.arrays()
    for key, value in changes.items():
        if value is None:
            arrays.pop(key)
        else:
            arrays[key] = value
    return arrays


def _save_raw(path, arrays) -> str:
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)
    return str(path)


# ---------------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("kind", ["linear", "mlp"])
def test_save_load_roundtrip_keeps_every_array_and_the_metadata(kind, rng, tmp_path):
    meta = dict(env_id="Hopper-v5", method="fopg_abs", seed=3, training_steps=123456,
                drake_abs_version="0.1.0", ratio=0.25, flag=True)  # fmt: skip
    file = _linear(rng, **meta) if kind == "linear" else _mlp(rng, "relu", **meta)
    path = file.save(tmp_path / "sub" / "seed3.npz")
    assert is_policy_file(path)
    back = load_policy_file(path)
    assert back.kind == kind and back.activation == file.activation
    for a, b in zip((*file.weights, *file.biases), (*back.weights, *back.biases), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(back.obs_mean, file.obs_mean)
    np.testing.assert_array_equal(back.obs_std, file.obs_std)
    assert dict(back.metadata) == meta
    assert all(type(back.metadata[k]) is type(v) for k, v in meta.items())
    obs = rng.standard_normal((7, file.n_obs))
    np.testing.assert_array_equal(back.act(obs), file.act(obs))
    with np.load(path) as raw:  # the keys of the published format, plain arrays
        expected = {"W", "b"} if kind == "linear" else {"W0", "b0", "W1", "b1", "W2", "b2",
                                                        "activation"}  # fmt: skip
        assert set(raw.files) == expected | {"obs_mean", "obs_std"} | set(meta)
        assert raw["env_id"].shape == () and str(raw["env_id"]) == "Hopper-v5"


def test_save_needs_an_npz_suffix(rng, tmp_path):
    with pytest.raises(ValueError, match=r"path must end in \.npz"):
        _linear(rng).save(tmp_path / "policy.npy")


# ------------------------------------------------------------------------------------ the formula


def test_a_linear_files_action_is_the_formula(rng):
    file = _linear(rng, n_obs=6, nu=4)
    obs = 3.0 * rng.standard_normal((50, 6))
    W, b = file.weights[0], file.biases[0]
    by_hand = np.array([np.clip(W @ ((o - file.obs_mean) / file.obs_std) + b, -1.0, 1.0)
                        for o in obs])  # fmt: skip
    np.testing.assert_allclose(file.act(obs), by_hand, rtol=0, atol=1e-14)
    assert np.any(np.abs(by_hand) == 1.0) and np.any(np.abs(by_hand) < 1.0)  # both cases ran
    np.testing.assert_allclose(file.act(obs[0]), by_hand[0], rtol=0, atol=1e-14)  # one obs
    low, high = np.array([-0.5, -1, -2, -0.1]), np.array([0.5, 1, 2, 0.1])
    np.testing.assert_allclose(file.act(obs, low, high), np.clip(file.output(obs), low, high))


@pytest.mark.parametrize("activation", sorted(ACTIVATIONS))
def test_an_mlp_files_action_is_its_layers(activation, rng):
    file = _mlp(rng, activation)
    f = {"tanh": np.tanh, "relu": lambda z: np.maximum(z, 0), "identity": lambda z: z,
         "elu": lambda z: np.where(z > 0, z, np.exp(z) - 1),
         "sigmoid": lambda z: 1 / (1 + np.exp(-z))}[activation]  # fmt: skip
    obs = rng.standard_normal((20, file.n_obs))
    for o in obs:
        h = (o - file.obs_mean) / file.obs_std
        for W, b in zip(file.weights[:-1], file.biases[:-1], strict=True):
            h = f(W @ h + b)
        out = file.weights[-1] @ h + file.biases[-1]
        np.testing.assert_allclose(file.output(o), out, rtol=1e-13, atol=1e-14)
        np.testing.assert_allclose(file.act(o), np.clip(out, -1, 1), rtol=1e-13, atol=1e-14)


def test_obs_of_the_wrong_size_is_refused(rng):
    with pytest.raises(ValueError, match=r"obs must have shape \(n_obs,\) or \(M, n_obs\) with "
                                         r"n_obs = 5"):  # fmt: skip
        _linear(rng).act(np.zeros(4))


# ------------------------------------------------------------------------------------ bad files


def _bad_cases(rng):
    lin, mlp = _linear(rng), _mlp(rng)
    return {
        "no obs_std": (_arrays(lin, obs_std=None), "no 'obs_std'"),
        "no obs_mean": (_arrays(mlp, obs_mean=None), "no 'obs_mean'"),
        "b of the wrong size": (_arrays(lin, b=np.zeros(4)), r"b must have shape \(3,\)"),
        "W not 2-D": (_arrays(lin, W=np.zeros(15)), r"W must have shape \(nu, n_obs\)"),
        "obs_mean of the wrong size": (_arrays(lin, obs_mean=np.zeros(4)),
                                       r"obs_mean must have shape \(n_obs,\) = \(5,\)"),
        "obs_std zero": (_arrays(lin, obs_std=np.array([1.0, 1, 0, 1, 1])),
                         r"obs_std must be > 0 in every entry \(it divides the observation\); "
                         r"entry 2 is 0\.0"),
        "NaN weight": (_arrays(lin, W=np.full((3, 5), np.nan)), "W contains NaN"),
        "string weights": (_arrays(lin, W=np.array([["a"] * 5] * 3)), "W must be a real numeric"),
        "no layers": ({"obs_mean": np.zeros(2), "obs_std": np.ones(2)}, "no layers"),
        "linear without b": (_arrays(lin, b=None), "no 'b'"),
        "linear with activation": (_arrays(lin, activation=np.array("tanh")),
                                   "'activation' belongs to an MLP"),
        "W and W0": (_arrays(lin, W0=np.zeros((3, 5)), b0=np.zeros(3)), "not both"),
        "a gap in the layers": (_arrays(mlp, W1=None, b1=None), r"missing \['W1'\]"),
        "a bias without its W": (_arrays(mlp, b3=np.zeros(2)), r"\['b3'\] without W"),
        "layers that do not chain": (_arrays(mlp, W1=np.zeros((6, 3))),
                                     r"W1 must have shape \(n_2, n_1\) = \(n_2, 4\)"),
        "no activation": (_arrays(mlp, activation=None), "no 'activation'"),
        "unknown activation": (_arrays(mlp, activation=np.array("swish")),
                               "activation must be one of"),
        "activation not a string": (_arrays(mlp, activation=np.array(1.0)),
                                    "activation must be a 0-d string"),
        "metadata not 0-d": (_arrays(lin, extra=np.zeros(3)), "metadata key 'extra' must be a 0-d"),
        "metadata bytes": (_arrays(lin, note=np.array(b"x")), "metadata key 'note' must hold"),
    }  # fmt: skip


@pytest.mark.parametrize("case", list(_bad_cases(np.random.default_rng(0))))
def test_bad_files_are_refused_naming_the_key(case, tmp_path):
    arrays, message = _bad_cases(np.random.default_rng(0))[case]
    path = _save_raw(tmp_path / "bad.npz", arrays)
    with pytest.raises(ValueError, match=message) as err:
        load_policy_file(path)
    assert str(err.value).startswith(path)  # the file is named too


def test_files_that_are_not_policy_archives_are_refused(tmp_path):
    text = tmp_path / "text.npz"
    text.write_text("not an archive")
    with pytest.raises(ValueError, match="is not a policy file"):
        load_policy_file(text)
    single = tmp_path / "single.npz"
    with single.open("wb") as handle:
        np.save(handle, np.zeros(3))
    with pytest.raises(ValueError, match="is not a policy file"):
        load_policy_file(single)
    pickled = _save_raw(tmp_path / "pickled.npz", {"W": np.array([{"a": 1}], dtype=object)})
    with pytest.raises(ValueError, match="is not a policy file"):
        load_policy_file(pickled)
    with pytest.raises(FileNotFoundError, match="no policy file"):
        load_policy_file(tmp_path / "missing.npz")
    assert not any(is_policy_file(p) for p in (text, single, tmp_path / "missing.npz"))
    assert is_policy_file(pickled)  # it has a W: it is meant as one, and loading says what is bad


def test_metadata_cannot_take_a_formats_key(rng):
    with pytest.raises(ValueError, match="metadata key 'W2' is a key of the format"):
        PolicyFile.linear(np.zeros((2, 3)), np.zeros(2), W2=1)
    with pytest.raises(ValueError, match="metadata key 'seed' must be"):
        PolicyFile.linear(np.zeros((2, 3)), np.zeros(2), seed=[1, 2])


# ------------------------------------------------------------------------ from our policies


def test_a_linear_policy_converts_to_its_own_actions(rng):
    for policy in (LinearPolicy(6, 3), LinearPolicy(6, 3, bias=False, x_ref=tuple(rng.random(6)))):
        theta = 0.3 * rng.standard_normal(policy.n_params)
        file = to_policy_file(policy, theta, method="fopg_abs")
        obs = rng.standard_normal((40, 6))
        np.testing.assert_allclose(file.output(obs), policy.act(theta, obs), rtol=0, atol=1e-14)
        np.testing.assert_array_equal(file.obs_std, np.ones(6))
        assert file.metadata["policy_kind"] == "LinearPolicy"
        assert file.metadata["method"] == "fopg_abs"


def test_an_mlp_policy_converts_with_its_output_scale(rng):
    policy = MLPPolicy(5, 2, hidden=(8, 4), output_scale=0.5)
    theta = policy.init(rng) + 0.1 * rng.standard_normal(policy.n_params)
    file = to_policy_file(policy, theta)
    assert file.activation == "tanh" and file.hidden == (8, 4)
    obs = rng.standard_normal((40, 5))
    np.testing.assert_allclose(file.output(obs), policy.act(theta, obs), rtol=1e-13, atol=1e-14)


def test_ars_policy_converts_with_its_normaliser_and_dropped_coordinates(rng):
    std = rng.uniform(0.5, 2.0, 5)
    std[1] = 0.0  # below min_std: ARS drops it
    policy = NormalizedLinearPolicy(5, 2, mean=rng.standard_normal(5), std=std, bias=True)
    theta = rng.standard_normal(policy.n_params)
    file = to_policy_file(policy, theta)
    assert np.all(file.weights[0][:, 1] == 0) and file.obs_std[1] == 1.0
    obs = rng.standard_normal((40, 5))
    np.testing.assert_allclose(file.output(obs), policy.act(theta, obs), rtol=1e-13, atol=1e-14)


@dataclass(frozen=True)
class _Normalized:
    """A stand-in of the observation normaliser's policy: u = inner((o - mean) / std)."""

    inner: object
    mean: np.ndarray
    std: np.ndarray
    divide: bool = True  # False: a policy that only looks like one (multiplies by std)

    nx = property(lambda self: self.inner.nx)
    nu = property(lambda self: self.inner.nu)
    n_params = property(lambda self: self.inner.n_params)

    def normalize(self, o):
        return (o - self.mean) / self.std if self.divide else (o - self.mean) * self.std

    def act(self, theta, o):
        return self.inner.act(theta, self.normalize(np.asarray(o, dtype=float)))


@pytest.mark.parametrize(
    "inner", [LinearPolicy(5, 2), LinearPolicy(5, 2, x_ref=(0.1, 0.2, -0.3, 0.4, 0.5)),
              MLPPolicy(5, 2, hidden=(6,))],
    ids=["linear", "linear-xref", "mlp"],
)  # fmt: skip
def test_a_normalised_policy_converts_with_its_statistics(inner, rng):
    policy = _Normalized(inner, rng.standard_normal(5), rng.uniform(0.2, 3.0, 5))
    theta = 0.5 * rng.standard_normal(inner.n_params)
    file = to_policy_file(policy, theta)
    assert file.metadata["policy_kind"] == f"_Normalized({type(inner).__name__})"
    obs = 3.0 * rng.standard_normal((40, 5))
    np.testing.assert_allclose(file.output(obs), policy.act(theta, obs), rtol=1e-12, atol=1e-12)
    if not isinstance(inner, LinearPolicy) or inner.x_ref is None:  # the inner has no own
        np.testing.assert_array_equal(file.obs_mean, policy.mean)
        np.testing.assert_array_equal(file.obs_std, policy.std)
    impostor = _Normalized(inner, policy.mean, policy.std, divide=False)
    with pytest.raises(RuntimeError, match="does not reproduce its output"):
        to_policy_file(impostor, theta)


def test_the_observation_normalisers_policy_converts(rng):
    module = pytest.importorskip("drake_abs.policy.observation_normalizer")
    inner = LinearPolicy(4, 2)
    policy = module.NormalizedPolicy(inner, rng.standard_normal(4), rng.uniform(0.5, 2.0, 4))
    theta = rng.standard_normal(inner.n_params)
    file = to_policy_file(policy, theta)
    obs = rng.standard_normal((20, 4))
    np.testing.assert_allclose(file.output(obs), policy.act(theta, obs), rtol=1e-12, atol=1e-12)


def test_other_policies_are_refused(rng):
    with pytest.raises(ValueError, match="policy must be a LinearPolicy, MLPPolicy or "
                                         "NormalizedLinearPolicy"):  # fmt: skip
        to_policy_file(object(), np.zeros(1))
    with pytest.raises(ValueError, match=r"theta must have shape \(P,\) = \(8,\)"):
        to_policy_file(LinearPolicy(3, 2), np.zeros(7))


# ------------------------------------------------------------------- a file as an engine Policy


def _central_jacobian(f, x, h=1e-6):
    cols = [(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(x.size)]
    return np.stack(cols, axis=-1)


@pytest.mark.parametrize("activation", ["tanh", "elu", "sigmoid"])
def test_file_policy_jacobians_match_central_differences(activation, rng):
    file = _mlp(rng, activation, sizes=(5, 6, 3))
    theta, x = np.zeros(0), rng.standard_normal((6, 5))
    out = file.output(x)
    bound = np.median(np.abs(out[:, 1]))  # action 1 clipped in about half the states
    policy = FilePolicy(file, np.array([-10.0, -bound, -10.0]), np.array([10.0, bound, 10.0]))
    assert isinstance(policy, Policy) and policy.n_params == 0
    du_dx, du_dth = policy.jacobians(theta, x)
    assert du_dth.shape == (6, 3, 0)
    clipped = np.abs(out[:, 1]) >= bound
    assert clipped.any() and (~clipped).any()  # both a clipped and a free action 1
    assert np.all(du_dx[clipped, 1] == 0) and np.all(du_dx[~clipped, 1] != 0)
    for m in range(6):
        fd = _central_jacobian(lambda o: policy.act(theta, o[None])[0], x[m])
        np.testing.assert_allclose(du_dx[m], fd, rtol=1e-6, atol=1e-8)
    g = rng.standard_normal((6, 3))
    g_x, g_th = policy.vjp(theta, x, g)
    np.testing.assert_allclose(g_x, np.einsum("mi,mij->mj", g, du_dx), rtol=1e-12, atol=1e-14)
    assert g_th.shape == (6, 0)


def test_file_policy_checks_theta_and_bounds(rng):
    policy = FilePolicy(_linear(rng))
    with pytest.raises(ValueError, match=r"theta must have shape \(0,\)"):
        policy.act(np.zeros(1), np.zeros((1, 5)))
    with pytest.raises(ValueError, match="low must be below high"):
        FilePolicy(_linear(rng), 1.0, -1.0)
    with pytest.raises(ValueError, match=r"low must be a scalar or have shape \(nu,\) = \(3,\)"):
        FilePolicy(_linear(rng), np.zeros(2), 1.0)


# ------------------------------------------------------------------- an output activation (tanh)


@pytest.mark.parametrize("kind", ["linear", "mlp"])
def test_a_tanh_output_is_applied_before_the_clip_and_kept_on_disk(kind, rng, tmp_path):
    plain = _linear(rng) if kind == "linear" else _mlp(rng, "relu")
    layers = list(zip(plain.weights, plain.biases, strict=True))
    file = (
        PolicyFile.linear(*layers[0], plain.obs_mean, plain.obs_std, output_activation="tanh",
                          seed=1)
        if kind == "linear" else
        PolicyFile.mlp(layers, "relu", plain.obs_mean, plain.obs_std, output_activation="tanh",
                       seed=1)
    )  # fmt: skip
    obs = 3.0 * rng.standard_normal((30, file.n_obs))
    last = plain.output(obs)  # the same layers without g
    np.testing.assert_allclose(file.output(obs), np.tanh(last), rtol=0, atol=1e-15)
    low, high = -0.5, 0.5  # tanh keeps (-1, 1): a tighter action space still clips
    np.testing.assert_allclose(file.act(obs, low, high), np.clip(np.tanh(last), low, high),
                               rtol=0, atol=1e-15)  # fmt: skip
    assert np.any(np.abs(np.tanh(last)) > 0.5) and np.any(np.abs(last) > 1.0)
    assert "tanh output" in file.describe()
    path = file.save(tmp_path / "sac.npz")
    with np.load(path) as raw:
        assert str(raw["output_activation"]) == "tanh" and raw["output_activation"].shape == ()
    back = load_policy_file(path)
    assert back.output_activation == "tanh" and dict(back.metadata) == {"seed": 1}
    np.testing.assert_array_equal(back.act(obs), file.act(obs))


def test_an_identity_output_is_no_key_at_all(rng, tmp_path):
    file = PolicyFile.linear(np.ones((2, 3)), np.zeros(2), output_activation="identity")
    assert file.output_activation is None
    with np.load(file.save(tmp_path / "p.npz")) as raw:
        assert "output_activation" not in raw.files


def test_a_bad_output_activation_is_refused_naming_the_key(rng, tmp_path):
    with pytest.raises(ValueError, match="output_activation must be None or one of"):
        PolicyFile.linear(np.ones((2, 3)), np.zeros(2), output_activation="softsign")
    with pytest.raises(ValueError, match="metadata key 'output_activation' is a key of the format"):
        PolicyFile((np.ones((2, 3)),), (np.zeros(2),), np.zeros(3), np.ones(3), None,
                   {"output_activation": "tanh"})  # fmt: skip
    for value in (np.array("swish"), np.array(1.0), np.array(["tanh"])):
        path = _save_raw(tmp_path / "bad.npz", _arrays(_linear(rng), output_activation=value))
        with pytest.raises(ValueError, match="output_activation must be a 0-d string array"):
            load_policy_file(path)


def test_file_policy_jacobians_with_a_tanh_output_match_central_differences(rng):
    plain = _mlp(rng, "tanh", sizes=(5, 6, 3))
    layers = list(zip(plain.weights, plain.biases, strict=True))
    file = PolicyFile.mlp(layers, "tanh", plain.obs_mean, plain.obs_std, output_activation="tanh")
    theta, x = np.zeros(0), rng.standard_normal((6, 5))
    bound = np.median(np.abs(file.output(x)[:, 0]))
    policy = FilePolicy(file, np.array([-bound, -1.0, -1.0]), np.array([bound, 1.0, 1.0]))
    du_dx, _ = policy.jacobians(theta, x)
    for m in range(6):
        fd = _central_jacobian(lambda o: policy.act(theta, o[None])[0], x[m])
        np.testing.assert_allclose(du_dx[m], fd, rtol=1e-6, atol=1e-8)


def test_published_paths():
    assert (
        str(published_path("Hopper-v5", "fopg_abs", 3)) == "policies/Hopper-v5/fopg_abs/seed3.npz"
    )
    assert published_path("Ant-v5", "ars", 0, root="/x").as_posix() == "/x/Ant-v5/ars/seed0.npz"
    for bad in (("", "ars", 0), ("Hopper-v5", "a/b", 0), ("Hopper-v5", "ars", -1)):
        with pytest.raises(ValueError, match="must be"):
            published_path(*bad)
