"""A free body's two charts: ZYX Euler angles of its rotation, and of its rotation turned by a fixed C.

A free body's six coordinates (:data:`~contactdyn.robot.urdf_model.FREE_COORDINATES`) are x, y, z [m] of its root
frame's origin in the world and three angles a = (a1, a2, a3) [rad]. Chart A (0): R = Rz(a1) Ry(a2) Rx(a3), the
yaw, pitch, roll of the world rotation. Chart B (1): R = Rz(a1) Ry(a2) Rx(a3) · C with C = Rz(−90°) (C's first row
is the world-to-body y axis): chart A is singular where the body's x axis is vertical (|R[2,0]| = |sin a2| = 1),
chart B where its y axis is (|R[2,1]| = 1). Since R[2,0]² + R[2,1]² ≤ 1, a switch A → B at |cos a2| = SWITCH_COS
(|R[2,0]|² = 0.75) lands at |cos b2| ≥ √0.75 ≈ 0.866, and back likewise: a hysteresis, never both singular.

Chart B's Pinocchio model is chart A's with the root link turned by C on the roll joint (:func:`turned_model`):
its inertia, its frames and its child joints' placements; the same joints, frames and ids. A switch
(:func:`switch`) keeps the position, the rotation R, the angular velocity ω [rad/s] (world) and the origin's
velocity [m/s]: the angles from R, their rates from ω = E(a) ȧ (E's columns: the axes the angles turn about).
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

__all__ = ["C", "SWITCH_COS", "angles", "chart_a_angles", "omega", "rates", "rotation", "switch", "turned_model"]

#: [-] chart B's fixed turn: R = Rz Ry Rx(b) · C (C = Rz(−90°): its first row is e_y)
C = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
SWITCH_COS = 0.5  #: [-] a free body's chart switches when |cos| of its active chart's pitch falls below this


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _ry(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rotation(a: np.ndarray, chart: int) -> np.ndarray:
    """The body's rotation R [-] (body to world) at the angles a [rad] of ``chart`` (0: A, 1: B)."""
    R = _rz(a[0]) @ _ry(a[1]) @ _rx(a[2])
    return R @ C if chart else R


def angles(R: np.ndarray, chart: int) -> np.ndarray:
    """The angles a [rad] of ``chart`` giving the rotation R: ZYX of R (A) or of R Cᵀ (B); a2 in [−π/2, π/2]."""
    M = R @ C.T if chart else R
    return np.array([np.arctan2(M[1, 0], M[0, 0]), np.arctan2(-M[2, 0], np.hypot(M[2, 1], M[2, 2])),
                     np.arctan2(M[2, 1], M[2, 2])])


def _E(a: np.ndarray) -> np.ndarray:
    """ω = E(a) ȧ [rad/s]: the world axes z, Rz(a1) y, Rz(a1) Ry(a2) x the angles turn about (either chart: C is
    fixed, so the body turns as the roll joint's frame)."""
    c1, s1, c2, s2 = np.cos(a[0]), np.sin(a[0]), np.cos(a[1]), np.sin(a[1])
    return np.array([[0.0, -s1, c1 * c2], [0.0, c1, s1 * c2], [1.0, 0.0, -s2]])


def omega(a: np.ndarray, ad: np.ndarray) -> np.ndarray:
    """ω [rad/s] (world) at angles a [rad] and their rates ȧ [rad/s] (either chart)."""
    return _E(a) @ ad


def rates(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """ȧ [rad/s] giving ω [rad/s] (world) at angles a [rad]: E(a)⁻¹ ω, unbounded as |cos a2| → 0 (inf there)."""
    c1, s1, c2, s2 = np.cos(a[0]), np.sin(a[0]), np.cos(a[1]), np.sin(a[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        a3d = (c1 * w[0] + s1 * w[1]) / c2
    return np.array([w[2] + s2 * a3d, -s1 * w[0] + c1 * w[1], a3d])


def switch(q: np.ndarray, v: np.ndarray, chart: int) -> tuple[np.ndarray, np.ndarray]:
    """A free body's (q, v) (its six coordinates [m, rad] and rates) in ``chart`` re-expressed in the other: the
    position and the origin's velocity as they are, the angles of the same R, the rates of the same ω."""
    a, ad = q[3:6], v[3:6]
    R, w = rotation(a, chart), omega(a, ad)
    b = angles(R, 1 - chart)
    q2, v2 = np.array(q, float), np.array(v, float)
    q2[3:6], v2[3:6] = b, rates(b, w)  # (|cos b2| ≥ √0.75 after a switch: E(b) well conditioned)
    return q2, v2


def chart_a_angles(q: np.ndarray, v: np.ndarray, chart: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(yaw, pitch, roll [rad] of the world rotation (chart A's, pitch in [−π/2, π/2] in chart B), their rates
    [rad/s] (unbounded near pitch ±90°), ω [rad/s] (world)) of a free body's angles q [rad] and rates v in
    ``chart``; chart A's as they are (its angles are continuous: unwrapped)."""
    w = omega(q, v)
    if not chart:
        return np.array(q, float), np.array(v, float), w
    a = angles(rotation(q, 1), 0)
    return a, rates(a, w), w


def turned_model(model: pin.Model, joint: int) -> pin.Model:
    """A copy of ``model`` with everything ``joint`` carries turned by C about its origin: its inertia, the frames
    on it (not its own joint frame) and its child joints' placements; the same joints and frames (ids, names)."""
    out = pin.Model(model)
    turn = pin.SE3(C, np.zeros(3))
    out.inertias[joint] = turn.act(model.inertias[joint])
    for k in range(1, model.njoints):
        if model.parents[k] == joint:
            out.jointPlacements[k] = turn * model.jointPlacements[k]
    for fid, frame in enumerate(model.frames):
        if frame.parentJoint == joint and not (frame.type == pin.FrameType.JOINT and frame.name == model.names[joint]):
            turned = out.frames[fid]
            turned.placement = turn * frame.placement
            out.frames[fid] = turned
    return out
