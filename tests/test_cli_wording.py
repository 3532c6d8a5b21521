"""Small things a user reads: controller descriptions, speed-up wording, bad playback speeds, bench defaults."""

from __future__ import annotations

import json

import pytest

from contactdyn.analysis.workprecision import _speed_words
from contactdyn.cli import EXIT_OK, EXIT_USAGE, build_parser, main


def test_every_controller_has_a_description(capsys):
    assert main(["list", "controllers", "--json"]) == EXIT_OK
    controllers = json.loads(capsys.readouterr().out)["controllers"]
    assert len(controllers) >= 7
    assert all(len(c["description"]) > 20 for c in controllers), controllers


def test_a_slowdown_is_called_slower():
    assert _speed_words(2.5) == "2.5× faster" and _speed_words(1.0) == "1.0× faster"
    assert _speed_words(0.6) == "1.7× slower"  # not "0.6× faster"


@pytest.mark.parametrize("speed", ["0", "-1", "nan", "inf", "fast"])
def test_a_bad_playback_speed_is_bad_input(capsys, tmp_path, speed):
    assert main(["view", str(tmp_path / "run"), "--speed", speed]) == EXIT_USAGE
    assert "--speed" in capsys.readouterr().err
    assert main(["run", "b1", "--view", "--speed", speed]) == EXIT_USAGE  # before the run starts


def test_bench_help_states_its_defaults():
    text = build_parser()._subparsers._group_actions[0].choices["bench"].format_help()
    assert "default DOP853,RK45" in text and "default 3" in text and "out/bench/SCENE" in text
