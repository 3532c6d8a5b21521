"""The robot model: a thin, allocation-light layer over Pinocchio.

A :class:`Robot` is loaded from a URDF path, a file in the project's ``urdf/`` folder, or
an example-robot-data name. It gives H(q), h(q, q̇), frame placements, world-aligned frame
Jacobians and the drift term J̇q̇. Joints can be locked at given values (the robot is then
reduced to its active joints), and a fraction of gravity can be compensated statically.
Units: SI, radians.
"""

from __future__ import annotations

import difflib
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from .errors import RobotError

__all__ = ["Robot", "FrameTerms", "EXAMPLE_ROBOTS", "urdf_dir", "resolve_robot_path"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED

#: example-robot-data names and their URDF, relative to the package's ``robots`` folder.
EXAMPLE_ROBOTS: dict[str, str] = {
    "ur3": "ur_description/urdf/ur3_robot.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "ur10": "ur_description/urdf/ur10_robot.urdf",
    "panda": "panda_description/urdf/panda.urdf",
    "double_pendulum": "double_pendulum_description/urdf/double_pendulum.urdf",
    "z1": "z1_description/urdf/z1.urdf",
    "xarm7": "xarm_description/urdf/xarm7.urdf",
    "so100": "so_arm_description/urdf/so100.urdf",
}


def urdf_dir() -> Path:
    """The project's ``urdf/`` folder, from a checkout or an installed wheel."""
    packaged = Path(__file__).parent / "data" / "urdf"
    return packaged if packaged.is_dir() else Path(__file__).parent.parent / "urdf"


def _example_robot_data_share() -> Path:
    import sysconfig

    for base in {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}:
        share = Path(base) / "cmeel.prefix" / "share" / "example-robot-data"
        if share.is_dir():
            return share
    raise RobotError("example-robot-data is not installed: pip install example-robot-data")


def resolve_robot_path(source: str | os.PathLike) -> tuple[Path, list[str]]:
    """Return (URDF path, package dirs) for a path, a name in ``urdf/``, or a robot name."""
    text = str(source)
    candidates = [Path(text), urdf_dir() / text, urdf_dir() / f"{text}.urdf"]
    for path in candidates:
        if path.suffix == ".urdf" and path.is_file():
            return path, [str(path.parent)]
    if text in EXAMPLE_ROBOTS:
        share = _example_robot_data_share()
        return share / "robots" / EXAMPLE_ROBOTS[text], [str(share.parent), str(share / "robots")]
    if text.endswith(".urdf") or os.sep in text:
        raise RobotError(f"robot {text!r}: no such URDF file")
    ours = sorted(p.stem for p in urdf_dir().glob("*.urdf"))
    known = ours + sorted(EXAMPLE_ROBOTS)
    close = difflib.get_close_matches(text, known, n=3)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    raise RobotError(f"robot {text!r}: not a URDF file nor a known robot name{hint} (known: {', '.join(known)})")


def _build_model(path: Path, package_dirs: list[str]) -> tuple[pin.Model, pin.GeometryModel]:
    """Build model and visual model; a malformed URDF raises with urdfdom's own reason."""
    with tempfile.TemporaryFile(mode="w+b") as err:
        saved = os.dup(2)
        os.dup2(err.fileno(), 2)
        try:
            model = pin.buildModelFromUrdf(str(path))
            visual = pin.buildGeomFromUrdf(model, str(path), pin.GeometryType.VISUAL, package_dirs=package_dirs)
            failure = None
        except (ValueError, RuntimeError) as exc:
            failure = exc
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        err.seek(0)
        reason = err.read().decode(errors="replace").strip()
    if failure is not None:
        lines = [ln.strip() for ln in reason.splitlines() if ln.strip().startswith("Error")]
        detail = "; ".join(ln.removeprefix("Error:").strip() for ln in lines) or str(failure)
        raise RobotError(f"{path}: not a valid URDF: {detail}")
    return model, visual


def _check_physics(model: pin.Model, path: Path) -> None:
    """Reject what Pinocchio accepts silently: bad masses, inertias and joint limits."""
    for jid in range(1, model.njoints):
        inertia = model.inertias[jid]
        body = model.names[jid]
        if not np.isfinite(inertia.mass) or inertia.mass < 0.0:
            raise RobotError(f"{path}: body after joint {body!r}: mass must be >= 0 [kg], found {inertia.mass}")
        eig = np.linalg.eigvalsh(inertia.inertia)
        if inertia.mass > 0.0 and (eig.min() < -1e-12 or eig[0] + eig[1] < eig[2] - 1e-9 * max(eig[2], 1.0)):
            raise RobotError(
                f"{path}: body after joint {body!r}: rotational inertia must be positive semi-definite "
                f"with principal moments satisfying the triangle inequality, found moments {eig.round(6).tolist()}"
            )
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for jid in range(1, model.njoints):
        sl = slice(model.idx_qs[jid], model.idx_qs[jid] + model.nqs[jid])
        if np.any(lower[sl] > upper[sl]):
            raise RobotError(
                f"{path}: joint {model.names[jid]!r}: lower limit {lower[sl].tolist()} > "
                f"upper limit {upper[sl].tolist()}"
            )
    if not any(inertia.mass > 0.0 for inertia in model.inertias[1:]):
        raise RobotError(f"{path}: every body has zero mass: nothing to simulate")


@dataclass(frozen=True)
class FrameTerms:
    """Kinematics of one frame's origin at the last :meth:`Robot.update` (world-aligned)."""

    position: np.ndarray  #: p [m], shape (3,)
    velocity: np.ndarray  #: ṗ = J q̇ [m/s], shape (3,)
    jacobian: np.ndarray  #: J = ∂p/∂q, linear rows [m/rad or m/m], shape (3, nv)
    drift: np.ndarray  #: J̇ q̇ [m/s²], shape (3,)
    rotation: np.ndarray  #: frame orientation in the world, shape (3, 3)
    angular_jacobian: np.ndarray  #: ω = J_ω q̇ [rad/s per joint unit], shape (3, nv)


class Robot:
    """A fixed-base robot with only its active joints as degrees of freedom."""

    def __init__(self, model: pin.Model, visual: pin.GeometryModel, source: str, gravity_compensation: float):
        self.model = model
        self.visual_model = visual
        self.data = model.createData()
        self.source = source
        self.gravity_compensation = gravity_compensation
        self.nq, self.nv = model.nq, model.nv
        self.joint_names = [model.names[j] for j in range(1, model.njoints)]
        if self.nq != self.nv:
            raise RobotError(
                f"{source}: joints with nq != nv (continuous or spherical) are not supported as active joints; "
                "lock them or give them limits"
            )

    # ---- loading -----------------------------------------------------------------------
    @classmethod
    def load(
        cls,
        source: str | os.PathLike,
        *,
        active_joints: list[str] | None = None,
        locked: dict[str, float] | None = None,
        gravity: tuple[float, float, float] = (0.0, 0.0, -9.81),
        gravity_compensation: float = 0.0,
    ) -> Robot:
        """Load a robot; keep ``active_joints`` (default: all) and lock the rest.

        ``locked`` gives values [rad or m] for locked joints (default 0, or the joint's
        neutral value). ``gravity`` [m/s²]; ``gravity_compensation`` is the fraction of the
        gravity load removed by a static compensator (0 ≤ c ≤ 1; case 1 uses 0.7).
        """
        if not 0.0 <= gravity_compensation <= 1.0:
            raise RobotError(f"gravity_compensation must be in [0, 1], found {gravity_compensation}")
        path, package_dirs = resolve_robot_path(source)
        model, visual = _build_model(path, package_dirs)
        _check_physics(model, path)
        names = [model.names[j] for j in range(1, model.njoints)]
        locked = dict(locked or {})
        for name in list(locked) + list(active_joints or []):
            if name not in names:
                raise RobotError(f"{path}: no joint named {name!r}{_suggest(name, names)}; joints: {names}")
        if active_joints is not None:
            lock_names = [n for n in names if n not in active_joints]
        else:
            lock_names = list(locked)
        if lock_names:
            q_ref = pin.neutral(model)
            for name in lock_names:
                jid = model.getJointId(name)
                if name in locked:
                    if model.nqs[jid] != 1:
                        raise RobotError(f"{path}: locked joint {name!r} has {model.nqs[jid]} coordinates, give 1")
                    q_ref[model.idx_qs[jid]] = locked[name]
            ids = [model.getJointId(n) for n in lock_names]
            model, visual = pin.buildReducedModel(model, visual, ids, q_ref)
        model.gravity.linear = (1.0 - gravity_compensation) * np.asarray(gravity, dtype=float)
        return cls(model, visual, str(path), gravity_compensation)

    def frame_id(self, name: str) -> int:
        """Index of a named frame; a clear error lists close matches."""
        if not self.model.existFrame(name):
            names = [f.name for f in self.model.frames]
            raise RobotError(f"{self.source}: no frame named {name!r}{_suggest(name, names)}")
        return self.model.getFrameId(name)

    # ---- the right-hand-side path: one update, then cheap reads ---------------------
    def update(self, q: np.ndarray, v: np.ndarray) -> None:
        """Compute H, h, joint Jacobians and the zero-acceleration kinematics at (q, q̇)."""
        pin.computeAllTerms(self.model, self.data, q, v)

    @property
    def H(self) -> np.ndarray:
        """Joint-space inertia matrix [kg·m² / kg] at the last update (full, symmetric)."""
        return self.data.M

    @property
    def h(self) -> np.ndarray:
        """Coriolis, centrifugal and uncompensated gravity terms [N·m / N] at the last update."""
        return self.data.nle

    def frame_terms(self, fid: int) -> FrameTerms:
        """Position, velocity, Jacobian and J̇q̇ of frame ``fid`` at the last update."""
        model, data = self.model, self.data
        placement = pin.updateFramePlacement(model, data, fid)
        J6 = pin.getFrameJacobian(model, data, fid, _LWA)
        return FrameTerms(
            position=placement.translation.copy(),
            velocity=pin.getFrameVelocity(model, data, fid, _LWA).linear,
            jacobian=J6[:3],
            drift=pin.getFrameClassicalAcceleration(model, data, fid, _LWA).linear,
            rotation=placement.rotation.copy(),
            angular_jacobian=J6[3:],
        )

    # ---- convenience (allocating) ------------------------------------------------------
    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """H(q), a copy."""
        return pin.crba(self.model, self.data, np.asarray(q, float)).copy()

    def bias(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """h(q, q̇) = C(q, q̇)q̇ + (1 − compensation)·g(q), a copy."""
        return pin.nonLinearEffects(self.model, self.data, np.asarray(q, float), np.asarray(v, float)).copy()

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """Uncompensated part of the gravity load g(q) [N·m / N], a copy."""
        return pin.computeGeneralizedGravity(self.model, self.data, np.asarray(q, float)).copy()

    def frame_placement(self, q: np.ndarray, frame: str | int) -> pin.SE3:
        fid = frame if isinstance(frame, int) else self.frame_id(frame)
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, float))
        return self.data.oMf[fid].copy()

    def frame_position(self, q: np.ndarray, frame: str | int) -> np.ndarray:
        return self.frame_placement(q, frame).translation.copy()

    def frame_jacobian(self, q: np.ndarray, frame: str | int) -> np.ndarray:
        """World-aligned 6×nv Jacobian (linear rows first) of the frame's origin."""
        fid = frame if isinstance(frame, int) else self.frame_id(frame)
        return pin.computeFrameJacobian(self.model, self.data, np.asarray(q, float), fid, _LWA).copy()

    def frame_drift(self, q: np.ndarray, v: np.ndarray, frame: str | int) -> np.ndarray:
        """J̇q̇ (classical, world-aligned), linear then angular, shape (6,)."""
        fid = frame if isinstance(frame, int) else self.frame_id(frame)
        q, v = np.asarray(q, float), np.asarray(v, float)
        pin.forwardKinematics(self.model, self.data, q, v, np.zeros(self.nv))
        pin.updateFramePlacement(self.model, self.data, fid)
        return pin.getFrameClassicalAcceleration(self.model, self.data, fid, _LWA).vector.copy()

    def kinetic_energy(self, q: np.ndarray, v: np.ndarray) -> float:
        return float(pin.computeKineticEnergy(self.model, self.data, np.asarray(q, float), np.asarray(v, float)))

    def potential_energy(self, q: np.ndarray) -> float:
        """Potential energy of the uncompensated gravity [J]."""
        return float(pin.computePotentialEnergy(self.model, self.data, np.asarray(q, float)))

    def inverse_kinematics(self, frame: str, target: np.ndarray, q0: np.ndarray, *, tol: float = 1e-12) -> np.ndarray:
        """Joint values putting the frame's origin at ``target`` [m] (damped Newton from q0)."""
        fid = self.frame_id(frame)
        q = np.asarray(q0, float).copy()
        target = np.asarray(target, float)
        for _ in range(200):
            err = target - self.frame_position(q, fid)
            if np.linalg.norm(err) < tol:
                return q
            J = self.frame_jacobian(q, fid)[:3]
            q += np.linalg.lstsq(J, err, rcond=None)[0]
        raise RobotError(
            f"{self.source}: frame {frame!r} cannot reach {target.tolist()} from q0 = {np.asarray(q0).tolist()} "
            f"(closest distance {np.linalg.norm(err):.3g} m): unreachable pose"
        )


def _suggest(name: str, names: list[str]) -> str:
    close = difflib.get_close_matches(name, names, n=3)
    return f" (did you mean {', '.join(map(repr, close))}?)" if close else ""
