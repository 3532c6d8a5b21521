"""Small drawn parts: spring coils, force arrows, text labels, and the nice scales they use."""

from __future__ import annotations

import math

import meshcat.geometry as mg
import numpy as np
from scipy.spatial.transform import Rotation

from .writer import TINY, Cone, Plane, SceneWriter, TextTexture

__all__ = ["nice_floor", "nice_ceil", "spring_object", "add_arrow", "add_label", "rotation_from_y", "frame_matrix",
           "translation", "placements", "on_top_material", "ON_TOP"]


def nice_floor(x: float) -> float:
    """Largest 1-2-5 × 10ᵏ not above x > 0."""
    k = math.floor(math.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0**k <= x * (1 + 1e-12):
            return m * 10.0**k
    return 10.0**k


def nice_ceil(x: float) -> float:
    """Smallest 1-2-5 × 10ᵏ not below x > 0."""
    k = math.floor(math.log10(x))
    for m in (1.0, 2.0, 5.0, 10.0):
        if m * 10.0**k >= x * (1 - 1e-12):
            return m * 10.0**k
    return 10.0 ** (k + 1)


def frame_matrix(x_axis: np.ndarray, y_axis: np.ndarray, origin=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Homogeneous transform with the given unit x and y axes (z = x × y) and origin."""
    H = np.eye(4)
    H[:3, 0], H[:3, 1], H[:3, 2] = x_axis, y_axis, np.cross(x_axis, y_axis)
    H[:3, 3] = origin
    return H


def translation(p) -> np.ndarray:
    """Homogeneous transform moving by ``p`` (3,) [m]."""
    H = np.eye(4)
    H[:3, 3] = p
    return H


def placements(positions: np.ndarray, rotations: np.ndarray | None = None) -> np.ndarray:
    """(N, 4, 4) homogeneous transforms at ``positions`` (N, 3) [m], turned by ``rotations`` (N, 3, 3) or one (3, 3)."""
    H = np.tile(np.eye(4), (len(positions), 1, 1))
    H[:, :3, 3] = positions
    if rotations is not None:
        H[:, :3, :3] = rotations
    return H


def spring_object(width: float, color: int, turns: int = 5) -> mg.Line:
    """A coil from y = 0 to y = 1 (zig-zag of half-width ``width`` [m]); scale y to stretch it."""
    ys = [0.0, 0.15]
    xs = [0.0, 0.0]
    for i in range(2 * turns):
        ys.append(0.15 + 0.7 * (i + 0.5) / (2 * turns))
        xs.append(width if i % 2 == 0 else -width)
    ys += [0.85, 1.0]
    xs += [0.0, 0.0]
    points = np.array([xs, ys, np.zeros(len(xs))], dtype=np.float32)
    return mg.Line(mg.PointsGeometry(points), mg.LineBasicMaterial(color=color))


ON_TOP = 10  #: three.js renderOrder of what is drawn over everything (arrows, the tool)


def on_top_material(color: int) -> mg.MeshBasicMaterial:
    """Unlit (the colour on screen is exactly ``color``), drawn last and over everything: never hidden
    inside an arm or a semi-transparent surface. Give the mesh renderOrder :data:`ON_TOP`."""
    return mg.MeshBasicMaterial(color=color, transparent=True, opacity=1.0, depthTest=False)


def rotation_from_y(direction: np.ndarray) -> np.ndarray:
    """A rotation matrix taking +y to the unit ``direction``."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    y = np.array([0.0, 1.0, 0.0])
    axis = np.cross(y, d)
    s, c = np.linalg.norm(axis), float(y @ d)
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


def add_arrow(writer: SceneWriter, path: str, origins: np.ndarray, vectors: np.ndarray, radius: float,
              color: int, order: int = ON_TOP) -> None:
    """An arrow from each origin [m] along each vector [m] (already scaled from force)."""
    material = on_top_material(color)
    head_h, head_r = 4.0 * radius, 2.5 * radius
    writer.object(f"{path}/shaft/body", mg.Cylinder(1.0, radius), material)
    writer.prop(f"{path}/shaft/body", "renderOrder", order)
    writer.transform(f"{path}/shaft/body", translation((0.0, 0.5, 0.0)))
    writer.object(f"{path}/head/cone", Cone(head_h, head_r), material)
    writer.prop(f"{path}/head/cone", "renderOrder", order)
    writer.transform(f"{path}/head/cone", translation((0.0, 0.5 * head_h, 0.0)))
    lengths = np.linalg.norm(vectors, axis=1)
    rot = np.empty((len(vectors), 3, 3))
    last = np.array([0.0, 1.0, 0.0])
    for k, (v, n) in enumerate(zip(vectors, lengths, strict=True)):
        if n > 1e-12:
            last = v / n
        rot[k] = rotation_from_y(last)
    writer.placement(path, placements(origins, rot))
    shaft = np.maximum(lengths - head_h, TINY)
    head = np.clip(lengths / head_h, TINY, 1.0)
    writer.track(f"{path}/shaft", "scale", "vector3", np.column_stack([np.ones_like(shaft), shaft,
                                                                        np.ones_like(shaft)]))
    writer.track(f"{path}/head", "position", "vector3", np.column_stack([np.zeros_like(shaft), lengths - head * head_h,
                                                                          np.zeros_like(shaft)]))
    writer.track(f"{path}/head", "scale", "vector3", np.column_stack([head, head, head]))


LABEL_ORDER = 10  #: labels are drawn last, over the robot, the arrows and the surface


def add_label(writer: SceneWriter, path: str, text: str, letter: float, rotation: np.ndarray,
              positions: np.ndarray) -> None:
    """Text of letter height ``letter`` [m] on a plane facing the camera; static, or moving with positions (N, 3).

    meshcat draws it on a 256-pixel canvas, shrinking a 40-pixel font until the line fits
    (about 0.55 em per character): the plane is sized so letters come out ``letter`` tall.
    """
    font_px = min(40.0, 256.0 / (0.55 * max(len(text), 1)))
    size = letter * 256.0 / font_px
    # drawn over everything (no depth test): no link of the robot hides a label
    material = mg.MeshBasicMaterial(map=TextTexture(text), transparent=True, side=0, depthTest=False)
    writer.object(f"{path}/text", Plane(size, size), material, render_order=LABEL_ORDER + 1)
    back = f"{path}/back"  # a pale strip behind the black letters, readable on meshcat's blue background
    writer.object(back, Plane(1.02 * len(text) * 0.55 * letter / 0.75, 1.5 * letter),
                  mg.MeshBasicMaterial(color=0xffffff, opacity=0.6, side=0, depthTest=False), render_order=LABEL_ORDER)
    writer.transform(back, translation((0.0, 0.25 * letter, -0.01 * letter)))
    positions = np.atleast_2d(np.asarray(positions, float))
    H = placements(positions, rotation)
    if len(positions) == 1:
        writer.transform(path, H[0])
    else:
        writer.placement(path, H)
