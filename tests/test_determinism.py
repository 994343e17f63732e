"""Determinism users rely on: the same call with the same inputs gives identical numbers, in the
same process and in a new one (a seeded experiment reruns exactly). Bit-exact equality is
asserted only here, for identical call sequences; results of different code paths or solver
histories are compared elsewhere with tolerances that say why."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from determinism_cases import CASES

HERE = Path(__file__).parent


@pytest.fixture(scope="module")
def in_process():
    return {name: case() for name, case in CASES.items()}


@pytest.mark.parametrize("name", sorted(CASES))
def test_same_call_twice_in_one_process_is_bit_identical(name, in_process):
    assert CASES[name]() == in_process[name]


def test_a_second_process_gives_bit_identical_numbers(in_process):
    out = subprocess.run(
        [sys.executable, str(HERE / "determinism_cases.py")],
        capture_output=True,
        text=True,
        check=True,
        cwd=HERE,
        timeout=600,
    )
    other = json.loads(out.stdout.strip().splitlines()[-1])
    assert other == in_process
