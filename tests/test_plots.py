"""Paper-style figures: the right figures for a run's channels, valid PNG/SVG, units on every axis."""

from __future__ import annotations

import argparse
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from contactdyn import simulate
from contactdyn.errors import ContactdynError
from contactdyn.output.plots import FIGURES, figure_names, plot_command, plot_result
from contactdyn.output.result import Result

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
UNIT = re.compile(r"\[[^\]]+\]")  #: "[N]", "[mm]", "[m/s]" ...
MAX_PNG_BYTES = 200_000  #: figures committed to docs/ must stay small


def synthetic_run() -> Result:
    """A hand-made run with every channel kind the figures read (case 1 and case 2 together)."""
    t = np.linspace(0.0, 2.0, 201)
    touch = t >= 1.0
    ramp = np.where(touch, 100.0 * (1.0 - np.exp(-(t - 1.0) / 0.2)), np.nan)
    F_n = np.where(touch, np.nan_to_num(ramp) + np.sin(20 * t), 0.0)
    tip = np.stack([0.3 + 0.05 * t, np.zeros_like(t), np.where(touch, -0.1 - 1e-3 * (t - 1.0), 0.1 - 0.2 * t)], 1)
    channels = {
        "t": t,
        "q": np.zeros((t.size, 2)),
        "u": np.stack([np.sin(t), np.cos(t)], 1),  # future motor voltages [V]
        "body.cart.u": 0.1 * t,
        "tip": tip,
        "tip_ref": tip + 1e-3,
        "body.cart.v": 0.25 + 0.001 * np.sin(t),
        "contact.tip.F_n": F_n,
        "contact.tip.F_d": ramp,
        "contact.tip.touching": touch.astype(float),
        "contact.tip.gap": np.where(touch, 0.0, 0.1 - 0.1 * t),
        "contact.tip.F_f": (-0.4 * F_n)[:, None],
        "contact.tip.v_slip": np.where(touch, 0.05, 0.0)[:, None],
        "contact.tip.stuck": np.zeros_like(t),
        "contact.tip.t1.F": 0.5 * F_n,
        "contact.tip.t1.F_d": ramp,
    }
    for d in ("n", "t1"):
        for s in ("env1", "env2", "rob1", "rob2"):
            channels[f"stage.tip.{d}.{s}.x"] = 1e-3 * np.sin(t * (1 + len(s)))
    scene = {"contact": {"tip": {"point": [0.3, 0.0, -0.1], "normal": {"direction": [0.0, 0.0, 1.0]},
                                 "tangent": {"directions": [[1.0, 0.0, 0.0]], "mu": 0.4}}},
             "body": {"cart": {"servo": {"velocity": 0.25}}}}
    events = [{"t": 1.0, "kind": "touch", "name": "tip"}, {"t": 1.0, "kind": "phase", "name": "contact"}]
    meta = {"name": "synthetic", "contacts": ["tip"], "bodies": ["cart"], "joints": ["q1", "q2"]}
    return Result(channels, events, [], {}, scene, meta)


def _check_png(path):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC, path
    assert len(data) < MAX_PNG_BYTES, f"{path}: {len(data)} bytes"
    import matplotlib.image

    image = matplotlib.image.imread(path)
    assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100


def _svg_texts(path) -> list[str]:
    root = ET.parse(path).getroot()
    assert root.tag.endswith("svg"), path
    return ["".join(e.itertext()) for e in root.iter() if e.tag.endswith("text")]


def test_synthetic_run_gives_every_figure_as_valid_png_and_svg(tmp_path):
    written = plot_result(synthetic_run(), tmp_path, "png,svg")
    assert sorted({p.stem for p in written}) == sorted(figure_names())
    for path in written:
        if path.suffix == ".png":
            _check_png(path)
        else:
            texts = _svg_texts(path)
            assert "time t [s]" in texts, path
            labelled = [s for s in texts if UNIT.search(s)]
            assert len(labelled) >= 2, f"{path}: axis labels with units, found {texts[:20]}"


