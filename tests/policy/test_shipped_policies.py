"""The shipped policy files (``policies/<env id>/<method>/seed<k>.npz``): each loads, says what
its path says, and the numpy-only reader of docs/policy_files.md gives the same actions as
:class:`~drake_abs.policy.policy_files.PolicyFile`."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from drake_abs.policy.policy_files import load_policy_file

ROOT = Path(__file__).resolve().parents[2]
SHIPPED = sorted((ROOT / "policies").glob("*/*/seed*.npz"))


def test_policies_are_shipped():
    assert len(SHIPPED) >= 10


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: "/".join(p.parts[-3:]))
def test_a_shipped_policy_is_what_its_path_says(path):
    file = load_policy_file(path)
    env_id, method, seed = path.parts[-3], path.parts[-2], path.stem
    assert file.metadata["env_id"] == env_id and file.metadata["method"] == method
    assert f"seed{file.metadata['seed']}" == seed
    assert file.metadata["training_steps"] >= 1_000_000


def test_the_documented_numpy_reader_gives_the_files_actions(monkeypatch):
    text = (ROOT / "docs" / "policy_files.md").read_text()
    block = re.findall(r"```python\n(.*?)```", text, flags=re.S)[0]
    monkeypatch.chdir(ROOT)
    rng = np.random.default_rng(0)
    for path in SHIPPED:
        code = block.replace("policies/Hopper-v5/shac_abs/seed0.npz", str(path))
        namespace: dict = {}
        exec(compile(code, "docs/policy_files.md", "exec"), namespace)
        file = load_policy_file(path)
        obs = 2.0 * rng.standard_normal((5, file.obs_mean.size))
        for o in obs:
            np.testing.assert_array_equal(namespace["act"](o), file.act(o))
