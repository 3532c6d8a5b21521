"""A self-contained HTML player: meshcat's JavaScript (from its wheel) plus the scene's commands.

Unlike meshcat's own ``static_html`` (one asynchronous ``fetch`` per command, served by a
running zmq server), the commands travel as one gzip'd payload holding each mesh file once
(:func:`pack_payload`), which the page inflates synchronously (``inflate.js``, ours: ~8 MB in
0.15 s) and applies in order while its script runs, so the scene is drawn before the page's
load event (a plain headless ``--screenshot`` shows it); then the animation plays from t = 0,
looping. ``window.contactdyn.ready`` is set when the scene is complete. No server, no network
and no browser are needed to write it.
"""

from __future__ import annotations

import base64
import copy
import gzip
import html
import json
import os
import re
import struct
from pathlib import Path

import meshcat
import umsgpack

from ..output.result import Result, atomic_write
from .build import build_scene
from .writer import ViewerScene

__all__ = ["export_html", "html_document", "meshcat_js", "pack_payload", "unpack_payload", "html_payload"]


def meshcat_js() -> str:
    """meshcat's bundled viewer (three.js and all), shipped inside the meshcat wheel."""
    return (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text()


MAGIC = b"CDV1"  #: payload format: meshes once, then the commands (see :func:`pack_payload`)
MESH_MARK = "\x00mesh:"  #: a command's mesh data replaced by a reference to the payload's mesh table


def pack_payload(scene: ViewerScene) -> bytes:
    """The scene as one gzip'd binary: each distinct mesh file once, then the msgpack'd commands.

    Layout: ``CDV1``, u32 mesh count, per mesh (u8 0 text / 1 bytes, u32 length, data), u32
    command count, per command (u32 length, msgpack). A command's mesh ``data`` becomes the
    string ``"\\0mesh:<index>"``. gzip shrinks the Collada text ~5× (base64 then adds a third).
    """
    meshes: dict[bytes, int] = {}
    table: list[tuple[int, bytes]] = []

    def mesh_ref(data) -> str:
        raw = (1, bytes(data.data)) if isinstance(data, umsgpack.Ext) else (0, str(data).encode())
        if raw[1] not in meshes:
            meshes[raw[1]] = len(table)
            table.append(raw)
        return f"{MESH_MARK}{meshes[raw[1]]}"

    commands = [umsgpack.packb(_extract_meshes(c, mesh_ref)) for c in scene.commands]
    body = [MAGIC, struct.pack("<I", len(table))]
    for kind, data in table:
        body += [struct.pack("<BI", kind, len(data)), data]
    body.append(struct.pack("<I", len(commands)))
    for c in commands:
        body += [struct.pack("<I", len(c)), c]
    return gzip.compress(b"".join(body), compresslevel=6, mtime=0)


def _extract_meshes(command: dict, mesh_ref) -> dict:
    """A copy of a ``set_object`` command with its mesh file contents replaced by references."""
    if command.get("type") != "set_object":
        return command
    command = copy.copy(command)
    obj = command["object"] = dict(command["object"])
    if obj.get("geometries"):
        obj["geometries"] = [dict(g, data=mesh_ref(g["data"])) if g.get("type") == "_meshfile_geometry" else g
                             for g in obj["geometries"]]
    inner = obj.get("object")
    if isinstance(inner, dict) and inner.get("type") == "_meshfile_object":
        obj["object"] = dict(inner, data=mesh_ref(inner["data"]))
    return command


def unpack_payload(payload: bytes) -> list[dict]:
    """The commands of :func:`pack_payload`, mesh data restored (for tests and tools)."""
    buf = gzip.decompress(payload)
    if buf[:4] != MAGIC:
        raise ValueError("not a contactdyn viewer payload")
    pos, meshes = 8, []
    for _ in range(struct.unpack_from("<I", buf, 4)[0]):
        kind, n = struct.unpack_from("<BI", buf, pos)
        data = buf[pos + 5:pos + 5 + n]
        meshes.append(umsgpack.Ext(0x12, data) if kind else data.decode())
        pos += 5 + n
    commands = []
    (count,) = struct.unpack_from("<I", buf, pos)
    pos += 4
    for _ in range(count):
        (n,) = struct.unpack_from("<I", buf, pos)
        commands.append(_restore(umsgpack.unpackb(buf[pos + 4:pos + 4 + n]), meshes))
        pos += 4 + n
    return commands


def _restore(x, meshes):
    if isinstance(x, str) and x.startswith(MESH_MARK):
        return meshes[int(x[len(MESH_MARK):])]
    if isinstance(x, dict):
        return {k: _restore(v, meshes) for k, v in x.items()}
    if isinstance(x, list):
        return [_restore(v, meshes) for v in x]
    return x


def html_payload(text: str) -> bytes:
    """The payload embedded in an exported HTML file."""
    return base64.b64decode(re.search(r'const payload = "([A-Za-z0-9+/=]*)";', text).group(1))


def html_document(scene: ViewerScene, title: str = "contactdyn run") -> str:
    payload = base64.b64encode(pack_payload(scene)).decode("ascii")
    legend = "<br>".join(html.escape(line) for line in scene.legend + scene.notes)
    info = json.dumps({"duration": scene.duration, "speed": scene.speed, "groups": scene.groups})
    script_js = meshcat_js().replace("</script", "<\\/script")
    inflate_js = (Path(__file__).parent / "inflate.js").read_text()
    return f"""<!DOCTYPE html>
<html>
<head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>
body {{ margin: 0; }}
#meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}
#legend {{ position: absolute; left: 8px; top: 8px; max-width: 60vw; padding: 6px 8px;
  font: 12px sans-serif; color: #111; background: rgba(255, 255, 255, 0.75); border-radius: 4px; }}
</style></head>
<body>
<div id="meshcat-pane"></div>
<div id="legend">{legend}</div>
<script>{script_js}</script>
<script>{inflate_js}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
(function () {{  // synchronous: the scene is drawn before the page's load event
  const payload = "{payload}";
  const zipped = Uint8Array.from(atob(payload), ch => ch.charCodeAt(0));
  const buf = contactdynInflate(zipped);
  const view = new DataView(buf.buffer, buf.byteOffset, buf.byteLength);
  let pos = 4;  // after the magic "CDV1"
  const meshes = [];
  const nMeshes = view.getUint32(pos, true); pos += 4;
  for (let i = 0; i < nMeshes; i++) {{
    const kind = buf[pos], n = view.getUint32(pos + 1, true);
    const data = buf.slice(pos + 5, pos + 5 + n);
    meshes.push(kind === 0 ? new TextDecoder().decode(data) : data);
    pos += 5 + n;
  }}
  const restore = x => {{
    if (typeof x === "string" && x.startsWith("\\u0000mesh:")) return meshes[Number(x.slice(6))];
    if (Array.isArray(x)) return x.map(restore);
    if (x && typeof x === "object" && x.constructor === Object) {{
      for (const k of Object.keys(x)) x[k] = restore(x[k]);
    }}
    return x;
  }};
  const handle = viewer.handle_command.bind(viewer);
  viewer.handle_command = cmd => handle(cmd.type === "set_object" ? restore(cmd) : cmd);
  const nCommands = view.getUint32(pos, true); pos += 4;
  for (let i = 0; i < nCommands; i++) {{
    const n = view.getUint32(pos, true);
    viewer.handle_command_bytearray(buf.slice(pos + 4, pos + 4 + n));
    pos += 4 + n;
  }}
  viewer.handle_command = handle;
  viewer.animator.reset();  // open at t = 0 and play, looping (the time spent loading is not played)
  viewer.animator.play();
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
    atomic_write(out, html_document(scene, title))
    return out
