"""Policy files anyone can load: a policy of gymnasium's observation as plain arrays in one
``.npz`` file, read with numpy alone (the published format of ``policies/<env id>/<method>/
seed<k>.npz``).

The file's keys::

    linear policy                       MLP
    W         (nu, n_obs)               W0, b0, W1, b1, ..., W{L-1}, b{L-1}
    b         (nu,)                         W_i (n_{i+1}, n_i), b_i (n_{i+1},),
                                            n_0 = n_obs, n_L = nu
    obs_mean  (n_obs,)                  obs_mean, obs_std  as for a linear policy
    obs_std   (n_obs,), every entry > 0 activation  0-d string: the hidden layers' activation
                                                    (one of ACTIVATIONS)

and the action of an observation ``o`` (gymnasium v5's default observation of the environment,
what ``env.step`` returns), with ``z = (o - obs_mean) / obs_std``::

    linear:  a = clip(g(W z + b), low, high)
    MLP:     h_0 = z,  h_i = f(W_{i-1} h_{i-1} + b_{i-1})  (i = 1 .. L-1, f the activation),
             a = clip(g(W_{L-1} h_{L-1} + b_{L-1}), low, high)

clipped to the environment's action space ``[low, high]`` (gymnasium's MuJoCo locomotion tasks
Hopper, HalfCheetah, Walker2d and Ant act in [-1, 1]). ``g`` is the identity (the last layer is
linear) unless the file has the optional key ``output_activation``, a 0-d string naming one of
ACTIVATIONS (for a linear policy or an MLP): ``"tanh"`` is the deterministic action of a policy
squashed by tanh, e.g. SAC's ``tanh(mean)``. A policy without observation normalisation has
``obs_mean = 0``, ``obs_std = 1``.

Any other key is metadata: a 0-d array holding a string, a whole number, a real number or a
bool. The ones this package writes (:data:`METADATA_KEYS`): ``env_id``, ``method``, ``seed``,
``training_steps``, ``policy_kind``, ``drake_abs_version``. A key that looks like a layer
(``W3``, ``b0``) is a layer, never metadata.

:func:`load_policy_file` checks everything above and raises ``ValueError`` naming the bad key
and the expected shape; :class:`PolicyFile` holds a checked policy (``act(obs)`` needs numpy
only); :func:`to_policy_file` converts this package's policies of an observation
(:class:`~drake_abs.policy.policies.LinearPolicy`,
:class:`~drake_abs.policy.policies.MLPPolicy`,
:class:`~drake_abs.policy.ars_v2.NormalizedLinearPolicy`, and any of these behind an
observation normaliser); :class:`FilePolicy` runs a file as
an engine :class:`~drake_abs.engine.protocols.Policy` (no parameters). The training code's own
save format (:mod:`drake_abs.policy.saving`, npz + json with the config) is separate.
"""

from __future__ import annotations

import re
import struct
import zipfile
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from drake_abs._validation import as_finite_array
from drake_abs.policy.ars_v2 import NormalizedLinearPolicy
from drake_abs.policy.policies import LinearPolicy, MLPPolicy

__all__ = [
    "ACTIVATIONS",
    "METADATA_KEYS",
    "FilePolicy",
    "PolicyFile",
    "is_policy_file",
    "load_policy_file",
    "published_path",
    "read_npz_arrays",
    "to_policy_file",
]


def published_path(env_id: str, method: str, seed: int, root: str | Path = "policies") -> Path:
    """Where the final policy of ``method`` trained with ``seed`` for ``env_id`` ships:
    ``root/<env id>/<method>/seed<k>.npz``."""
    for name, value in (("env_id", env_id), ("method", method)):
        if not isinstance(value, str) or not value or "/" in value or value.startswith("."):
            raise ValueError(f"{name} must be a non-empty name without '/'; got {value!r}")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a whole number >= 0; got {seed!r}")
    return Path(root) / env_id / method / f"seed{int(seed)}.npz"


def _elu_derivative(z: np.ndarray) -> np.ndarray:
    return np.where(z > 0, 1.0, np.exp(np.minimum(z, 0.0)))