@pytest.mark.parametrize("spec", FIGURES, ids=lambda s: s.name)
def test_every_panel_names_a_quantity_and_its_unit(spec):
    panels = spec.build(synthetic_run())
    assert panels, spec.name
    for panel in panels:
        assert UNIT.search(panel.ylabel) and len(panel.ylabel.split("[")[0].strip()) > 1, panel.ylabel
        assert panel.lines, f"{spec.name}: an empty panel"
        for line in panel.lines:
            assert line.t.shape == line.y.shape


def test_deformations_split_by_direction_and_named_as_in_the_paper():
    run = synthetic_run()
    vertical = dict(FIGURES_BY_NAME["fig12_deformations_vertical"].build(run)[0].__dict__)
    horizontal = FIGURES_BY_NAME["fig11_deformations_horizontal"].build(run)[0]
    assert "normal +z" in vertical["title"] and "tangent +x" in horizontal.title
    labels = [line.label for line in vertical["lines"]]
    assert labels == ["x″_e internal (env1)", "x′_e external (env2)", "x″_r internal (rob1)", "x′_r external (rob2)"]
    # deformations are drawn in millimetres
    np.testing.assert_allclose(vertical["lines"][0].y, 1e3 * run["stage.tip.n.env1.x"])


def test_a_horizontal_normal_puts_its_deformation_in_the_horizontal_figure(tmp_path):
    run = synthetic_run()
    run.scene["contact"]["tip"]["normal"]["direction"] = [0.0, 1.0, 0.0]  # a wall, under gravity -z
    run.scene["contact"]["tip"]["tangent"]["directions"] = [[1.0, 0.0, 0.0]]
    run.scene.setdefault("robot", {})["gravity"] = [0.0, 0.0, -9.81]
    horizontal = FIGURES_BY_NAME["fig11_deformations_horizontal"].build(run)
    assert {p.title for p in horizontal} == {"contact tip, normal +y", "contact tip, tangent +x"}
    assert FIGURES_BY_NAME["fig12_deformations_vertical"].build(run) is None


def test_without_gravity_the_normal_is_the_vertical_direction():
    """Benchmark B1 works in the horizontal plane without gravity: its normal +y goes to the "vertical" figure."""
    run = synthetic_run()
    run.scene["contact"]["tip"]["normal"]["direction"] = [0.0, 1.0, 0.0]
    run.scene["contact"]["tip"]["tangent"]["directions"] = [[1.0, 0.0, 0.0]]
    run.scene.setdefault("robot", {})["gravity"] = [0.0, 0.0, 0.0]
    (vertical,) = FIGURES_BY_NAME["fig12_deformations_vertical"].build(run)
    (horizontal,) = FIGURES_BY_NAME["fig11_deformations_horizontal"].build(run)
    assert vertical.title == "contact tip, normal +y" and horizontal.title == "contact tip, tangent +x"


def test_tracking_errors_stop_at_the_first_touch():
    run = synthetic_run()
    (panel,) = FIGURES_BY_NAME["fig16_tracking_errors"].build(run)
    assert all(line.t.max() <= 1.0 for line in panel.lines)
    np.testing.assert_allclose(panel.lines[0].y, 1.0)  # tip_ref − tip = 1 mm


def test_force_error_is_drawn_only_while_touching():
    run = synthetic_run()
    panels = FIGURES_BY_NAME["fig17_force_position_errors"].build(run)
    err = panels[0].lines[0].y
    assert np.all(np.isnan(err[run.t < 1.0]))
    np.testing.assert_allclose(err[run.t >= 1.0], np.sin(20 * run.t[run.t >= 1.0]), atol=1e-12)


