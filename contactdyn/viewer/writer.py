"""A meshcat scene as a list of lowered commands: objects, static transforms, animation tracks.

:class:`SceneWriter` collects what meshcat's ``Visualizer`` would send (``set_object``,
``set_transform``, ``set_property``, ``set_animation``) without any server, so a scene is
built headless and then either written into a self-contained HTML file or sent to a live
meshcat server. Animation keys are in simulated seconds; the clip's ``fps`` is the
playback speed, so the browser plays at ``speed`` × real time (meshcat scales key times
by 1/fps).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import meshcat.geometry as mg
import numpy as np
import umsgpack
from meshcat.commands import SetObject
from meshcat.path import Path as MeshcatPath
from scipy.spatial.transform import Rotation

__all__ = ["SceneWriter", "ViewerScene", "TextTexture", "MeshFileGeometry", "MeshFileObject", "Plane", "Cone",
           "color_int", "ROOT"]

ROOT = "/meshcat"
TINY = 1e-6  #: scale standing for "invisible" (three.js dislikes exactly singular matrices)


@dataclass
class ViewerScene:
    """A run drawn for meshcat: lowered commands in order, and what a reader needs to know."""

    commands: list[dict[str, Any]]  #: meshcat commands (dicts as msgpack'd to the viewer)
    duration: float  #: [s] simulated time covered by the animation
    speed: float  #: playback speed (1 = real time)
    legend: list[str]  #: scales and events, one line each
    notes: list[str] = field(default_factory=list)  #: what could not be drawn, and why
    groups: dict[str, str] = field(default_factory=dict)  #: part name -> meshcat path (robot, environment, ...)
    #: drawing scales: ``size`` L [m], ``stage_length`` ℓ [m], ``magnification`` S [-], ``arrow`` [m/N]
    scales: dict[str, float] = field(default_factory=dict)

    def packed(self) -> list[bytes]:
        """The commands as the msgpack messages meshcat's JavaScript decodes."""
        return [umsgpack.packb(c) for c in self.commands]


def color_int(rgba) -> tuple[int, float]:
    """(0xRRGGBB, opacity) from an RGBA sequence in [0, 1]."""
    r, g, b = (int(round(255 * float(np.clip(c, 0.0, 1.0)))) for c in rgba[:3])
    return (r << 16) | (g << 8) | b, float(rgba[3]) if len(rgba) > 3 else 1.0


class TextTexture(mg.Texture):
    """Text drawn by meshcat's JavaScript on a 256 × 256 canvas (its ``_text`` texture)."""

    def __init__(self, text: str, font_size: int = 40, font_face: str = "sans-serif"):
        super().__init__()
        self.text, self.font_size, self.font_face = text, font_size, font_face

    def lower(self, object_data):
        return {"uuid": self.uuid, "type": "_text", "text": self.text, "font_size": self.font_size,
                "font_face": self.font_face}


class MeshFileGeometry(mg.Geometry):
    """A mesh file (dae, obj, stl) parsed in the browser; colored by our material."""

    def __init__(self, contents, mesh_format: str):
        super().__init__()
        self.contents, self.mesh_format = contents, mesh_format

    def lower(self, object_data):
        return {"uuid": self.uuid, "type": "_meshfile_geometry", "format": self.mesh_format, "data": self.contents}


class MeshFileObject(mg.SceneElement):
    """A mesh file keeping its own materials (Collada colors), meshcat's ``_meshfile_object``."""

    def __init__(self, contents, mesh_format: str):
        super().__init__()
        self.contents, self.mesh_format = contents, mesh_format

    def lower(self):
        return {"metadata": {"version": 4.5, "type": "Object"},
                "object": {"uuid": self.uuid, "type": "_meshfile_object", "format": self.mesh_format,
                           "data": self.contents, "resources": {}}}