#: The hidden layers' activations an MLP file may name, each name with (f(z), f'(z)),
#: elementwise; ``elu`` has alpha = 1, ``sigmoid`` is 1 / (1 + exp(-z)).
ACTIVATIONS: Mapping[str, tuple[Callable, Callable]] = MappingProxyType({
    "tanh": (np.tanh, lambda z: 1.0 - np.tanh(z) ** 2),
    "relu": (lambda z: np.maximum(z, 0.0), lambda z: (z > 0).astype(float)),
    "elu": (lambda z: np.where(z > 0, z, np.expm1(np.minimum(z, 0.0))), _elu_derivative),
    "sigmoid": (lambda z: 1.0 / (1.0 + np.exp(-z)),
                lambda z: np.exp(-z) / (1.0 + np.exp(-z)) ** 2),
    "identity": (lambda z: z, np.ones_like),
})  # fmt: skip

#: The metadata keys this package writes, and what each holds.
METADATA_KEYS: Mapping[str, str] = MappingProxyType({
    "env_id": "the gymnasium environment the policy acts in, e.g. 'Hopper-v5'",
    "method": "the training method's key (drake_abs.policy.methods), e.g. 'fopg_abs'",
    "seed": "the training seed (a whole number)",
    "training_steps": "environment steps spent in training (a whole number)",
    "policy_kind": "the class it was converted from, e.g. 'LinearPolicy'",
    "drake_abs_version": "the drake-abs version that wrote the file",
})  # fmt: skip

_NORMALISER = ("obs_mean", "obs_std")
_ACTIVATION_KEYS = ("activation", "output_activation")
_LAYER_KEY = re.compile(r"^([Wb])(\d*)$")


def _metadata_value(key: str, value) -> str | int | float | bool:
    """A metadata value as a plain Python str, int, float or bool (``ValueError`` otherwise)."""
    if isinstance(value, np.ndarray):
        if value.ndim != 0:
            raise ValueError(
                f"metadata key {key!r} must be a 0-d array (a string or a number); got shape "
                f"{value.shape} (layers are W, b or W0, b0, ...; the normaliser obs_mean, obs_std)"
            )
        if value.dtype.kind not in "biufU":
            raise ValueError(
                f"metadata key {key!r} must hold a string, a whole or real number or a bool; got "
                f"dtype {value.dtype}"
            )
        value = value.item()
    if isinstance(value, np.generic):
        value = value.item()
    if not isinstance(value, str | int | float | bool):
        raise ValueError(
            f"metadata key {key!r} must be a string, a whole or real number or a bool; got "
            f"{type(value).__name__}"
        )
    if isinstance(value, float) and not np.isfinite(value):
        raise ValueError(f"metadata key {key!r} must be finite; got {value!r}")
    return value


def _matrix(value, key: str, shape: tuple[int | None, ...], form: str) -> np.ndarray:
    """``value`` as a finite float array of ``shape`` (None: any size there), else ValueError
    naming ``key`` and ``form``."""
    arr = np.asarray(value)
    if arr.dtype.kind not in "iuf":
        raise ValueError(f"{key} must be a real numeric array of shape {form}; got dtype "
                         f"{arr.dtype}")  # fmt: skip
    if arr.ndim != len(shape) or any(
        n is not None and n != m for n, m in zip(shape, arr.shape, strict=True)
    ):
        raise ValueError(f"{key} must have shape {form}; got {arr.shape}")
    return as_finite_array(arr, key)


