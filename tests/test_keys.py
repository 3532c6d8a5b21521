"""The scene key reference (docs/scenes.md, `contactdyn list keys`) is complete and current."""

from __future__ import annotations

import ast
import json
import tomllib
from pathlib import Path

import pytest

from contactdyn.cli import EXIT_OK, EXIT_USAGE, main
from contactdyn.errors import SceneError
from contactdyn.scene.keys import _display, keyfields_source, markdown, reference
from contactdyn.scene.reader import recording, table_fields
from contactdyn.scene.scene_file import load_scene, parse_scene, sims_dir

ROOT = Path(__file__).resolve().parent.parent
#: modules whose Reader calls define scene keys
READERS = ["scene/scene_file.py", "laws/drives.py", *(f"laws/controllers/{m}.py" for m in
           ("base", "pd", "force", "voltage", "dynamic", "operational"))]
READ_METHODS = {"float", "int", "bool", "str", "vector", "raw", "has", "sub", "tables", "named_tables", "error"}
KEY_HELPERS = {"_gain": slice(1, 2), "_gains": slice(1, 2), "_read_stage": slice(1, 3), "_read_elements": slice(1, 2)}


@pytest.fixture
def builtin_laws_only(monkeypatch):
    """The law registries as the package ships them: a user's law registered by an earlier test in this process
    (examples/cubic_stage.py by test_pipeline_proto, say) is not part of the package's key reference."""
    from contactdyn.laws.controllers import CONTROLLERS
    from contactdyn.laws.drive_kinds import DRIVE_KINDS
    from contactdyn.laws.friction_laws import FRICTION_LAWS
    from contactdyn.laws.stage_laws import STAGE_LAWS

    for registry in (CONTROLLERS, DRIVE_KINDS, FRICTION_LAWS, STAGE_LAWS):
        for name, cls in list(registry.items()):
            if not cls.__module__.startswith("contactdyn."):
                monkeypatch.delitem(registry, name)


def test_docs_scenes_md_and_keyfields_are_generated_from_the_reader(builtin_laws_only):
    assert (ROOT / "docs" / "scenes.md").read_text() == markdown(),\
        "docs/scenes.md is stale: python -m contactdyn.scene.keys"
    assert (ROOT / "contactdyn" / "scene" / "keyfields.py").read_text() == keyfields_source(), \
        "contactdyn/scene/keyfields.py is stale: python -m contactdyn.scene.keys"


def test_every_row_has_a_meaning_type_and_resolved_choices():
    for d in reference():
        assert d.meaning, f"{d.key}: add a line to contactdyn.scene.keys.MEANINGS"
        assert d.type != "any", f"{d.key}: the reader reads it raw; give its type in contactdyn.scene.keys.OVERRIDES"
        assert "?" not in (d.allowed, d.default), \
            f"{d.key}: choices or default depend on the scene ({d.allowed!r}, {d.default!r}); say so in OVERRIDES"


def _scene_files() -> list[Path]:
    return sorted(sims_dir().glob("*.toml")) + sorted((ROOT / "benchmarks" / "hard").glob("*.toml"))


def test_every_key_of_every_shipped_scene_is_in_the_reference():
    keys = {d.key for d in reference()}
    with recording() as reads:
        for path in _scene_files():
            load_scene(path)
    missing = {_display(r.pattern) for r in reads} - keys
    assert not missing, f"keys read but not in the reference: {sorted(missing)}"


