"""The environment and the contact zone: surfaces, carts, deformation chains, forces, impacts.

Lengths are in units of the scene size ``L`` [m] (the robot's reach), so a 2 m arm and a
0.6 m writer look alike. A deformation chain is drawn as a *gauge* standing beside the
surface along its direction: each stage a coil of nominal length ``ℓ`` shortened by
``S`` × its compression (S chosen so the largest compression takes 60 % of ℓ), each
equivalent mass a cube, the environment body's anchor a plate. The real tip and the
real surface stay at true scale; only the gauge is magnified.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import meshcat.geometry as mg
import numpy as np

from ..model.chain import Chain, NodeKind, build_chain
from ..scene.scene_file import ContactSpec, Scene
from .shapes import (
    ON_TOP,
    add_arrow,
    add_label,
    frame_matrix,
    nice_ceil,
    nice_floor,
    on_top_material,
    placements,
    spring_object,
    translation,
)
from .writer import TINY, SceneWriter

__all__ = ["ContactView", "contact_views", "add_environment", "add_gauges", "force_arrows", "add_forces", "add_tool",
           "add_trace", "add_impacts",
           "COLORS"]

STAGE_LENGTH = 0.1  #: ℓ, a stage's drawn length at zero compression [L]
MARGIN = 0.15  #: surface plate beyond the tip's travel [L]
COLORS = {"surface": 0x9a9a9a, "cart": 0xd98c1f, "env": 0x7a4a1a, "robot": 0x1f4fa0, "mass": 0x555555,
          "normal": 0xd62728, "friction": 0x2ca02c, "impact": 0xff2020, "tool": 0xd000d0, "trace": 0xff8c00}
ARROW_RADIUS = 0.15  #: arrow shaft radius, in scale steps (the head is 4 radii long, 2.5 wide)
PERCENTILE = 90  #: [%] the force an arrow scale is fitted to (impact peaks may draw longer)
SHARED_SCALE = 1.5  #: tangential forces this many times smaller than the normal ones get their own arrow scale
TOOL_RADIUS = 0.03  #: the tool ball's radius, in view radii

Channel = Callable[[str], np.ndarray | None]


@dataclass
class ContactView:
    """One contact's geometry along the animation frames (body frame = frame of its body at coordinate 0)."""

    spec: ContactSpec
    u: np.ndarray  #: unit normal
    e1: np.ndarray  #: first tangent (plate axis)
    e2: np.ndarray  #: u × e1
    w: np.ndarray  #: ±e2, the side where gauges stand (upward when it can be)
    tip: np.ndarray  #: (N, 3) contact frame position [m]
    disp: np.ndarray  #: (N, 3) body displacement [m]
    range1: tuple[float, float]  #: plate extent along e1 [m], from the contact point
    range2: tuple[float, float]  #: plate extent along e2 [m]
    body_path: str
    #: a surface carried by a robot frame: its rotation per frame (N, 3, 3), turning the spec's normal and tangents
    #: (given in that frame) into the world's; None for a surface that does not turn
    turning: np.ndarray | None = None

    def normals(self) -> np.ndarray:
        """(N, 3) or (3,) the world normal per frame."""
        return self.u if self.turning is None else self.turning @ self.u

    def tangent_dirs(self) -> np.ndarray:
        """(N, k, 3) or (k, 3) the world tangents per frame."""
        T = self.spec.tangents
        return T if self.turning is None else np.einsum("nij,kj->nki", self.turning, T)

    @property
    def edge_w(self) -> float:
        """The plate's edge along w [m] (gauges stand beyond it)."""
        return self.range2[1] if self.w @ self.e2 > 0 else -self.range2[0]


def contact_views(scene: Scene, tips: dict[str, np.ndarray], disp: dict[str, np.ndarray], L: float,
                  env_root: str, turning: dict[str, np.ndarray] | None = None) -> list[ContactView]:
    """Each contact's view; ``turning``: per contact on a surface carried by a robot frame, its rotations (N, 3, 3)."""
    turning = turning or {}
    views = []
    for spec in scene.contacts.values():
        u = spec.normal
        e1 = spec.tangents[0] if len(spec.tangents) else _perpendicular(u)
        e2 = np.cross(u, e1)
        w = e2 if e2[2] >= -1e-12 else -e2
        d = disp.get(spec.body, np.zeros_like(tips[spec.name]))
        rel = tips[spec.name] - d - spec.point
        a1, a2 = rel @ e1, rel @ e2
        views.append(ContactView(spec, u, e1, e2, w, tips[spec.name], d, _extent(a1, L), _extent(a2, L),
                                 f"{env_root}/{spec.body}", turning.get(spec.name)))
    return views


