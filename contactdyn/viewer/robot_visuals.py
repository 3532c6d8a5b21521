"""The robot's visual geometry, from Pinocchio's visual GeometryModel, animated by the run's q.

Why Pinocchio's model and not yourdfpy: :class:`contactdyn.robot.robot.Robot` already builds the
visual model from the same URDF, with ``package://`` meshes resolved (our robots and
example-robot-data's) and with the scene's locked joints folded in by
``buildReducedModel`` — so the run's ``q`` channel (active joints only) places every
visual directly through ``updateGeometryPlacements``, with the kinematics that simulated
the run. yourdfpy would need the full joint vector rebuilt (locked values, joint order) and
a second forward kinematics that could disagree with the simulated one.
"""

from __future__ import annotations

import functools
from pathlib import Path

import coal
import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
import umsgpack

from ..robot.robot import Robot
from .writer import Cone, MeshFileGeometry, MeshFileObject, SceneWriter, color_int

__all__ = ["add_robot", "add_body", "geometry_placements", "geometry_spheres", "MESH_FORMATS"]

MESH_FORMATS = {".dae": "dae", ".obj": "obj", ".stl": "stl"}
_RX90 = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])  # meshcat's y axis -> z


def geometry_placements(robot: Robot, q: np.ndarray) -> np.ndarray:
    """World placements (n_geoms, N, 4, 4) of every visual geometry at each row of q."""
    model, vmodel = robot.model, robot.visual_model
    data, vdata = model.createData(), pin.GeometryData(vmodel)
    out = np.empty((vmodel.ngeoms, len(q), 4, 4))
    for k, qk in enumerate(np.asarray(q, float)):
        pin.forwardKinematics(model, data, qk)
        pin.updateGeometryPlacements(model, data, vmodel, vdata)
        for i in range(vmodel.ngeoms):
            out[i, k] = vdata.oMg[i].homogeneous
    return out


def geometry_spheres(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounding spheres of every visual at each row of q: centres (n_geoms·N, 3) [m] and radii (n_geoms·N,) [m]."""
    placements = geometry_placements(robot, q)  # (n_geoms, N, 4, 4)
    centres, radii = [], []
    for i, geom in enumerate(robot.visual_model.geometryObjects):
        shape = geom.geometry
        shape.computeLocalAABB()
        centre = np.append(np.asarray(shape.aabb_center, float) * geom.meshScale, 1.0)
        centres.append((placements[i] @ centre)[:, :3])
        radii.append(np.full(len(q), float(shape.aabb_radius) * float(np.max(np.abs(geom.meshScale)))))
    if not centres:
        return np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(centres), np.concatenate(radii)


def add_robot(writer: SceneWriter, robot: Robot, q: np.ndarray, root: str) -> list[str]:
    """Draw every visual geometry under ``root``; return notes on what could not be drawn."""
    notes = []
    placements = geometry_placements(robot, q)
    for i, geom in enumerate(robot.visual_model.geometryObjects):
        path = f"{root}/{geom.name.replace('/', '_')}"
        parts = _shape_parts(geom)
        if not parts:
            notes.append(f"visual {geom.name!r}: {type(geom.geometry).__name__} {geom.meshPath!r} not drawable")
            continue
        for sub, obj, material, matrix in parts:
            writer.object(f"{path}/{sub}", obj, material)
            writer.transform(f"{path}/{sub}", matrix)
        writer.placement(path, placements[i])
    return notes


def add_body(writer: SceneWriter, urdf: str, x: np.ndarray, root: str, free: bool = False) -> list[str]:
    """A body's URDF visuals (:mod:`contactdyn.robot.body`) under ``root``, its joints at the body's coordinates
    ``x`` [m or rad] per frame ((frames,) or (frames, k); ``free``: its root link's six first); notes on what could
    not be drawn."""
    from ..robot.body import load_body

    x = np.asarray(x, float)
    return add_robot(writer, load_body(urdf, free).robot, x[:, None] if x.ndim == 1 else x, root)


def _shape_parts(geom: pin.GeometryObject) -> list[tuple[str, object, object, np.ndarray]]:
    """(sub-path, meshcat geometry or object, material, static transform) of one visual."""
    color, opacity = color_int(geom.meshColor)
    material = mg.MeshPhongMaterial(color=color, opacity=opacity)
    shape = geom.geometry
    mesh = Path(geom.meshPath) if geom.meshPath else None
    if mesh is not None and mesh.suffix.lower() in MESH_FORMATS and mesh.is_file():
        fmt = MESH_FORMATS[mesh.suffix.lower()]
        scale = np.diag([*np.asarray(geom.meshScale, float), 1.0])
        contents = _mesh_contents(str(mesh), fmt)
        if fmt == "dae" and not geom.overrideMaterial:  # keep the Collada file's own colors
            return [("mesh", MeshFileObject(contents, fmt), None, scale)]
        return [("mesh", MeshFileGeometry(contents, fmt), material, scale)]
    eye = np.eye(4)
    if isinstance(shape, coal.Box):
        return [("box", mg.Box((2.0 * shape.halfSide).tolist()), material, eye)]
    if isinstance(shape, coal.Sphere):
        return [("sphere", mg.Sphere(shape.radius), material, eye)]
    if isinstance(shape, coal.Ellipsoid):
        return [("ellipsoid", mg.Ellipsoid(np.asarray(shape.radii).tolist()), material, eye)]
    if isinstance(shape, coal.Cylinder):
        return [("cylinder", mg.Cylinder(2.0 * shape.halfLength, shape.radius), material, _RX90)]
    if isinstance(shape, coal.Cone):
        return [("cone", Cone(2.0 * shape.halfLength, shape.radius), material, _RX90)]
    if isinstance(shape, coal.Capsule):
        ends = [eye.copy(), eye.copy()]
        ends[0][2, 3], ends[1][2, 3] = shape.halfLength, -shape.halfLength
        return [("body", mg.Cylinder(2.0 * shape.halfLength, shape.radius), material, _RX90),
                ("cap0", mg.Sphere(shape.radius), material, ends[0]),
                ("cap1", mg.Sphere(shape.radius), material, ends[1])]
    return []


@functools.lru_cache(maxsize=256)
def _mesh_contents(path: str, fmt: str):
    """A mesh file as meshcat sends it: text for dae/obj, a Uint8Array for stl."""
    if fmt == "stl":
        return umsgpack.Ext(0x12, Path(path).read_bytes())
    return Path(path).read_text(errors="replace")
