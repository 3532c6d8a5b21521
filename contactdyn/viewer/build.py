"""Build a run's meshcat scene headless: the robot, the environment, chains, forces, impacts."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..errors import ContactdynError, RunFileError
from ..output.result import Result
from ..output.run_check import check_drawable
from ..robot.robot import Robot
from ..scene.scene_file import Scene
from .camera import frame_view
from .contact_visuals import (
    STAGE_LENGTH,
    TOOL_RADIUS,
    add_environment,
    add_forces,
    add_gauges,
    add_impacts,
    add_tool,
    add_trace,
    contact_views,
    force_arrows,
)
from .robot_visuals import add_body, add_robot, geometry_spheres
from .shapes import add_label
from .writer import ROOT, SceneWriter, ViewerScene

__all__ = ["build_scene", "MAX_FRAMES"]

MAX_FRAMES = 2000  #: animation keys per track at most (the run's samples are thinned to this)
IMPACT_HOLD = 0.25  #: [s of playback] an impact marker stays large this long
GROUPS = {"robot": f"{ROOT}/robot", "environment": f"{ROOT}/environment", "chains": f"{ROOT}/chains",
          "forces": f"{ROOT}/forces", "tool": f"{ROOT}/tool", "labels": f"{ROOT}/labels", "bodies": f"{ROOT}/bodies"}
ARROW_UNIT = 0.2  #: drawn length of one arrow scale step, in view radii (the typical force spans ~3 steps)


def build_scene(result: Result, speed: float = 1.0, max_frames: int = MAX_FRAMES) -> ViewerScene:
    """The meshcat commands drawing ``result``, played at ``speed`` × real time; no server, no browser."""
    if not (isinstance(speed, int | float) and math.isfinite(speed) and speed > 0):
        raise ContactdynError(f"view: speed must be a number > 0 (1 = real time), found {speed!r}")
    scene = check_drawable(result)  # the same checks as `plot` (contactdyn.output.run_check)
    robot = _robot_of(result, scene)
    t_all, q_all = np.asarray(result["t"], float), np.asarray(result["q"], float).reshape(len(result["t"]), -1)
    if q_all.shape[1] != robot.nq:
        raise RunFileError(f"run {result.meta.get('name', '?')}: channel q has {q_all.shape[1]} columns but "
                              f"robot {robot.source} has {robot.nq} active joints {robot.joint_names}")
    idx = _frames(len(t_all), max_frames)
    times, q = t_all[idx], q_all[idx]
    duration = float(times[-1] - times[0]) if len(times) > 1 else 0.0
    writer = SceneWriter(times, speed)
    notes = add_robot(writer, robot, q, GROUPS["robot"])

    def ch(name: str) -> np.ndarray | None:
        return np.asarray(result.channels[name])[idx] if name in result.channels else None

    contacts = list(scene.contacts.values()) if scene else []
    bodies = scene.bodies if scene else {}
    disp, drawn, body_notes = _draw_bodies(writer, result, bodies, contacts, idx)
    notes += body_notes
    on_frames, turning = _turning_frames(result, bodies, contacts, idx, robot, q)
    tips = {c.name: on_frames[c.name] if c.name in on_frames else disp[c.frame] + c.frame_point
            if c.frame_point is not None else _frame_positions(robot, q, c.frame) for c in contacts}
    body, body_radii = geometry_spheres(robot, q[:: max(1, len(q) // 50)])
    points = [body, *tips.values(), *(c.point[None] for c in contacts)]
    cloud = np.concatenate(points) if points else np.zeros((1, 3))
    L = max(float(np.max(np.linalg.norm(cloud, axis=1))), 0.1)  # [m] scene size
    # [m] what reaches beyond each point: a mesh's bounds; a contact point's ball (a body's corner may be the scene's
    # extreme: its ball stays inside, TOOL_RADIUS of the view's radius, ~ half the scene's size L)
    n_tips = sum(len(p) for p in tips.values())
    radii = np.concatenate([body_radii, np.full(n_tips, 0.5 * TOOL_RADIUS * L),
                            np.zeros(len(cloud) - len(body) - n_tips)])

    views = contact_views(scene, tips, disp, L, GROUPS["environment"], turning) if scene else []
    v0 = views[0] if views else None
    arrows, per = force_arrows(views, ch) if views else ([], {})
    label_rotation, V = _frame_with_arrows(writer, cloud, radii, arrows, v0.u if v0 else None,
                                           v0.e1 if v0 else None,
                                           body.mean(axis=0) - v0.tip.mean(axis=0) if v0 and len(body) else None)
    add_tool(writer, tips, V, GROUPS["tool"])
    legend = [f"run {result.meta.get('name', '?')}: {duration:g} s at {speed:g} × real time "
              f"({len(idx)} frames of {len(t_all)} samples)"]
    scales = {"size": L, "stage_length": STAGE_LENGTH * L}
    if views:
        add_environment(writer, views, disp, L, drawn)
        S, chain_notes = add_gauges(writer, views, ch, L, GROUPS["chains"], label_rotation)
        notes += chain_notes
        scales["magnification"] = S
        if any(not v.spec.normal_chain.rigid or v.spec.tangent_chain is not None for v in views):
            legend.append(f"deformation chains: gauges beside the surface, compressions magnified ×{S:g}, "
                          f"{STAGE_LENGTH * L:.3g} m per stage at rest")
        unit = ARROW_UNIT * V  # [m] drawn length of one scale step
        add_forces(writer, arrows, unit, GROUPS["forces"])
        scales["arrow"] = unit / per["normal"]
        scales["arrow_tangent"] = unit / per["tangent"]
        both = per["normal"] == per["tangent"]
        text = f"{unit:.3g} m = {per['normal']:g} N" + ("" if both else f" normal (red), {per['tangent']:g} N "
                                                                           "tangential (green)")
        legend.append(f"force arrows (on the robot, ending at the contact point): {text}"
                      + (" (red normal, green tangential)" if both else ""))
        add_label(writer, f"{GROUPS['labels']}/forces", f"arrows: {unit:.2g} m = {per['normal']:g} N"
                  + ("" if both else f" / {per['tangent']:g} N"), 0.04 * V, label_rotation,
                  v0.tip.mean(axis=0) + 0.5 * V * v0.u - 0.5 * V * v0.e1)
        legend += add_impacts(writer, views, result.impacts, _tips_at(result, scene, robot), L, IMPACT_HOLD * speed,
                              float(times[-1]), GROUPS["environment"])
    for name in bodies:
        if name not in drawn and not any(v.spec.body == name or v.spec.frame == name for v in views):
            notes.append(f"body {name!r} carries no contact surface: not drawn")
    return ViewerScene(writer.finish(), duration, float(speed), legend, notes, dict(GROUPS), scales)


def _draw_bodies(writer: SceneWriter, result: Result, bodies: dict, contacts: list, idx
                 ) -> tuple[dict[str, np.ndarray], frozenset[str], list[str]]:
    """Each body from a URDF drawn with its visuals moving with its coordinates, and each body's path (its contact
    points' centre); (its displacement (frames, 3) [m] per body, the bodies drawn, notes)."""
    coords = {name: _coordinates(result, name, b, idx) for name, b in bodies.items()}
    drawn = frozenset(name for name, b in bodies.items() if b.urdf is not None and coords[name] is not None)
    notes: list[str] = []
    for name in sorted(drawn):
        notes += add_body(writer, bodies[name].urdf, coords[name], f"{GROUPS['bodies']}/{name}", bodies[name].free)
    disp = {name: (np.zeros((len(idx), 3)) if coords[name] is None or b.articulated else coords[name] @ b.axes)
            for name, b in bodies.items()}  # (an articulated body turns: its visuals show it, no path drawn)
    for name in sorted(n for n, b in bodies.items() if coords[n] is not None and not b.articulated):
        at = [c.point for c in contacts if c.body == name] + [c.frame_point for c in contacts if c.frame == name]
        add_trace(writer, disp[name] + (np.mean(at, axis=0) if at else np.zeros(3)),
                  f"{GROUPS['bodies']}/{name}_path")
    return disp, drawn, notes