def add_environment(writer: SceneWriter, views: list[ContactView], disp: dict[str, np.ndarray], L: float,
                    drawn: frozenset[str] = frozenset()) -> None:
    """Surface plates (semi-transparent) and, under those on a cart, the cart's body (a box; not for the bodies in
    ``drawn``, whose URDF visuals are drawn)."""
    thickness = 0.02 * L
    moved = set()
    for v in views:
        if v.spec.surface_frame is not None:  # carried by a robot frame or an articulated body's: its visuals draw
            continue  # it, turning
        c1, c2 = 0.5 * sum(v.range1), 0.5 * sum(v.range2)
        size = [v.range1[1] - v.range1[0], v.range2[1] - v.range2[0]]
        H = frame_matrix(v.e1, v.e2, v.spec.point + c1 * v.e1 + c2 * v.e2 - 0.5 * thickness * v.u)
        path = f"{v.body_path}/surface_{v.spec.name}"
        writer.object(path, mg.Box([*size, thickness]), mg.MeshPhongMaterial(color=COLORS["surface"], opacity=0.6))
        writer.transform(path, H)
        if v.spec.body != "ground":
            depth = 0.06 * L
            H[:3, 3] -= (0.5 * thickness + 0.5 * depth) * v.u
            if v.spec.body not in drawn:
                writer.object(f"{v.body_path}/cart_{v.spec.name}", mg.Box([*size, depth]),
                              mg.MeshPhongMaterial(color=COLORS["cart"]))
                writer.transform(f"{v.body_path}/cart_{v.spec.name}", H)
            if v.spec.body not in moved:
                moved.add(v.spec.body)
                writer.track(v.body_path, "position", "vector3", disp[v.spec.body])


def add_gauges(writer: SceneWriter, views: list[ContactView], ch: Channel, L: float, root: str,
               label_rotation: np.ndarray) -> tuple[float, list[str]]:
    """One gauge per deformation chain; return the magnification S [-] and notes."""
    ell = STAGE_LENGTH * L
    chains: list[tuple[ContactView, str, np.ndarray, Chain, int]] = []
    for v in views:
        spec = v.spec
        if not spec.normal_chain.rigid:
            chains.append((v, "n", v.u, build_chain(spec.normal_chain, f"contact.{spec.name}.normal"), len(chains)))
        if spec.tangent_chain is not None:
            for i, t in enumerate(spec.tangents):
                chains.append((v, f"t{i + 1}", t, build_chain(spec.tangent_chain, f"contact.{spec.name}.tangent"),
                               len(chains)))
    notes: list[str] = []
    comp: dict[tuple[str, str, str], np.ndarray] = {}
    for v, label, _, chain, _ in chains:
        for s in chain.stages:
            x = ch(f"stage.{v.spec.name}.{label}.{s.label}.x")
            if x is None:
                notes.append(f"no channel stage.{v.spec.name}.{label}.{s.label}.x: drawn undeformed")
                x = np.zeros(len(writer.times))
            comp[(v.spec.name, label, s.label)] = x
    x_max = max((float(np.max(np.abs(x))) for x in comp.values()), default=0.0)
    S = max(1.0, nice_floor(0.6 * ell / x_max)) if x_max > 0 else 1.0
    for v, label, u, chain, k in chains:
        gap = ch(f"contact.{v.spec.name}.gap")
        gap = np.clip(gap, 0.0, 2.0 * ell) if gap is not None else np.zeros(len(writer.times))
        n_env = sum(1 for s in chain.stages if s.side == "environment")
        a1 = (v.tip - v.disp - v.spec.point) @ v.e1
        side = v.disp + v.spec.point + np.outer(a1, v.e1) + (v.edge_w + (0.08 + 0.12 * k) * L) * v.w
        if label != "n":  # a tangential gauge: its rest surface level with the tip along u
            side = side + np.outer((v.tip - side) @ u, u)
        origin = side - n_env * ell * u
        path = f"{root}/{v.spec.name}_{label}"
        H = np.tile(frame_matrix(v.w, u), (len(origin), 1, 1))
        H[:, :3, 3] = origin
        writer.placement(path, H)
        _draw_chain(writer, path, chain, {s.label: comp[(v.spec.name, label, s.label)] for s in chain.stages}, gap,
                    ell, S)
        add_label(writer, f"{path}_label", f"{v.spec.name}.{label} ×{S:g}", 0.03 * L, label_rotation,
                  origin - 0.8 * ell * u)
    return S, notes