def _literal_keys(path: Path) -> set[str]:
    """String literals naming keys in the module's Reader calls: r.float("k", ...), _gain(r, "kp", ...)."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.Call):
            continue
        func = node.func
        if isinstance(func, ast.Attribute) and func.attr in READ_METHODS and node.args:
            args = node.args[:1]
        elif isinstance(func, ast.Name) and func.id in KEY_HELPERS:
            args = node.args[KEY_HELPERS[func.id]]
        else:
            continue
        names |= {a.value for a in args if isinstance(a, ast.Constant) and isinstance(a.value, str)}
    return names


def test_every_key_name_in_the_reader_source_is_in_the_reference():
    """A key added in a branch the tour does not reach (contactdyn/scene/keytour.py) fails here."""
    from contactdyn.laws.drive_kinds import DRIVE_KINDS

    leaves = {d.key.rpartition(".")[2].removesuffix("[]") for d in reference()} | {d.key for d in reference()}
    names = set().union(*(_literal_keys(ROOT / "contactdyn" / m) for m in READERS))
    names |= {p.name for kind in DRIVE_KINDS.values() for p in kind.params}
    names -= {"a"}  # the reader's own item wrapper ({"a": axis})
    names = {n for n in names if not n.startswith("body.ground")}  # an error key, not a read
    missing = sorted(n for n in names if n not in leaves and "." not in n)
    assert not missing, f"keys the reader accepts but the reference lacks (extend scene/keytour.py): {missing}"


def test_a_table_error_names_its_fields():
    doc = tomllib.loads((sims_dir() / "b1.toml").read_text())
    with pytest.raises(SceneError, match=r"phase\[0\]\.force: expected an array of tables with fields "
                                         r"value \(required\), contact, start, duration"):
        parse_scene(doc, {"phase.0.force": 20})
    with pytest.raises(SceneError, match=r"contact\.tip\.normal: expected a table with fields direction "
                                         r"\(required\), .*model"):
        parse_scene(doc, {"contact.tip.normal": 20})
    assert table_fields("phase[0].reference.moves[1]").startswith("duration (required), kind")
    assert table_fields("solver") .startswith("method, rtol, atol")


def test_a_misspelt_required_key_is_named_beside_the_missing_one():
    doc = tomllib.loads((sims_dir() / "b1.toml").read_text())
    doc["durration"] = doc.pop("duration")
    with pytest.raises(SceneError) as info:
        parse_scene(doc)
    assert info.value.key == "duration" and "the table has 'durration': a misspelling?" in str(info.value)
    del doc["durration"]  # missing, nothing close: no hint
    with pytest.raises(SceneError) as info:
        parse_scene(doc)
    assert info.value.key == "duration" and "misspelling" not in str(info.value)
    doc = tomllib.loads((sims_dir() / "b1.toml").read_text())
    tangent = doc["contact"]["tip"]["tangent"]
    tangent["muu"] = tangent.pop("mu")  # (a friction law's own required key)
    with pytest.raises(SceneError) as info:
        parse_scene(doc)
    assert info.value.key == "contact.tip.tangent.mu" and "the table has 'muu': a misspelling?" in str(info.value)


def test_unknown_key_message_reads_as_one_sentence():
    doc = tomllib.loads((sims_dir() / "b1.toml").read_text())
    with pytest.raises(SceneError) as info:
        parse_scene(doc, {"contact.tip.normal.kk": 1.0})
    assert str(info.value) == ("contact.tip.normal.kk: unknown key; did you mean 'k'? "
                               "(known here: b, direction, environment, k, law, m, model, robot)")  # (a chain's too)


def test_list_keys_prints_the_reference(capsys):
    assert main(["list", "keys", "phase[].force"]) == EXIT_OK
    out = capsys.readouterr().out
    assert "phase[].force[].value: number, [N], required" in out and "contact.<contact>" not in out
    assert main(["list", "keys", "solver.rtol", "--json"]) == EXIT_OK
    rows = json.loads(capsys.readouterr().out)["keys"]
    assert rows == [{"key": "solver.rtol", "when": "", "type": "number", "unit": "", "default": "1e-08",
                     "allowed": ">= 1e-14, <= 0.1", "meaning": "relative tolerance"}]
    assert main(["list", "keys", "nosuch"]) == EXIT_USAGE
    assert "scene key" in capsys.readouterr().err


@pytest.mark.parametrize("prefix, first, absent", [
    ("contact.pencil.normal.k", "contact.<contact>.normal.k (when", "normal.b"),  # a contact's own name
    ("phase[1].force", "phase[].force: array of tables", "phase[].reference"),  # an index
    ("phase.force.val", "phase[].force[].value: number", "force[].contact"),  # as in a [[phase.force]] header
    ("body.cart.", "body.<body>.mass", "body.<body>: table"),  # a trailing dot: the table's keys only
])
def test_list_keys_takes_the_names_a_scene_uses(prefix, first, absent, capsys):
    assert main(["list", "keys", prefix]) == EXIT_OK
    out = capsys.readouterr().out
    assert first in out and absent not in out, out
    assert main(["list", "keys", prefix + ".zz"]) == EXIT_USAGE and "scene key" in capsys.readouterr().err


# ---- which file runs -------------------------------------------------------------------------
def test_a_scene_name_is_found_in_the_working_directory_sims_first(tmp_path, monkeypatch, capsys):
    (tmp_path / "sims").mkdir()
    local = tmp_path / "sims" / "b1.toml"
    local.write_text((sims_dir() / "b1.toml").read_text().replace("duration = 2.0", "duration = 0.01"))
    monkeypatch.chdir(tmp_path)
    assert load_scene("b1").duration == 0.01 and Path(load_scene("b1").file) == local
    assert main(["run", "b1", "--set", "solver.output_rate=200"]) == EXIT_OK
    assert f"scene b1: {local}" in capsys.readouterr().out
    monkeypatch.chdir(ROOT / "tests")  # no sims/ here: the installed copy
    assert load_scene("b1").duration == 2.0


def test_a_relative_urdf_path_resolves_against_the_scene_file(tmp_path, monkeypatch):
    from contactdyn.robot.robot import urdf_dir

    (tmp_path / "robots").mkdir()
    (tmp_path / "robots" / "arm.urdf").write_text((urdf_dir() / "planar2r_b1.urdf").read_text())
    text = (sims_dir() / "b1.toml").read_text().replace('urdf = "planar2r_b1"', 'urdf = "robots/arm.urdf"')
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "mine.toml").write_text(text.replace('"robots/', '"../robots/'))
    monkeypatch.chdir(ROOT)  # elsewhere: the working directory does not matter
    scene = load_scene(tmp_path / "scenes" / "mine.toml")
    assert scene.robot.source == str(tmp_path / "robots" / "arm.urdf")
    bad = tmp_path / "scenes" / "bad.toml"
    bad.write_text(text)  # robots/arm.urdf beside the scene does not exist: named where it was looked for
    with pytest.raises(SceneError, match="scenes/robots/arm.urdf"):
        from contactdyn.model.system import System

        System(load_scene(bad))
