"""Size of the exported HTML player per scene: the gzip'd payload with each mesh once, against the
previous encoding (every command as base64 of its msgpack), both measured on the same built scene.

    PYTHONPATH=. python benchmarks/viewer_html_size.py [--duration 1.0]   # writes benchmarks/out/viewer_html_size.json
"""

from __future__ import annotations

import argparse
import base64
import json
from pathlib import Path

import contactdyn
from contactdyn.scene.scene_file import sims_dir
from contactdyn.viewer import build_scene
from contactdyn.viewer.export import html_document, meshcat_js

OUT = Path(__file__).parent / "out"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=1.0, help="simulated time per scene [s]")
    args = parser.parse_args()
    rows = []
    js = len(meshcat_js().encode())  # [bytes] meshcat's viewer, inline in both encodings
    print(f"{'scene':22s} {'old [MB]':>9s} {'new [MB]':>9s} {'ratio':>6s}   (both include meshcat's {js / 1e6:.2f} MB "
          "of JavaScript)")
    for path in sorted(sims_dir().glob("*.toml")):
        result = contactdyn.simulate(path, {"duration": args.duration})
        scene = build_scene(result)
        new = len(html_document(scene).encode())
        old = js + sum(len(base64.b64encode(b)) + 4 for b in scene.packed())  # + quotes, comma, newline
        rows.append({"scene": path.stem, "old_bytes": old, "new_bytes": new, "ratio": new / old})
        print(f"{path.stem:22s} {old / 1e6:9.2f} {new / 1e6:9.2f} {new / old:6.2f}")
    OUT.mkdir(exist_ok=True)
    (OUT / "viewer_html_size.json").write_text(json.dumps({"duration_s": args.duration, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
