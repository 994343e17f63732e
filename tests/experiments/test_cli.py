"""Every experiment the CLI knows has one Python entry point: ``Config`` (with ``test_size()``),
``run(config=None, out=None) -> dict`` and ``report(summary) -> str``."""

from __future__ import annotations

import importlib
import inspect

import pytest

from drake_abs.experiments.cli import EXPERIMENTS, STANDARD_EXPERIMENTS, main


@pytest.mark.parametrize("name", sorted(STANDARD_EXPERIMENTS))
def test_every_experiment_has_the_same_entry_point(name):
    module = importlib.import_module(f"drake_abs.experiments.{STANDARD_EXPERIMENTS[name]}")
    assert isinstance(module.Config.test_size(), module.Config)
    params = list(inspect.signature(module.run).parameters.values())
    assert [p.name for p in params] == ["config", "out"], name
    assert params[0].default is None, name
    assert callable(module.report)


def test_the_cli_lists_every_experiment(capsys):
    assert set(EXPERIMENTS) == set(STANDARD_EXPERIMENTS)
    with pytest.raises(SystemExit):
        main(["experiment", "no-such-experiment"])
    assert "invalid choice" in capsys.readouterr().err