@dataclass(frozen=True, eq=False)
class PolicyFile:
    """A checked policy of an observation, as stored in a policy file (module docstring).

    Attributes:
        weights: the layers' W_i, (n_{i+1}, n_i) each; one for a linear policy.
        biases: the layers' b_i, (n_{i+1},) each.
        obs_mean: (n_obs,) subtracted from the observation (units of the observation).
        obs_std: (n_obs,) divides it, every entry > 0.
        activation: the hidden layers' activation (a key of :data:`ACTIVATIONS`) for an MLP;
            None for a linear policy (then exactly one layer, stored as ``W``, ``b``).
        metadata: the file's other keys, each a str, int, float or bool.
        output_activation: g, applied to the last layer's output before the clip (a key of
            :data:`ACTIVATIONS`, e.g. ``"tanh"``); None (or ``"identity"``, stored as None):
            the last layer is linear, and the file has no ``output_activation`` key.

    Build one with :meth:`linear` or :meth:`mlp` (``ValueError`` naming the bad array).
    """

    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    obs_mean: np.ndarray
    obs_std: np.ndarray
    activation: str | None = None
    metadata: Mapping[str, str | int | float | bool] = field(default_factory=dict)
    output_activation: str | None = None

    def __post_init__(self):
        weights, biases = tuple(self.weights), tuple(self.biases)
        if self.output_activation is not None and self.output_activation not in ACTIVATIONS:
            raise ValueError(
                f"output_activation must be None or one of {sorted(ACTIVATIONS)}; got "
                f"{self.output_activation!r}"
            )
        if self.output_activation == "identity":
            object.__setattr__(self, "output_activation", None)
        linear = self.activation is None
        if not weights or len(weights) != len(biases):
            raise ValueError(
                f"weights and biases must be one W and one b per layer, at least one layer; got "
                f"{len(weights)} and {len(biases)}"
            )
        if linear and len(weights) != 1:
            raise ValueError(
                f"a linear policy (activation None) has one layer W, b; got {len(weights)} layers "
                "(an MLP names its activation)"
            )
        if not linear and self.activation not in ACTIVATIONS:
            raise ValueError(
                f"activation must be one of {sorted(ACTIVATIONS)}; got {self.activation!r}"
            )
        names = ["W"] if linear else [f"W{i}" for i in range(len(weights))]
        checked_w, checked_b = [], []
        n_in = None
        for i, (name, W, b) in enumerate(zip(names, weights, biases, strict=True)):
            bias = "b" + name[1:]
            if i == 0:
                W = _matrix(W, name, (None, None), "(n_1, n_obs)" if not linear else
                            "(nu, n_obs)")  # fmt: skip
            else:
                W = _matrix(W, name, (None, n_in), f"(n_{i + 1}, n_{i}) = (n_{i + 1}, {n_in})")
            if W.shape[0] < 1 or W.shape[1] < 1:
                raise ValueError(f"{name} must have at least one row and one column; got "
                                 f"{W.shape}")  # fmt: skip
            b = _matrix(b, bias, (W.shape[0],), f"({W.shape[0]},), the rows of {name}")
            checked_w.append(W)
            checked_b.append(b)
            n_in = W.shape[0]
        n_obs = checked_w[0].shape[1]
        form = f"(n_obs,) = ({n_obs},), the columns of {names[0]}"
        mean = _matrix(self.obs_mean, "obs_mean", (n_obs,), form)
        std = _matrix(self.obs_std, "obs_std", (n_obs,), form)
        if np.any(std <= 0):
            bad = int(np.argmin(std > 0))
            raise ValueError(
                f"obs_std must be > 0 in every entry (it divides the observation); entry {bad} "
                f"is {float(std[bad])!r}"
            )
        metadata = {}
        for key, value in dict(self.metadata).items():
            if not isinstance(key, str) or not key:
                raise ValueError(f"metadata keys must be non-empty strings; got {key!r}")
            if _LAYER_KEY.match(key) or key in (*_NORMALISER, *_ACTIVATION_KEYS):
                raise ValueError(
                    f"metadata key {key!r} is a key of the format itself (a layer, the "
                    "normaliser or the activation), not metadata"
                )
            metadata[key] = _metadata_value(key, value)
        object.__setattr__(self, "weights", tuple(checked_w))
        object.__setattr__(self, "biases", tuple(checked_b))
        object.__setattr__(self, "obs_mean", mean)
        object.__setattr__(self, "obs_std", std)
        object.__setattr__(self, "metadata", MappingProxyType(metadata))

    # ------------------------------------------------------------------------------- building

    @classmethod
    def linear(
        cls, W, b, obs_mean=None, obs_std=None, *, output_activation=None, **metadata
    ) -> PolicyFile:
        """A linear policy ``a = clip(g(W (o - obs_mean) / obs_std + b))``; obs_mean 0 and
        obs_std 1 by default (no normalisation); g the ``output_activation`` (default None,
        the identity); ``metadata`` as keyword arguments."""
        W = np.asarray(W)
        n_obs = W.shape[1] if W.ndim == 2 else 0
        return cls(
            (W,), (b,), np.zeros(n_obs) if obs_mean is None else obs_mean,
            np.ones(n_obs) if obs_std is None else obs_std, None, metadata, output_activation,
        )  # fmt: skip

    @classmethod
    def mlp(
        cls,
        layers,
        activation: str,
        obs_mean=None,
        obs_std=None,
        *,
        output_activation=None,
        **metadata,
    ) -> PolicyFile:
        """An MLP of ``layers`` = [(W0, b0), (W1, b1), ...] with ``activation`` on the hidden
        layers (the last layer linear, then ``output_activation``); normaliser, output
        activation and metadata as :meth:`linear`."""
        layers = list(layers)
        if not layers or any(len(layer) != 2 for layer in layers):
            raise ValueError("layers must be a non-empty list of (W, b) pairs")
        W0 = np.asarray(layers[0][0])
        n_obs = W0.shape[1] if W0.ndim == 2 else 0
        return cls(
            tuple(W for W, _ in layers), tuple(b for _, b in layers),
            np.zeros(n_obs) if obs_mean is None else obs_mean,
            np.ones(n_obs) if obs_std is None else obs_std, activation, metadata,
            output_activation,
        )  # fmt: skip

    # ---------------------------------------------------------------------------- properties

    @property
    def kind(self) -> str:
        """``"linear"`` or ``"mlp"``."""
        return "linear" if self.activation is None else "mlp"

    @property
    def n_obs(self) -> int:
        """The observation's size."""
        return int(self.weights[0].shape[1])

    @property
    def nu(self) -> int:
        """The action's size."""
        return int(self.weights[-1].shape[0])

    @property
    def hidden(self) -> tuple[int, ...]:
        """The hidden layers' widths (empty for a linear policy)."""
        return tuple(int(W.shape[0]) for W in self.weights[:-1])

    def describe(self) -> str:
        """One plain line: kind, sizes, activation, normalised or not."""
        sizes = " -> ".join(str(n) for n in (self.n_obs, *self.hidden, self.nu))
        normalised = not (np.all(self.obs_mean == 0) and np.all(self.obs_std == 1))
        what = "linear" if self.activation is None else f"MLP ({self.activation})"
        squash = "" if self.output_activation is None else f"{self.output_activation} output, "
        return f"{what}, {sizes}, {squash}" + ("normalised observation" if normalised else
                                               "no observation normalisation")  # fmt: skip

    # ---------------------------------------------------------------------------- evaluation

    def _obs(self, obs) -> tuple[np.ndarray, bool]:
        o = np.asarray(obs, dtype=float)
        single = o.ndim == 1
        if o.ndim not in (1, 2) or o.shape[-1] != self.n_obs:
            raise ValueError(
                f"obs must have shape (n_obs,) or (M, n_obs) with n_obs = {self.n_obs}; got "
                f"{o.shape}"
            )
        return (o[None] if single else o), single

    def _forward(self, o: np.ndarray) -> tuple[list[np.ndarray], np.ndarray]:
        """(pre-activations of the hidden layers, the last layer's output (M, nu) before the
        output activation)."""
        h = (o - self.obs_mean) / self.obs_std
        pre = []
        if self.activation is not None:
            f = ACTIVATIONS[self.activation][0]
            for W, b in zip(self.weights[:-1], self.biases[:-1], strict=True):
                pre.append(h @ W.T + b)
                h = f(pre[-1])
        return pre, h @ self.weights[-1].T + self.biases[-1]

    def output(self, obs) -> np.ndarray:
        """The output before clipping, ``g(last layer)``: (nu,) for obs (n_obs,), (M, nu) for
        (M, n_obs)."""
        o, single = self._obs(obs)
        out = self._forward(o)[1]
        if self.output_activation is not None:
            out = ACTIVATIONS[self.output_activation][0](out)
        return out[0] if single else out

    def act(self, obs, low=-1.0, high=1.0) -> np.ndarray:
        """The action ``clip(output(obs), low, high)`` ((nu,) or (M, nu), as :meth:`output`);
        ``low``, ``high`` scalars or (nu,): the action space (default [-1, 1], gymnasium's
        MuJoCo locomotion tasks)."""
        return np.clip(self.output(obs), low, high)

    def output_vjp(self, obs, g_out) -> np.ndarray:
        """``g_out d output / d obs`` (M, n_obs) for obs (M, n_obs), g_out (M, nu): the chain
        rule backwards through the layers and the normaliser."""
        o, _ = self._obs(obs)
        g = np.asarray(g_out, dtype=float).reshape(o.shape[0], self.nu)
        pre, last = self._forward(o)
        if self.output_activation is not None:
            g = g * ACTIVATIONS[self.output_activation][1](last)
        g = g @ self.weights[-1]
        if self.activation is not None:
            df = ACTIVATIONS[self.activation][1]
            for i in range(len(pre) - 1, -1, -1):
                g = (g * df(pre[i])) @ self.weights[i]
        return g / self.obs_std

    # ------------------------------------------------------------------------------- storing

    def arrays(self) -> dict[str, np.ndarray]:
        """The file's arrays, by key (module docstring)."""
        if self.activation is None:
            out = {"W": self.weights[0], "b": self.biases[0]}
        else:
            out = {}
            for i, (W, b) in enumerate(zip(self.weights, self.biases, strict=True)):
                out[f"W{i}"], out[f"b{i}"] = W, b
            out["activation"] = np.array(self.activation)
        out |= {"obs_mean": self.obs_mean, "obs_std": self.obs_std}
        if self.output_activation is not None:
            out["output_activation"] = np.array(self.output_activation)
        return out | {key: np.array(value) for key, value in self.metadata.items()}

    def save(self, path: str | Path) -> Path:
        """Write the file (``path`` ends in ``.npz``; its folder is created). Returns the
        path."""
        path = Path(path).expanduser()
        if path.suffix != ".npz":
            raise ValueError(f"path must end in .npz; got {str(path)!r}")
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("wb") as handle:
            np.savez(handle, **self.arrays())
        return path

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray], source: str = "arrays") -> PolicyFile:
        """Read a policy from a file's arrays (``ValueError`` naming ``source`` and the bad key:
        no layers, a gap in the layers, a shape that does not chain, a missing normaliser or
        activation, an output activation that is not a 0-d string of ACTIVATIONS, metadata that
        is not a 0-d string or number)."""
        try:
            return cls._from_arrays(arrays)
        except ValueError as err:
            raise ValueError(f"{source}: {err}") from None

    @classmethod
    def _from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> PolicyFile:
        layers: dict[str, dict[int | None, np.ndarray]] = {"W": {}, "b": {}}
        metadata = {}
        for key, value in arrays.items():
            match = _LAYER_KEY.match(key)
            if match:
                letter, index = match.groups()
                layers[letter][int(index) if index else None] = value
            elif key not in (*_NORMALISER, *_ACTIVATION_KEYS):
                metadata[key] = value
        for key in _NORMALISER:
            if key not in arrays:
                raise ValueError(
                    f"no {key!r}: a policy file holds obs_mean and obs_std (n_obs,) (0 and 1 for "
                    "a policy without observation normalisation)"
                )
        output_activation = None
        if "output_activation" in arrays:
            value = np.asarray(arrays["output_activation"])
            if value.ndim != 0 or value.dtype.kind != "U" or str(value) not in ACTIVATIONS:
                raise ValueError(
                    f"output_activation must be a 0-d string array, one of {sorted(ACTIVATIONS)}; "
                    f"got {value!r}"
                )
            output_activation = str(value)
        Ws, bs = layers["W"], layers["b"]
        if None in Ws or None in bs:  # a linear policy: W, b
            if set(Ws) | set(bs) != {None}:
                raise ValueError(
                    f"keys {sorted(k for k in arrays if _LAYER_KEY.match(k))}: a linear policy "
                    "is W, b; an MLP is W0, b0, W1, b1, ...; not both"
                )
            for key in ("W", "b"):
                if key not in arrays:
                    raise ValueError(f"no {key!r}: a linear policy holds W (nu, n_obs), b (nu,)")
            if "activation" in arrays:
                raise ValueError(
                    "'activation' belongs to an MLP (W0, b0, ...); a linear policy (W, b) has none"
                )
            return cls((arrays["W"],), (arrays["b"],), arrays["obs_mean"], arrays["obs_std"],
                       None, metadata, output_activation)  # fmt: skip
        if not Ws:
            raise ValueError(
                "no layers: a policy file holds W, b (linear) or W0, b0, W1, b1, ... (an MLP); "
                f"its keys are {sorted(arrays)}"
            )
        count = max(Ws) + 1
        for letter, found in (("W", Ws), ("b", bs)):
            missing = [f"{letter}{i}" for i in range(count) if i not in found]
            extra = [f"{letter}{i}" for i in found if i >= count]
            if missing or extra:
                raise ValueError(
                    f"the layers must be W0, b0 .. W{count - 1}, b{count - 1} without gaps; "
                    + (f"missing {missing}" if missing else f"{extra} without W")
                )
        if "activation" not in arrays:
            raise ValueError("no 'activation': an MLP (W0, b0, ...) names its hidden layers' "
                             f"activation, one of {sorted(ACTIVATIONS)}")  # fmt: skip
        activation = np.asarray(arrays["activation"])
        if activation.ndim != 0 or activation.dtype.kind != "U":
            raise ValueError(
                f"activation must be a 0-d string array, one of {sorted(ACTIVATIONS)}; got "
                f"dtype {activation.dtype}, shape {activation.shape}"
            )
        return cls(
            tuple(Ws[i] for i in range(count)), tuple(bs[i] for i in range(count)),
            arrays["obs_mean"], arrays["obs_std"], str(activation), metadata, output_activation,
        )  # fmt: skip