class Plane(mg.Geometry):
    """A width × height [m] rectangle in the local x-y plane, facing +z (three.js PlaneGeometry)."""

    def __init__(self, width: float, height: float):
        super().__init__()
        self.width, self.height = width, height

    def lower(self, object_data):
        return {"uuid": self.uuid, "type": "PlaneGeometry", "width": self.width, "height": self.height}


def Cone(height: float, radius: float) -> mg.Cylinder:  # noqa: N802 (a geometry constructor, like meshcat's)
    """A cone along +y, apex up, centred at the origin."""
    return mg.Cylinder(height, radiusTop=0.0, radiusBottom=radius)

LOOPS = 10**9  #: the animation's repetitions: it loops (meshcat's default, 1, stops on the last frame)


class SceneWriter:
    """Collects meshcat commands; ``times`` [s] are the animation's key times."""

    def __init__(self, times: np.ndarray, speed: float):
        self.times = np.asarray(times, float)
        self.speed = float(speed)
        self.commands: list[dict[str, Any]] = []
        self.clips: dict[str, list[dict[str, Any]]] = {}

    # ---- static ------------------------------------------------------------------------
    def object(self, path: str, geometry_or_object, material=None, render_order: int = 0) -> None:
        """A mesh at ``path``; ``render_order`` > 0 draws it after (over) the others (labels)."""
        if isinstance(geometry_or_object, MeshFileObject):
            cmd = {"type": "set_object", "object": geometry_or_object.lower(), "path": path}
        else:
            cmd = SetObject(geometry_or_object, material, MeshcatPath(tuple(p for p in path.split("/") if p))).lower()
        if render_order:
            cmd["object"]["object"]["renderOrder"] = render_order
        self.commands.append(cmd)

    def transform(self, path: str, matrix: np.ndarray) -> None:
        self.commands.append({"type": "set_transform", "path": path, "matrix": [float(v) for v in
                                                                                np.asarray(matrix).T.flatten()]})

    def prop(self, path: str, key: str, value) -> None:
        self.commands.append({"type": "set_property", "path": path, "property": key, "value": value})

    # ---- animated ----------------------------------------------------------------------
    def track(self, path: str, prop: str, jstype: str, values: np.ndarray, times: np.ndarray | None = None) -> None:
        """Keys of one property (``position``, ``quaternion``, ``scale``) of the node at ``path``."""
        times = self.times if times is None else np.asarray(times, float)
        values = np.asarray(values, float).reshape(len(times), -1)
        keys = [{"time": float(t), "value": [float(v) for v in row]} for t, row in zip(times, values, strict=True)]
        self.clips.setdefault(path, []).append({"name": f".{prop}", "type": jstype, "keys": keys})

    def placement(self, path: str, matrices: np.ndarray, tol: float = 1e-12) -> None:
        """Place a node by a (N, 4, 4) series: a static transform if it never moves, else tracks."""
        H = np.asarray(matrices, float)
        if np.all(np.abs(H - H[0]) <= tol):
            self.transform(path, H[0])
            return
        quat = Rotation.from_matrix(H[:, :3, :3]).as_quat()  # [x, y, z, w], three.js order
        flips = np.einsum("ij,ij->i", quat[1:], quat[:-1]) < 0.0  # keep the sign continuous for slerp
        signs = np.concatenate([[1.0], np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)])
        self.track(path, "position", "vector3", H[:, :3, 3])
        self.track(path, "quaternion", "quaternion", quat * signs[:, None])

    def finish(self, play: bool = True) -> list[dict[str, Any]]:
        """All commands, the animation last (it needs the objects it moves), playing from t = 0 in a loop."""
        fps = self.speed
        animations = [{"path": path, "clip": {"fps": fps, "name": "default", "tracks": tracks}}
                      for path, tracks in self.clips.items()]
        return [*self.commands, {"type": "set_animation", "animations": animations,
                                 "options": {"play": play, "repetitions": LOOPS}, "path": ""}]
