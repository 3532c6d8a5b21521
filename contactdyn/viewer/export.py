"""A self-contained HTML player: meshcat's JavaScript (from its wheel) plus the scene's commands.

Unlike meshcat's own ``static_html`` (one asynchronous ``fetch`` per command, served by a
running zmq server), the commands are decoded and applied synchronously in order, so the
page is complete when its script ends (``window.contactdyn.ready``) and needs no server,
no network and no browser to be written.
"""

from __future__ import annotations

import base64
import html
import json
import os
from pathlib import Path

import meshcat

from ..result import Result
from .build import build_scene
from .writer import ViewerScene

__all__ = ["export_html", "html_document", "meshcat_js"]


def meshcat_js() -> str:
    """meshcat's bundled viewer (three.js and all), shipped inside the meshcat wheel."""
    return (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text()


def html_document(scene: ViewerScene, title: str = "contactdyn run") -> str:
    commands = ",\n".join(json.dumps(base64.b64encode(b).decode("ascii")) for b in scene.packed())
    legend = "<br>".join(html.escape(line) for line in scene.legend + scene.notes)
    info = json.dumps({"duration": scene.duration, "speed": scene.speed, "groups": scene.groups})
    script_js = meshcat_js().replace("</script", "<\\/script")
    return f"""<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>
body {{ margin: 0; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
#legend {{ position: absolute; left: 8px; bottom: 8px; max-width: 60vw; padding: 6px 8px;
  font: 12px sans-serif; color: #111; background: rgba(255, 255, 255, 0.75); border-radius: 4px; }}
</style></head>
<body>
<div id="meshcat-pane"></div>
<div id="legend">{legend}</div>
<script>{script_js}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
(function () {{
  const commands = [{commands}];
  for (const c of commands) {{
    const bytes = Uint8Array.from(atob(c), ch => ch.charCodeAt(0));
    viewer.handle_command_bytearray(bytes);
  }}
  window.contactdyn = Object.assign({info}, {{ready: true}});
}})();
</script>
</body>
</html>
"""


def export_html(result: Result | ViewerScene, path: str | os.PathLike, *, speed: float = 1.0) -> Path:
    """Write a self-contained HTML player of ``result`` (or of a built scene) to ``path``; return it."""
    scene = result if isinstance(result, ViewerScene) else build_scene(result, speed=speed)
    title = scene.legend[0].split(":")[0] if scene.legend else "contactdyn run"
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(f".{out.name}.tmp")
    tmp.write_text(html_document(scene, title), encoding="utf-8")
    os.replace(tmp, out)
    return out