def _draw_chain(writer: SceneWriter, path: str, chain: Chain, x: dict[str, np.ndarray], gap: np.ndarray, ell: float,
                S: float) -> None:
    """Nodes and coils of one chain along the gauge's local +y, anchor at y = 0."""
    n = len(gap)
    y = {chain.anchor: np.zeros(n)}
    env = [s for s in chain.stages if s.side == "environment"]
    rob = [s for s in chain.stages if s.side == "robot"]
    for s in env:
        y[s.upper] = y[s.lower] + ell - S * x[s.label]
    y[chain.robot_surface] = y[chain.env_surface] + gap
    for s in reversed(rob):
        y[s.upper] = y[s.lower] + ell - S * x[s.label]
    for s in chain.stages:
        sp = f"{path}/{s.label}"
        writer.object(f"{sp}/coil", spring_object(0.15 * ell, 0x000000 if s.side == "robot" else 0x3b2a1a))
        zeros = np.zeros(n)
        writer.track(sp, "position", "vector3", np.column_stack([zeros, y[s.lower], zeros]))
        length = np.maximum(y[s.upper] - y[s.lower], TINY)
        writer.track(sp, "scale", "vector3", np.column_stack([np.ones(n), length, np.ones(n)]))
    anchor = mg.Box([0.7 * ell, 0.08 * ell, 0.7 * ell])
    writer.object(f"{path}/anchor", anchor, mg.MeshPhongMaterial(color=COLORS["env"]))
    writer.transform(f"{path}/anchor", translation((0.0, -0.04 * ell, 0.0)))
    for i, node in enumerate(chain.nodes):
        if i == chain.anchor:
            continue
        if node.kind == NodeKind.MASS:
            geom, color = mg.Box([0.4 * ell] * 3), COLORS["mass"]
        elif node.kind == NodeKind.TIP:
            geom, color = mg.Sphere(0.08 * ell), 0x111111
        else:
            geom, color = mg.Sphere(0.04 * ell), 0x888888
        np_ = f"{path}/node{i}"
        writer.object(np_, geom, mg.MeshPhongMaterial(color=color))
        writer.track(np_, "position", "vector3", np.column_stack([np.zeros(n), y[i], np.zeros(n)]))


def force_arrows(views: list[ContactView], ch: Channel) -> tuple[list[tuple], dict[str, float]]:
    """The normal and tangential force on the robot at each contact, in scale steps: ((kind, name, view, force
    (frames, 3) in steps, color) per arrow, the newtons per step of the normal and the tangential arrows). Each
    scale is the 1-2-5 number putting the :data:`PERCENTILE` of its force at ≤ 3 steps (peaks such as impacts may
    draw longer), the tangential one on its own scale when its forces are below 1/:data:`SHARED_SCALE` of the normal
    ones (else both share the normal scale)."""
    forces: list[tuple[str, str, ContactView, np.ndarray, int]] = []
    for v in views:
        name = v.spec.name
        F_n = ch(f"contact.{name}.F_n")
        if F_n is not None:
            forces.append(("normal", f"{name}_normal", v, np.asarray(F_n)[:, None] * v.normals(), COLORS["normal"]))
        F_f = ch(f"contact.{name}.F_f")
        tangential = np.zeros_like(v.tip)
        T = v.tangent_dirs()  # (k, 3), or (N, k, 3) on a turning surface
        if F_f is not None:
            F = np.asarray(F_f).reshape(len(v.tip), -1)
            tangential += F @ T if T.ndim == 2 else np.einsum("nk,nki->ni", F, T)
        for i in range(len(v.spec.tangents)):
            F_t = ch(f"contact.{name}.t{i + 1}.F")
            if F_t is not None:
                tangential += np.asarray(F_t)[:, None] * T[..., i, :]
        if F_f is not None or v.spec.tangent_chain is not None:
            forces.append(("tangent", f"{name}_tangent", v, tangential, COLORS["friction"]))
    typical = {kind: max((float(np.percentile(np.linalg.norm(F, axis=1), PERCENTILE)) for k, _, _, F, _ in forces
                          if k == kind), default=0.0) for kind in ("normal", "tangent")}
    per = {kind: nice_ceil(f / 3.0) if f > 0 else 1.0 for kind, f in typical.items()}  # [N] per step
    if typical["normal"] > 0 and typical["tangent"] >= typical["normal"] / SHARED_SCALE:
        per["tangent"] = per["normal"]
    return [(kind, name, v, F / per[kind], color) for kind, name, v, F, color in forces], per