#: What reading a damaged npz archive raises: not a zip archive or a bad checksum
#: (BadZipFile), cut short (EOFError), a damaged compressed member (zlib.error), a damaged
#: array header (ValueError, SyntaxError from the header's text), a pickled array (ValueError),
#: flags of a damaged zip header (NotImplementedError: "compression method not supported",
#: RuntimeError: "encrypted").
_DAMAGED = (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error, SyntaxError,
            KeyError, struct.error, NotImplementedError, RuntimeError)  # fmt: skip


def _open_npz(path: Path):
    """``np.load`` of an npz archive (pickles refused); ``ValueError`` for anything else."""
    data = np.load(path, allow_pickle=False)
    if not isinstance(data, np.lib.npyio.NpzFile):
        raise ValueError("a single array, not an npz archive of named arrays")
    return data


def read_npz_arrays(path: str | Path, what: str = "npz archive") -> dict[str, np.ndarray]:
    """Every array of the npz archive at ``path``, read in full (so that a damaged member is
    found now, not when it is used).

    Raises:
        FileNotFoundError: no such file.
        ValueError: the file is empty, cut short, not an npz archive, damaged (a checksum or an
            array header that does not read) or holds a pickled object array; the message names
            the file, ``what`` it should be and what is wrong.
    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise FileNotFoundError(f"no {what} {str(path)!r}")
    if path.stat().st_size == 0:
        raise ValueError(f"{str(path)!r} is not a {what}: the file is empty")
    try:
        with _open_npz(path) as data:
            return {key: np.array(data[key]) for key in data.files}
    except _DAMAGED as err:
        reason = f"{type(err).__name__}: {err}" if str(err) else type(err).__name__
        raise ValueError(
            f"{str(path)!r} is not a {what}: {reason} (it should be an npz archive of named "
            "arrays, as numpy.savez writes; this file is damaged, cut short or of another kind)"
        ) from None


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    return read_npz_arrays(path, "policy file")


def load_policy_file(path: str | Path) -> PolicyFile:
    """Read and check a policy file (module docstring).

    Raises:
        FileNotFoundError: no such file.
        ValueError: not an npz archive, or not a policy: the message names the file and the bad
            key with the expected form.
    """
    path = Path(path).expanduser()
    return PolicyFile.from_arrays(_read_npz(path), source=str(path))


def is_policy_file(path: str | Path) -> bool:
    """Whether ``path`` is an npz archive with a policy file's layers (``W`` or ``W0``); the
    check of everything else is :func:`load_policy_file`'s."""
    path = Path(path).expanduser()
    if path.suffix != ".npz" or not path.is_file():
        return False
    try:
        with _open_npz(path) as data:
            return bool({"W", "W0"} & set(data.files))
    except _DAMAGED:
        return False


