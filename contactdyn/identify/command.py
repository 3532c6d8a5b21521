"""``contactdyn fit``: the command-line front of :func:`~contactdyn.identify.fitting.fit`."""

from __future__ import annotations

import argparse
import json
import math

from ..errors import SceneError
from .fitting import fit
from .report import as_dict, save_scene, text, write_report

__all__ = ["fit_command", "parse_noise"]


def parse_noise(items: list[str]) -> dict[str, float]:
    """``COLUMN=SIGMA`` items (σ in the column's unit, > 0)."""
    out = {}
    for item in items:
        name, sep, value = (s.strip() for s in item.rpartition("="))
        try:
            sigma = float(value)
        except ValueError:
            sigma = math.nan
        if not sep or not name or not (math.isfinite(sigma) and sigma > 0):
            raise SceneError("--noise", "COLUMN=SIGMA with SIGMA > 0 in the column's unit", item)
        out[name] = sigma
    return out


def fit_command(args: argparse.Namespace) -> int:
    from ..scene.scene_file import parse_override

    overrides = dict(parse_override(s) for s in args.set)
    result = fit(args.scene, args.data, args.params, overrides=overrides, noise=parse_noise(args.noise),
                 starts=args.starts, seed=args.seed, workers=args.workers, stages=args.stages,
                 rtol=args.rtol, atol=args.atol)
    paths = write_report(result, args.out) if args.out else {}
    scene_path = save_scene(result, args.save_scene) if args.save_scene else None
    if args.json:
        doc = as_dict(result)
        doc["files"] = {k: str(v) for k, v in paths.items()} | ({"scene": str(scene_path)} if scene_path else {})
        print(json.dumps(doc, indent=1, allow_nan=False))
    elif not args.quiet:
        print(text(result))
        for path in [*paths.values(), *([scene_path] if scene_path else [])]:
            print(f"  wrote {path}")
    return 0