def test_figures_a_run_lacks_are_skipped():
    run = synthetic_run()
    for key in [k for k in run.channels if k == "u" or k.endswith(".u") or k.startswith("body.")]:
        del run.channels[key]
    names = {spec.name for spec in FIGURES if spec.build(run)}
    assert names == set(figure_names()) - {"fig10_voltages", "fig10b_body_velocity"}
    del run.channels["contact.tip.t1.F"]  # friction but no tangential chain: Fig. 15 shows the forces
    assert FIGURES_BY_NAME["fig13_contact_forces"].build(run) is None


def test_real_run_saved_then_plotted_by_the_command(tmp_path, capsys):
    result = simulate("case2_writer_b", {"duration": 1.2, "solver.output_rate": 200.0})
    run = result.save(tmp_path / "runs" / "writer")
    code = plot_command(argparse.Namespace(run=str(run), out=None, format="png"))
    assert code == 0
    out = tmp_path / "runs" / "writer_figures"
    names = {p.stem for p in out.iterdir()}
    assert {"fig14_tip_motion", "fig15_forces_friction", "fig16_tracking_errors"} <= names
    assert len(list(out.glob("*.png"))) == len(names)
    for png in out.glob("*.png"):
        _check_png(png)
    assert "fig15_forces_friction" in capsys.readouterr().out


def small_run() -> Result:
    """Only a tip and its reference: two figures, cheap to draw."""
    full = synthetic_run()
    return Result({k: full.channels[k] for k in ("t", "q", "tip", "tip_ref")}, meta={"name": "small"})


def test_command_options_and_errors(tmp_path):
    run = small_run()
    run.save(tmp_path / "syn")
    assert plot_command(argparse.Namespace(run=str(tmp_path / "syn.json"), out=str(tmp_path / "figs"),
                                           format="svg")) == 0
    assert {p.suffix for p in (tmp_path / "figs").iterdir()} == {".svg"}
    # the command line passes formats as a list (--format png,svg split by the parser)
    assert plot_command(argparse.Namespace(run=str(tmp_path / "syn"), out=str(tmp_path / "figs2"),
                                           format=["png"])) == 0
    assert {p.suffix for p in (tmp_path / "figs2").iterdir()} == {".png"}
    with pytest.raises(ContactdynError, match="expected a comma-separated list of png, svg, found 'pdf'"):
        plot_result(run, tmp_path, "pdf")
    with pytest.raises(ContactdynError, match="not a saved run"):
        plot_command(argparse.Namespace(run=str(tmp_path / "missing"), out=None, format="png"))
    with pytest.raises(ContactdynError, match="unknown figure"):
        plot_result(run, tmp_path, "png", only=["fig99"])


def test_a_run_without_any_plottable_channel_says_so(tmp_path, capsys):
    empty = Result({"t": np.linspace(0, 1, 3), "q": np.zeros((3, 2))}, meta={"name": "empty"})
    empty.save(tmp_path / "empty")
    assert plot_command(argparse.Namespace(run=str(tmp_path / "empty"), out=None, format="png")) == 1
    assert "no figure applies" in capsys.readouterr().out


FIGURES_BY_NAME = {f.name: f for f in FIGURES}


def test_a_pure_force_law_run_shows_the_tip_depth_instead_of_a_position_error():
    run = synthetic_run()
    del run.channels["tip_ref"]
    run.scene["contact"]["tip"]["point"] = [0.3, 0.0, -0.1]
    panels = FIGURES_BY_NAME["fig17_force_position_errors"].build(run)
    assert [p.ylabel for p in panels] == ["force error F − F_d [N]"] * 2 + ["tip depth [mm]"]  # normal, tangent
    depth = panels[-1].lines[0].y
    touching = run.t >= 1.0
    assert np.all(np.isnan(depth[~touching]))
    np.testing.assert_allclose(depth[touching], 1e3 * 1e-3 * (run.t[touching] - 1.0), atol=1e-9)  # 1 mm/s sinking