def _is_normalized(policy) -> bool:
    """Whether ``policy`` is ``u = inner((o - mean) / std)`` with frozen statistics
    (:class:`drake_abs.policy.observation_normalizer.NormalizedPolicy`, recognised by its
    parts)."""
    return all(hasattr(policy, name) for name in ("inner", "mean", "std", "normalize"))


def _kind(policy) -> str:
    if _is_normalized(policy):
        return f"{type(policy).__name__}({_kind(policy.inner)})"
    return type(policy).__name__


def _converted(policy, theta: np.ndarray, metadata: dict) -> PolicyFile:
    """The file of ``policy`` (one of :func:`to_policy_file`'s kinds) with parameters theta."""
    if _is_normalized(policy):
        inner = _converted(policy.inner, theta, metadata)
        mean = np.asarray(policy.mean, dtype=float)
        std = np.asarray(policy.std, dtype=float)
        # ((o - mean) / std - m) / s = (o - (mean + std m)) / (std s)
        return PolicyFile(inner.weights, inner.biases, mean + std * inner.obs_mean,
                          std * inner.obs_std, inner.activation, metadata,
                          inner.output_activation)  # fmt: skip
    if not isinstance(policy, LinearPolicy | MLPPolicy | NormalizedLinearPolicy):
        raise ValueError(
            "policy must be a LinearPolicy, MLPPolicy or NormalizedLinearPolicy of the "
            f"observation, or a NormalizedPolicy of one; got {type(policy).__name__}"
        )
    nx, nu = policy.nx, policy.nu
    if isinstance(policy, MLPPolicy):
        sizes, layers, o = policy.sizes, [], 0
        for i in range(len(sizes) - 1):
            W = theta[o : o + sizes[i + 1] * sizes[i]].reshape(sizes[i + 1], sizes[i])
            o += sizes[i + 1] * sizes[i]
            layers.append([W, theta[o : o + sizes[i + 1]]])
            o += sizes[i + 1]
        layers[-1] = [policy.output_scale * layers[-1][0], policy.output_scale * layers[-1][1]]
        return PolicyFile.mlp(layers, "tanh", **metadata)
    K = theta[: nu * nx].reshape(nu, nx)
    k = theta[nu * nx :] if policy.bias else np.zeros(nu)
    if isinstance(policy, LinearPolicy):
        mean = None if policy.x_ref is None else np.asarray(policy.x_ref, dtype=float)
        return PolicyFile.linear(K, k, mean, None, **metadata)
    keep = policy.scale > 0
    W = np.where(keep, K, 0.0)
    return PolicyFile.linear(W, k, policy.mean, np.where(keep, policy.std, 1.0), **metadata)