def add_forces(writer: SceneWriter, arrows: list[tuple], unit: float, root: str) -> None:
    """The arrows of :func:`force_arrows`, ``unit`` [m] the drawn length of one scale step, each ending at its
    contact point (the force on the robot)."""
    for kind, name, v, steps, color in arrows:
        vectors = steps * unit
        add_arrow(writer, f"{root}/{name}", v.tip - vectors, vectors, ARROW_RADIUS * unit, color,
                  order=ON_TOP + (2 if kind == "normal" else 1))  # the normal over the tangential


def add_tool(writer: SceneWriter, tips: dict[str, np.ndarray], size: float, root: str) -> None:
    """Each contact frame (the tool's tip) as a ball in :data:`COLORS` ``tool``, and its path as a trace."""
    for name, tip in tips.items():
        path = f"{root}/{name}"
        writer.object(f"{path}/ball", mg.Sphere(TOOL_RADIUS * size), on_top_material(COLORS["tool"]))
        writer.prop(f"{path}/ball", "renderOrder", ON_TOP + 3)
        writer.placement(f"{path}/ball", placements(tip))
        add_trace(writer, tip, f"{path}/trace")


def add_trace(writer: SceneWriter, points: np.ndarray, path: str) -> None:
    """A path through ``points`` (frames, 3) [m] as a line in :data:`COLORS` ``trace``."""
    xyz = np.asarray(points, np.float32).T
    writer.object(path, mg.Line(mg.PointsGeometry(xyz), mg.LineBasicMaterial(color=COLORS["trace"])))


def add_impacts(writer: SceneWriter, views: list[ContactView], impacts: list[dict], tips_at: Callable,
                L: float, hold: float, duration: float, root: str) -> list[str]:
    """A red ball flashing where each impact happened, then staying small; return legend lines."""
    by_name = {v.spec.name: v for v in views}
    lines = []
    for i, imp in enumerate(impacts):
        v = by_name.get(imp.get("contact"))
        if v is None:
            continue
        t = float(imp["t"])
        tip, disp = tips_at(v.spec.name, t)
        path = f"{v.body_path}/impact{i}"
        writer.object(path, mg.Sphere(0.06 * L), mg.MeshPhongMaterial(color=COLORS["impact"], opacity=0.5))
        eps = 1e-6 * max(duration, 1e-9)
        times = [0.0, max(t - eps, 0.0), t, min(t + hold, duration), min(t + hold, duration) + eps,
                 max(duration, min(t + hold, duration) + 2 * eps)]
        sizes = [TINY, TINY, 1.0, 1.0, 0.35, 0.35]
        keep = np.concatenate([[True], np.diff(times) > 0])
        times, sizes = np.asarray(times)[keep], np.asarray(sizes)[keep]
        writer.transform(path, translation(tip - disp))
        writer.track(path, "scale", "vector3", np.column_stack([sizes, sizes, sizes]), times=times)
        lines.append(f"impact on {v.spec.name} at t = {t:.6g} s: F·Δt = {float(imp.get('normal_impulse', 0)):.4g} N·s")
    return lines


def _extent(a: np.ndarray, L: float) -> tuple[float, float]:
    lo, hi = float(np.min(a)) - MARGIN * L, float(np.max(a)) + MARGIN * L
    return lo, hi


def _perpendicular(u: np.ndarray) -> np.ndarray:
    trial = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    p = trial - (trial @ u) * u
    return p / np.linalg.norm(p)
