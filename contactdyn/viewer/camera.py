"""The default camera: the robot and its contact seen from the side, looking along the surface.

meshcat's camera looks at the origin from ``/Cameras/default/rotated/<object>`` (a y-up
frame: world (x, y, z) is (x, z, −y) there), 75° vertical field of view. So the scene is
shifted to put the centre of what must be seen (robot, tip path, contact points) at the
origin, and the camera is placed on the line through it along the surface's second tangent
e₂ = n × e₁ (e₁: the slide direction), raised by :data:`ELEVATION` towards the normal so the
surface is seen slightly from the robot's side: normal forces point up the screen, the slide
runs across it. Without contacts the view is the robot's principal plane.
"""

from __future__ import annotations

import math

import numpy as np

from .shapes import translation
from .writer import ROOT, SceneWriter

__all__ = ["frame_view", "FOV", "ELEVATION", "ASPECT"]

FOV = math.radians(75.0)  #: [rad] meshcat's vertical field of view
ASPECT = 4.0 / 3.0  #: width / height assumed when fitting the frame
ELEVATION = math.radians(20.0)  #: [rad] camera raised above the surface plane, towards the normal
MARGIN = 1.15  #: the framed region (bounding spheres of the meshes included) fills 1/MARGIN of the view


def frame_view(writer: SceneWriter, cloud: np.ndarray, radii: np.ndarray, normal: np.ndarray | None,
               slide: np.ndarray | None, robot_side: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Shift the scene and place the camera; return (label rotation facing the camera, view radius [m]).

    ``cloud`` (N, 3) [m]: points to see, each with a sphere of ``radii`` (N,) [m] around it (a mesh's bounds).

    ``robot_side`` [m]: where the robot's bulk is relative to the contact point; the camera goes to
    the other side of the surface's tangent plane so the arm does not hide the contact.
    """
    lo, hi = (cloud - radii[:, None]).min(axis=0), (cloud + radii[:, None]).max(axis=0)
    centre = 0.5 * (lo + hi)
    writer.transform(ROOT, translation(-centre))
    writer.transform("/Grid", translation(np.array([0.0, 0.0, -centre[2]])))  # the floor stays at z = 0
    writer.transform("/Axes", translation(-centre))
    direction, up = _direction(cloud - centre, normal, slide, robot_side)
    right = np.cross(up, direction)
    right /= np.linalg.norm(right)
    screen_up = np.cross(direction, right)
    rel = cloud - centre
    half_w = float(np.max(np.abs(rel @ right) + radii))
    half_h = float(np.max(np.abs(rel @ screen_up) + radii))
    # each sphere inside the view: d - (its depth towards the camera) >= MARGIN * (its offset) / tan(FOV/2)
    offset = np.maximum(np.abs(rel @ screen_up), np.abs(rel @ right) / ASPECT) + radii
    distance = float(np.max(MARGIN * np.maximum(offset, 0.05) / math.tan(0.5 * FOV) + rel @ direction + radii))
    eye = distance * direction
    writer.prop("/Cameras/default/rotated/<object>", "position", [float(eye[0]), float(eye[2]), float(-eye[1])])
    radius = max(half_w, half_h, 0.05)
    return np.column_stack([right, screen_up, direction]), radius


def _direction(rel: np.ndarray, normal: np.ndarray | None, slide: np.ndarray | None,
               robot_side: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(unit vector from the target to the camera, the camera's up: world z as meshcat keeps it)."""
    z = np.array([0.0, 0.0, 1.0])
    if normal is None:  # the robot's principal plane, seen face on
        spread = np.linalg.svd(rel - rel.mean(axis=0), full_matrices=False)
        side = spread[2][-1] if spread[1][-1] < 0.05 * spread[1][0] else np.array([0.6, -0.6, 0.5])
        up_along = z
    else:
        side = np.cross(normal, slide)
        up_along = normal
    side = side / np.linalg.norm(side)
    away = -float(robot_side @ side) if robot_side is not None else 0.0
    if abs(away) > 0.02 * float(np.max(np.linalg.norm(rel, axis=1))):  # the robot stands off the plane: look past it
        side = side if away > 0 else -side
    elif side @ np.array([0.1, -1.0, 0.3]) < 0:  # else meshcat's habit: the camera on the −y side
        side = -side
    direction = math.cos(ELEVATION) * side + math.sin(ELEVATION) * up_along
    if abs(direction @ z) > 0.7:  # looking (nearly) straight down or up: turn so the normal points up the screen
        direction = math.cos(ELEVATION) * side - math.sin(ELEVATION) * up_along
    return direction / np.linalg.norm(direction), z
