"""The start posture, solved from the task: tip position and, where the controller holds one,
the tool direction.

Inverse kinematics by damped Gauss–Newton steps projected into the joint limits, from several
seeds: the scene's ``robot.q_seed`` first (a hint: when it converges to a posture at least
SEED_MARGIN of each joint's half-range away from its limits, that posture is kept, so a scene can
choose e.g. an elbow-up posture; a seed meant for another arm of the same DOF count may not
suit), then the middle of the limits and random
postures within them (a fixed random seed: the result is deterministic). Among the solutions
the one farthest from the limits and from singularities wins: the largest product of the
smallest normalized limit margin and the smallest singular value of the task Jacobian.
A task no seed reaches stops with one line saying by how much the best attempt misses.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..errors import RobotError, SceneError
from .robot import Robot

if TYPE_CHECKING:
    from ..scene.scene_file import RobotSpec

__all__ = ["PostureTask", "Posture", "solve_posture", "start_posture", "check_within_limits", "sampling_bounds"]

POSITION_TOL = 1e-12  #: [m] a solution puts the tip this close to its target
DIRECTION_TOL = 1e-10  #: [rad] and the tool this close to its direction
N_SEEDS = 24  #: seeds tried besides the scene's q_seed
MAX_ITERATIONS = 300
DAMPING = 1e-6  #: λ of the damped least-squares step [m, rad]
MAX_STEP = 0.5  #: largest joint step per iteration [rad or m]
STALL_WINDOW = 10  #: iterations that must shrink the task error by 1 %, else the descent ends
SEED_MARGIN = 0.1  #: a seed's solution closer to a limit than this (fraction of the half-range) is not kept
_SPAN = np.pi  #: half-range used for unbounded joints [rad]


class PostureTask(NamedTuple):
    """What the start posture must do."""

    frame: str  #: the tip frame
    position: np.ndarray  #: [m] its origin's target (world)
    tool_axis: np.ndarray | None = None  #: unit tool direction in the tip frame (None: orientation free)
    tool_direction: np.ndarray | None = None  #: its target in the world (unit)


class Posture(NamedTuple):
    q: np.ndarray  #: [rad or m]
    position_error: float  #: [m]
    direction_error: float  #: [rad]
    limit_margin: float  #: smallest distance to a limit over the joint's half-range [-], 1 for unbounded
    sigma_min: float  #: smallest singular value of the task Jacobian [m/rad]
    from_seed: bool  #: the scene's q_seed led to it


def sampling_bounds(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """Limits for sampling: finite ones as given, ±π around 0 for unbounded joints."""
    lo, hi = robot.lower.copy(), robot.upper.copy()
    free = ~np.isfinite(lo) | ~np.isfinite(hi)
    lo[free], hi[free] = -_SPAN, _SPAN
    return lo, hi


def _residual(robot: Robot, fid: int, task: PostureTask, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Task error e, its Jacobian de/dq (sign: q += J⁺e reduces e) and the direction error [rad]."""
    placement = robot.frame_placement(q, fid)
    J6 = robot.frame_jacobian(q, fid)
    e, J = task.position - placement.translation, J6[:3]
    angle = 0.0
    if task.tool_axis is not None:
        a = placement.rotation @ task.tool_axis
        skew = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
        e = np.r_[e, task.tool_direction - a]
        J = np.vstack([J, -skew @ J6[3:]])  # ȧ = ω × a = −[a]× ω
        angle = float(np.arctan2(np.linalg.norm(np.cross(a, task.tool_direction)), a @ task.tool_direction))
    return e, J, angle


