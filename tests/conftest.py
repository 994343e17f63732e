import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as drake_abs does: small matrices

import numpy as np  # noqa: E402
import pytest
from hypothesis import HealthCheck, settings

# Seeded, reproducible property tests: the same run gives the same examples.
settings.register_profile(
    "repro",
    derandomize=True,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
    print_blob=True,
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repro"))


@pytest.fixture
def rng():
    return np.random.default_rng(20261123)