def to_policy_file(policy, theta, **metadata) -> PolicyFile:
    """The policy file of one of this package's policies of an observation, with parameters
    ``theta``.

    - :class:`~drake_abs.policy.policies.LinearPolicy` ``u = K (o - x_ref) + k``: W = K,
      b = k (0 without bias), obs_mean = x_ref (0 without), obs_std = 1.
    - :class:`~drake_abs.policy.policies.MLPPolicy` (tanh hidden layers): its layers, the
      ``output_scale`` multiplied into the last one; obs_mean 0, obs_std 1.
    - :class:`~drake_abs.policy.ars_v2.NormalizedLinearPolicy` ``u = K (o - mean) / std + k``:
      W = K, b = k, obs_mean = mean, obs_std = std, with a coordinate it drops (std below its
      ``min_std``) stored as a zero column of W and std 1.
    - a normalised policy ``u = inner((o - mean) / std)`` of one of these (the observation
      normaliser's ``NormalizedPolicy``: ``inner``, ``mean``, ``std``): the inner policy's file
      with obs_mean = mean + std m and obs_std = std s (m, s the inner file's).

    The file's input is the policy's input: pass the policy of a task's observation
    (:func:`drake_abs.tasks.published_policies.task_policy_file` does that for a task, checking
    the observation). The file clips the output to the action space; these policies do not.
    ``metadata`` become the file's metadata keys (:data:`METADATA_KEYS`), ``policy_kind``
    added.

    The file is checked to reproduce the policy's output at a few observations (to 1e-9
    relative); a mismatch raises ``RuntimeError`` (a policy that only looks like these)."""
    theta = as_finite_array(theta, "theta", ndim=(1,))
    n_params = getattr(policy, "n_params", None)
    if n_params is not None and theta.shape != (n_params,):
        raise ValueError(f"theta must have shape (P,) = ({n_params},); got {theta.shape}")
    file = _converted(policy, theta, {"policy_kind": _kind(policy)} | metadata)
    rng = np.random.default_rng(0)
    obs = file.obs_mean + file.obs_std * rng.standard_normal((8, file.n_obs))
    ours, theirs = file.output(obs), np.asarray(policy.act(theta, obs), dtype=float)
    scale = max(1.0, float(np.max(np.abs(theirs))))
    if theirs.shape != ours.shape or not np.allclose(ours, theirs, rtol=0, atol=1e-9 * scale):
        raise RuntimeError(
            f"the policy file of {_kind(policy)} does not reproduce its output: largest "
            f"difference {float(np.max(np.abs(ours - theirs)))} (a defect of the conversion)"
        )
    return file


