"""A Result in a notebook: a DataFrame, a short repr, an HTML summary, an inline player, documented methods."""

from __future__ import annotations

import inspect
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

from contactdyn import simulate
from contactdyn.output.result import Result

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def run() -> Result:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return simulate("b1", {"duration": 0.2, "solver.output_rate": 100.0})


def test_to_pandas_has_a_column_per_component_indexed_by_time(run):
    df = run.to_pandas()
    assert df.index.name == "t" and np.array_equal(df.index.to_numpy(), run.t)
    assert np.array_equal(df["q[1]"].to_numpy(), run["q"][:, 1])
    assert np.array_equal(df["contact.tip.F_f[0]"].to_numpy(), run["contact.tip.F_f"][:, 0])
    assert np.array_equal(df["contact.tip.F_n"].to_numpy(), run["contact.tip.F_n"])
    widths = sum(1 if np.ndim(v) == 1 else np.shape(v)[1] for k, v in run.channels.items() if k != "t")
    assert df.shape == (len(run.t), widths)


def test_the_repr_is_one_short_line_with_the_runs_summary(run):
    text = repr(run)
    peak = run["contact.tip.F_n"].max()
    assert "\n" not in text and len(text) < 200
    assert text.startswith("<Result b1: 0.2 s") and f"tip {peak:.4g} N" in text and "0 impacts" in text


def test_the_html_summary_is_a_table_with_the_peaks_and_warnings(run):
    page = run._repr_html_()
    assert page.startswith("<table>") and "peak F_n tip" in page and "b1" in page
    doctored = Result(run.channels, meta={**run.meta, "check_warnings": ["physics check: <x> & y"]})
    assert "physics check: &lt;x&gt; &amp; y" in doctored._repr_html_()


def test_show_gives_the_player_inline_in_an_iframe(run):
    player = run.show(height=300)
    page = player._repr_html_()
    assert page.startswith("<iframe srcdoc=") and "height: 300px" in page
    assert "MeshCat.Viewer" in page and "<script>" not in page  # the page is escaped inside srcdoc


def test_result_and_its_public_methods_are_documented():
    assert inspect.getdoc(Result) and len(inspect.getdoc(Result).splitlines()) > 3
    for name in ("t", "to_pandas", "summary", "show", "save", "__getitem__"):
        assert inspect.getdoc(getattr(Result, name)), name


def test_the_package_says_it_is_typed():
    assert (ROOT / "contactdyn" / "py.typed").exists()
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert "py.typed" in data["contactdyn"]