def _descend(robot: Robot, fid: int, task: PostureTask, q: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Projected damped Gauss–Newton from q; returns (q, position error [m], direction error [rad])."""
    lo, hi = robot.lower, robot.upper
    q = np.clip(q, lo, hi)
    history: list[float] = []
    for _ in range(MAX_ITERATIONS):
        e, J, angle = _residual(robot, fid, task, q)
        dist = float(np.linalg.norm(e[:3]))
        if dist < POSITION_TOL and angle < DIRECTION_TOL:
            break
        history.append(float(np.linalg.norm(e)))
        if len(history) > STALL_WINDOW and history[-1] > 0.99 * history[-1 - STALL_WINDOW]:
            break  # stuck against the limits or at a closest point
        step = np.linalg.lstsq(np.vstack([J, DAMPING * np.eye(len(q))]), np.r_[e, np.zeros(len(q))], rcond=None)[0]
        size = np.abs(step).max()
        q = np.clip(q + step * min(1.0, MAX_STEP / max(size, 1e-300)), lo, hi)
    e, J, angle = _residual(robot, fid, task, q)
    return q, float(np.linalg.norm(e[:3])), angle


def _quality(robot: Robot, fid: int, task: PostureTask, q: np.ndarray) -> tuple[float, float]:
    lo, hi = sampling_bounds(robot)
    half = 0.5 * (hi - lo)
    margin = np.minimum(q - lo, hi - q) / np.where(half > 0, half, 1.0)
    bounded = np.isfinite(robot.lower) & np.isfinite(robot.upper)
    margin = float(margin[bounded].min()) if bounded.any() else 1.0
    J = _residual(robot, fid, task, q)[1]
    if task.tool_axis is not None:  # the direction's rows have rank 2: keep those across the tool
        basis = np.linalg.svd(J[3:], full_matrices=False)[0][:, :2]
        J = np.vstack([J[:3], basis.T @ J[3:]])
    return margin, float(np.linalg.svd(J, compute_uv=False).min())


def solve_posture(robot: Robot, task: PostureTask, seed: np.ndarray | None = None, *,
                  n_seeds: int = N_SEEDS, rng_seed: int = 0) -> Posture:
    """The start posture for ``task`` (see the module docstring); RobotError when it cannot be reached."""
    fid = robot.frame_id(task.frame)
    lo, hi = sampling_bounds(robot)
    rng = np.random.default_rng(rng_seed)
    seeds = [] if seed is None else [np.asarray(seed, float)]
    seeds += [0.5 * (lo + hi)] + [rng.uniform(lo, hi) for _ in range(n_seeds - 1)]
    best: Posture | None = None
    closest = (np.inf, np.inf)
    for k, q0 in enumerate(seeds):
        q, dist, angle = _descend(robot, fid, task, q0)
        closest = min(closest, (dist, angle), key=lambda c: c[0] + 0.1 * c[1])  # 0.1 m per rad to rank misses
        if dist >= POSITION_TOL * 100 or angle >= DIRECTION_TOL * 100:
            continue
        margin, sigma = _quality(robot, fid, task, q)
        found = Posture(q, dist, angle, margin, sigma, seed is not None and k == 0)
        if found.from_seed and margin >= SEED_MARGIN:
            return found
        if best is None or margin * sigma > best.limit_margin * best.sigma_min:
            best = found
    if best is None:
        what = "position" if task.tool_axis is None else "position and tool direction"
        raise RobotError(
            f"{Path(robot.source).name}: frame {task.frame!r} cannot reach the task's {what} within the joint limits: "
            f"the best of {len(seeds)} attempts misses by {closest[0]:.3g} m"
            + (f" and {closest[1]:.3g} rad" if task.tool_axis is not None else ""))
    return best


def check_within_limits(robot: Robot, q: np.ndarray, key: str, file: str | None) -> None:
    """A start posture outside the joint limits is bad input naming the joint."""
    for name, unit, value, lo, hi in zip(robot.joint_names, robot.joint_units, q, robot.lower, robot.upper,
                                         strict=True):
        if not lo <= value <= hi:
            raise SceneError(key, f"a start posture within the joint limits (joint {name!r} in [{lo:.6g}, {hi:.6g}] "
                             f"{unit}; or robot.joint_limits = \"ignore\")", f"{value:.6g} {unit}", file)


def start_posture(robot: Robot, spec: RobotSpec, controller: Any, file: str | None) -> tuple[np.ndarray, dict]:
    """q at t = 0 [rad or m] for a scene's ``[robot]`` and first controller, and how it was found.

    ``q0`` is taken as given; else with ``tip0`` the posture is solved from the task (tip0 and the
    controller's tool direction, if any), ``q_seed`` a hint used only when its size fits;
    else ``q_seed``, else the neutral posture (0 clipped into the limits).
    """
    n = robot.nq
    enforce = spec.joint_limits == "enforce"
    if spec.q0 is not None:
        if len(spec.q0) != n:
            raise SceneError("robot.q0", f"{n} joint values for joints {robot.joint_names}", spec.q0.tolist(), file)
        if enforce:
            check_within_limits(robot, spec.q0, "robot.q0", file)
        return spec.q0.copy(), {"how": "robot.q0"}
    seed = spec.q_seed if spec.q_seed is not None and len(spec.q_seed) == n else None
    if spec.tip0 is None:
        if spec.q_seed is not None and seed is None:
            raise SceneError("robot.q_seed", f"{n} joint values for joints {robot.joint_names} (or robot.tip0 to "
                             "solve the posture)", spec.q_seed.tolist(), file)
        q = seed.copy() if seed is not None else np.clip(np.zeros(n), robot.lower, robot.upper)
        if enforce:
            check_within_limits(robot, q, "robot.q_seed", file)
        return q, {"how": "robot.q_seed" if seed is not None else "neutral"}
    axis = getattr(controller, "tool_axis", None)
    direction = getattr(controller, "tool_target", None) if axis is not None else None
    task = PostureTask(spec.tip, spec.tip0, axis, direction)
    try:
        posture = solve_posture(robot, task, seed)
    except RobotError as exc:
        raise SceneError("robot.tip0", f"a pose the robot can reach ({exc})", spec.tip0.tolist(), file) from None
    how = "solved from robot.tip0" + (" and the controller's tool_target" if axis is not None else "")
    return posture.q, {"how": how, "from_seed": posture.from_seed, "limit_margin": posture.limit_margin,
                       "sigma_min": posture.sigma_min, "position_error_m": posture.position_error,
                       "direction_error_rad": posture.direction_error}