@dataclass(frozen=True, eq=False)
class FilePolicy:
    """A policy file as an engine :class:`~drake_abs.engine.protocols.Policy` of the
    observation, with no parameters (theta has shape (0,)): ``act(theta, o (M, n_obs))`` is
    ``file.act(o, low, high)``.

    Its Jacobian ``du/do`` is the file's, with a zero row where the action is clipped (at or
    beyond a bound); ``du/dtheta`` is (M, nu, 0).

    Args:
        file: the :class:`PolicyFile`.
        low, high: the action space's bounds, scalars or (nu,) (default [-1, 1]).
    """

    file: PolicyFile
    low: float | np.ndarray = -1.0
    high: float | np.ndarray = 1.0

    def __post_init__(self):
        if not isinstance(self.file, PolicyFile):
            raise ValueError(f"file must be a PolicyFile; got {type(self.file).__name__}")
        low = as_finite_array(self.low, "low", ndim=(0, 1))
        high = as_finite_array(self.high, "high", ndim=(0, 1))
        for name, arr in (("low", low), ("high", high)):
            if arr.ndim == 1 and arr.shape != (self.nu,):
                raise ValueError(f"{name} must be a scalar or have shape (nu,) = ({self.nu},); "
                                 f"got {arr.shape}")  # fmt: skip
        if np.any(np.broadcast_to(low, (self.nu,)) >= np.broadcast_to(high, (self.nu,))):
            raise ValueError(f"low must be below high in every entry; got {low}, {high}")
        object.__setattr__(self, "low", low)
        object.__setattr__(self, "high", high)

    @property
    def nx(self) -> int:
        """The observation's size (this policy's input)."""
        return self.file.n_obs

    @property
    def nu(self) -> int:
        return self.file.nu

    @property
    def n_params(self) -> int:
        """Always 0 (a file's policy has no parameters)."""
        return 0

    def _check(self, theta, x) -> np.ndarray:
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (0,):
            raise ValueError(f"theta must have shape (0,) (a policy file has no parameters); got "
                             f"{theta.shape}")  # fmt: skip
        x = as_finite_array(x, "x", ndim=(2,))
        if x.shape[1] != self.nx:
            raise ValueError(f"x must have shape (M, n_obs) = (M, {self.nx}); got {x.shape}")
        return x

    def _inside(self, x: np.ndarray) -> np.ndarray:
        out = self.file.output(x)
        return ((out > self.low) & (out < self.high)).astype(float)

    def act(self, theta, x) -> np.ndarray:
        """u (M, nu) at observations x (M, n_obs)."""
        return self.file.act(self._check(theta, x), self.low, self.high)

    def vjp(self, theta, x, g_u) -> tuple[np.ndarray, np.ndarray]:
        """(g_u du/dx (M, n_obs), (M, 0)) for g_u (M, nu)."""
        x = self._check(theta, x)
        g = np.asarray(g_u, dtype=float).reshape(x.shape[0], self.nu) * self._inside(x)
        return self.file.output_vjp(x, g), np.zeros((x.shape[0], 0))

    def jacobians(self, theta, x) -> tuple[np.ndarray, np.ndarray]:
        """(du/dx (M, nu, n_obs), du/dtheta (M, nu, 0))."""
        x = self._check(theta, x)
        M = x.shape[0]
        rows = [self.vjp(theta, x, np.broadcast_to(e, (M, self.nu)))[0] for e in np.eye(self.nu)]
        return np.stack(rows, axis=1), np.zeros((M, self.nu, 0))