def _turning_frames(result: Result, bodies: dict, contacts: list, idx, robot: Robot, q: np.ndarray
                    ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """What turns with a frame, per contact and animation frame: (the touching point [m] (N, 3) of an articulated
    body's frame (``body_frame``, ``frame_point`` in its coordinates), the rotation (N, 3, 3) of the frame carrying
    its surface (``surface_frame``: the robot's, or an articulated body's))."""
    from ..robot.body import load_body

    def placements(owner: str, frame: str) -> list | None:
        if owner == "robot":
            return [robot.frame_placement(qk, frame) for qk in q]
        b = bodies.get(owner)
        x = _coordinates(result, owner, b, idx) if b is not None and b.articulated else None
        if x is None:
            return None
        model = load_body(b.urdf, b.free).robot  # (the body's joints in its coordinates' order)
        return [model.frame_placement(xk, frame) for xk in x]

    points, turning = {}, {}
    for c in contacts:
        if c.body_frame is not None and (P := placements(c.frame, c.body_frame)) is not None:
            points[c.name] = np.array([Pk.act(c.frame_point) for Pk in P])
        if c.surface_frame is not None and (P := placements(c.body, c.surface_frame)) is not None:
            turning[c.name] = np.array([Pk.rotation for Pk in P])
    return points, turning


def _frame_with_arrows(writer: SceneWriter, cloud: np.ndarray, radii: np.ndarray, arrows: list, *view
                       ) -> tuple[np.ndarray, float]:
    """:func:`frame_view` of ``cloud`` and of the force arrows' tails: an arrow's length scales with the view
    radius V (ARROW_UNIT · V a step), so V is found by a few passes on a scratch writer (each pass's tails inside the
    next's view: V grows by less each time)."""
    tips = np.concatenate([v.tip for _, _, v, _, _ in arrows]) if arrows else np.zeros((0, 3))
    steps = np.concatenate([F for _, _, _, F, _ in arrows]) if arrows else np.zeros((0, 3))
    points, sizes = cloud, radii
    for _ in range(3 if arrows else 0):
        V = frame_view(SceneWriter(np.zeros(1), 1.0), points, sizes, *view)[1]
        points = np.concatenate([cloud, tips - steps * (ARROW_UNIT * V)])
        sizes = np.concatenate([radii, np.zeros(len(tips))])
    return frame_view(writer, points, sizes, *view)


def _tips_at(result: Result, scene: Scene, robot: Robot):
    """(t [s], contact) -> (its touching point [m], its surface body's displacement [m]) at t, interpolated."""
    t_all, q_all = np.asarray(result["t"], float), np.asarray(result["q"], float).reshape(len(result["t"]), -1)
    bodies = scene.bodies

    def offset_at(body: str, t: float) -> np.ndarray:
        """[m] a body's displacement at t (0 for the ground or a body without channels)."""
        x = _coordinates(result, body, bodies[body], slice(None)) if body in bodies else None
        return np.zeros(3) if x is None else np.array([np.interp(t, t_all, col) for col in x.T]) @ bodies[body].axes

    def tips_at(name: str, t: float) -> tuple[np.ndarray, np.ndarray]:
        spec = scene.contacts[name]
        if spec.frame_point is not None:  # a body's point touches
            return spec.frame_point + offset_at(spec.frame, t), offset_at(spec.body, t)
        qt = np.array([np.interp(t, t_all, q_all[:, j]) for j in range(q_all.shape[1])])
        return robot.frame_position(qt, spec.frame), offset_at(spec.body, t)

    return tips_at


def _robot_of(result: Result, scene: Scene | None) -> Robot:
    """The run's robot: from the scene's ``robot.urdf`` (a name resolves example-robot-data's
    ``package://`` meshes), else from the URDF path saved in ``meta['robot']``."""
    sources = [s for s in (scene.robot.source if scene else None, result.meta.get("robot")) if s]
    if not sources:
        raise RunFileError("run has no robot: neither a scene document nor meta['robot']")
    first: ContactdynError | None = None
    for source in dict.fromkeys(sources):
        try:
            if scene is not None:
                return Robot.from_spec(replace(scene.robot, source=source))
            return Robot.load(source, active_joints=result.meta.get("joints"), locked=result.meta.get("locked"))
        except ContactdynError as exc:
            first = first or exc
    raise first


def _frames(n: int, max_frames: int) -> np.ndarray:
    """Sample indices: every k-th so at most ``max_frames`` remain, always with the last."""
    stride = max(1, math.ceil(n / max(max_frames, 2)))
    idx = np.arange(0, n, stride)
    return idx if idx[-1] == n - 1 else np.append(idx, n - 1)


def _coordinates(result: Result, name: str, body, idx) -> np.ndarray | None:
    """(frames, k) a body's coordinates [m] at the samples ``idx`` (None when the run has no channel of them)."""
    one = len(body.coordinates) == 1
    names = [f"body.{name}.x" if one else f"body.{name}.{c.joint}.x" for c in body.coordinates]
    if any(n not in result.channels for n in names):
        return None
    return np.column_stack([np.asarray(result.channels[n])[idx] for n in names])


def _frame_positions(robot: Robot, q: np.ndarray, frame: str) -> np.ndarray:
    fid = robot.frame_id(frame)
    return np.array([robot.frame_position(qk, fid) for qk in q])
