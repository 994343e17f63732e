"""The experiments' figure, table, CSV and JSON writers (experiments/outputs.py)."""

from __future__ import annotations

import csv
import json
import math

import pytest

from drake_abs.experiments.outputs import (
    markdown_table,
    pyplot,
    save_figure,
    write_csv,
    write_json,
)


def test_csv_of_dicts_and_of_sequences(tmp_path):
    path = write_csv(tmp_path / "a.csv", [{"x": 1, "y": 0.5}, {"x": 2, "y": None}])
    assert list(csv.reader(path.open())) == [["x", "y"], ["1", "0.5"], ["2", ""]]
    path = write_csv(tmp_path / "b.csv", [(1, "a"), (2, "b")], header=["n", "s"])
    assert list(csv.reader(path.open())) == [["n", "s"], ["1", "a"], ["2", "b"]]
    with pytest.raises(ValueError, match="header"):
        write_csv(tmp_path / "c.csv", [(1, 2)])


def test_markdown_table():
    assert markdown_table(["a", "b"], [[1, "x"]]) == ["| a | b |", "| --- | --- |", "| 1 | x |"]


def test_json_writes_nan_as_null_when_asked(tmp_path):
    data = {"a": [1.0, math.nan], "b": math.inf}
    assert json.loads(write_json(tmp_path / "f.json", data, finite=True).read_text()) == {
        "a": [1.0, None],
        "b": None,
    }
    text = write_json(tmp_path / "g.json", data, indent=1).read_text()
    assert "NaN" in text and "Infinity" in text


def test_save_figure_writes_and_closes(tmp_path):
    plt = pyplot()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    path = save_figure(fig, tmp_path / "f.png", dpi=50)
    assert path.is_file() and path.stat().st_size > 0
    assert not plt.fignum_exists(fig.number)
