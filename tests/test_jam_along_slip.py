"""Case 2's impulse ratio under the paper's impact procedure (benchmarks/jam_along_slip.py; docs/reproduction.md,
"The ratio 0.427 > μ"): where the jamming branch, without a cone test, exceeds μ."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

import jam_along_slip  # noqa: E402


@pytest.fixture(scope="module")
def rows():
    return jam_along_slip.scan()


def test_every_ratio_over_mu_is_a_jam_pushing_along_the_slip_far_out_on_the_surface(rows):
    over = [r for r in rows if r["ratio"] > jam_along_slip.MU * (1 + 1e-9)]
    assert len(rows) == 1353 and len(over) == 81
    assert all(r["jammed"] and r["along_slip"] for r in over)
    assert min(r["x"] for r in over) == pytest.approx(0.41)
    assert max(r["ratio"] for r in over) == pytest.approx(0.875, abs=5e-4)


def test_the_papers_0427_is_a_jam_along_the_slip_at_x_045(rows):
    at = {r["direction"]: r for r in rows if abs(r["x"] - 0.45) < 1e-9}
    assert at["-5°"]["ratio"] == pytest.approx(0.427, abs=1e-3)  # approached 5° from the vertical
    assert at["-10°"]["ratio"] < 0.427 < at["-4°"]["ratio"]
    assert at["-5°"]["jammed"] and at["-5°"]["along_slip"]


def test_the_scenes_touch_is_a_jam_inside_the_cone(rows):
    at_b = next(r for r in rows if r["direction"] == "scene" and abs(r["x"] - 0.30) < 1e-9)
    assert at_b["jammed"] and not at_b["along_slip"]
    assert at_b["ratio"] == pytest.approx(0.3972, abs=5e-5)
