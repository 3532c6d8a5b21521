"""Save every scene's outputs, or compare a run against outputs saved before a change.

    python benchmarks/compare_outputs.py save DIR [SCENE ...]
    python benchmarks/compare_outputs.py compare DIR [SCENE ...] [--rtol 1e-12] [--interpreted]

Runs every scene in ``sims/`` and ``benchmarks/hard/``, plus the extra settings that
``benchmarks/hard_cases.py`` runs (``stiff_1e10``, ``grazing_first_touch``), each at its
own settings with no duration override. ``save`` writes ``DIR/<scene>.npz`` (all channels)
and ``DIR/<scene>.json`` (events, impacts). ``compare`` reruns and reports, per scene, the
largest relative difference over all channels,

    max |new − old| / max(|old|_∞ per channel, 1e-300),

(NaN equal to NaN), and checks that the events (kind, name, time) and impacts are the same
(times to the same relative tolerance). Exit 1 if any scene differs by more than ``--rtol``
or a scene fails to run. Refactors of the model must keep every scene within 1e-12. ``--interpreted``: the runs take
the compiled call's functions interpreted (:mod:`contactdyn.numerics.twins`, a scene kind's first run): against
outputs saved on the compiled call, what the first run gives that a later one would not.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

from contactdyn.hybrid.loop import HybridRun  # noqa: E402
from contactdyn.model.system import System  # noqa: E402
from contactdyn.output.result import jsonable  # noqa: E402
from contactdyn.scene.scene_file import load_scene, sims_dir  # noqa: E402

HERE = Path(__file__).resolve().parent
EXTRA = {  # the settings benchmarks/hard_cases.py runs beyond the scenes' own
    "hard_stiff_1e10": (HERE / "hard" / "stiff.toml", {"contact.tip.normal.k": 1e10, "contact.tip.normal.b": 3.0e5}),
    "hard_grazing_first_touch": ("b1", {"contact.tip.bonded": False, "solver.method": "auto"}),
}


def cases() -> dict[str, tuple[object, dict]]:
    """name: (scene path or name, overrides) of every compared run."""
    out: dict[str, tuple[object, dict]] = {}
    for path in sorted(sims_dir().glob("*.toml")):
        out[path.stem] = (path, {})
    for path in sorted((HERE / "hard").glob("*.toml")):
        out["hard_" + path.stem] = (path, {})
    out.update(EXTRA)
    return out


def run_case(scene, overrides: dict, interpreted: bool = False) -> tuple[dict[str, np.ndarray], dict]:
    """(channels, {"events", "impacts"}) of one run (``interpreted``: on the interpreted call)."""
    result = HybridRun(System(load_scene(scene, overrides)), interpreted=interpreted).run(time.perf_counter())
    return dict(result.channels), {"events": result.events, "impacts": result.impacts}


def _numbers(doc) -> list[float]:
    """The floats of an event/impact list, in order (non-numbers ignored)."""
    out: list[float] = []
    if isinstance(doc, dict):
        for key in sorted(doc):
            out += _numbers(doc[key])
    elif isinstance(doc, (list, tuple)):
        for item in doc:
            out += _numbers(item)
    elif isinstance(doc, (int, float)) and not isinstance(doc, bool):
        out.append(float(doc))
    return out


def _labels(doc) -> list[str]:
    """The strings of an event/impact list, in order."""
    out: list[str] = []
    if isinstance(doc, dict):
        for key in sorted(doc):
            out += [str(key)] + _labels(doc[key])
    elif isinstance(doc, (list, tuple)):
        for item in doc:
            out += _labels(item)
    elif isinstance(doc, str):
        out.append(doc)
    return out


def rel_diff(new: np.ndarray, old: np.ndarray) -> float:
    """max |new − old| / max |old| over one channel; NaN equals NaN; inf if shapes differ."""
    new, old = np.asarray(new, float), np.asarray(old, float)
    if new.shape != old.shape:
        return float("inf")
    same_nan = np.isnan(new) & np.isnan(old)
    if np.any(np.isnan(new) != np.isnan(old)):
        return float("inf")
    diff = np.where(same_nan, 0.0, np.abs(new - old))
    scale = np.nanmax(np.abs(old)) if old.size and not np.all(np.isnan(old)) else 0.0
    return float(np.max(diff, initial=0.0) / max(scale, 1e-300))


def compare_case(channels, doc, saved: Path) -> tuple[float, str, str]:
    """(max rel diff over channels, worst channel, event verdict) against ``saved``."""
    with np.load(saved.with_suffix(".npz")) as data:
        old = {k: data[k] for k in data.files}
    old_doc = json.loads(saved.with_suffix(".json").read_text())
    worst, worst_name = 0.0, "-"
    for name in sorted(set(old) | set(channels)):
        d = rel_diff(channels[name], old[name]) if name in old and name in channels else float("inf")
        if d > worst:
            worst, worst_name = d, name
    new_doc = json.loads(json.dumps(doc, default=jsonable))
    verdict = "same"
    for key in ("events", "impacts"):
        if len(new_doc[key]) != len(old_doc[key]):
            verdict = f"{key}: {len(new_doc[key])} vs {len(old_doc[key])}"
            break
        if _labels(new_doc[key]) != _labels(old_doc[key]):
            verdict = f"{key}: kinds/names differ"
            break
        a, b = np.array(_numbers(new_doc[key])), np.array(_numbers(old_doc[key]))
        if a.shape != b.shape:
            verdict = f"{key}: fields differ"
            break
        if a.size:
            d = float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300 + 1e-12 * np.max(np.abs(b)))))
            worst = max(worst, d)
            if d > 0 and worst == d:
                worst_name = key
    return worst, worst_name, verdict


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("action", choices=["save", "compare"])
    ap.add_argument("dir", type=Path)
    ap.add_argument("scenes", nargs="*", help="subset of case names (default: all)")
    ap.add_argument("--rtol", type=float, default=1e-12)
    ap.add_argument("--interpreted", action="store_true", help="run on the interpreted call (numerics.twins)")
    args = ap.parse_args(argv)
    todo = cases()
    names = args.scenes or list(todo)
    unknown = [n for n in names if n not in todo]
    if unknown:
        print(f"unknown case(s) {unknown}; known: {sorted(todo)}", file=sys.stderr)
        return 2
    args.dir.mkdir(parents=True, exist_ok=True)
    failed = 0
    print(f"{'case':32s} {'wall [s]':>8s} {'max rel diff':>12s}  channel / verdict")
    for name in names:
        scene, overrides = todo[name]
        t0 = time.perf_counter()
        try:
            channels, doc = run_case(scene, overrides, args.interpreted)
        except Exception as exc:  # report and go on: a broken scene must not hide the others
            print(f"{name:32s} FAILED: {type(exc).__name__}: {exc}")
            failed += 1
            continue
        wall = time.perf_counter() - t0
        path = args.dir / name
        if args.action == "save":
            np.savez(path.with_suffix(".npz"), **channels)
            path.with_suffix(".json").write_text(json.dumps(doc, default=jsonable))
            print(f"{name:32s} {wall:8.2f} {'saved':>12s}  {len(channels)} channels, {len(doc['events'])} events")
            continue
        if not path.with_suffix(".npz").exists():  # a scene the baseline's tree did not have
            print(f"{name:32s} {wall:8.2f} {'new':>12s}  no baseline: {len(channels)} channels, "
                  f"{len(doc['events'])} events")
            continue
        worst, channel, verdict = compare_case(channels, doc, path)
        bad = worst > args.rtol or verdict != "same"
        failed += bad
        print(f"{name:32s} {wall:8.2f} {worst:12.2e}  {channel} / {verdict}{'  <-- DIFFERS' if bad else ''}")
    print(f"{failed} case(s) differ or failed" if failed else "all cases agree")
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
