"""The robot model: a thin, allocation-light layer over Pinocchio.

A :class:`Robot` is loaded from a URDF path, a file in the project's ``urdf/`` folder, or
an example-robot-data name. It gives H(q), h(q, q̇), frame placements, world-aligned frame
Jacobians and the drift term J̇q̇. Joints can be locked at given values (the robot is then
reduced to its active joints), and a fraction of gravity can be compensated statically.
Units: SI, radians.

Checks beyond Pinocchio's (which accepts all of these silently), per URDF link:
mass ≥ 0 [kg]; a zero mass only with a zero rotational inertia (a massless frame link such
as ``tip``); for a massive link the rotational inertia about the COM is positive
semi-definite and its principal moments satisfy the triangle inequality I1 + I2 ≥ I3
(zero moments are allowed: point masses and thin rods are accepted idealizations; relative
tolerance 1e-6 for rounded file values). Per joint: lower limit ≤ upper limit, and every
active joint moves some mass (H(q0)ᵢᵢ > 0), else H is singular. Every visual mesh exists.
"""

from __future__ import annotations

import difflib
import functools
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from .errors import RobotError
from .urdf_check import check_urdf_tree, isolated_build

__all__ = ["Robot", "FrameTerms", "EXAMPLE_ROBOTS", "urdf_dir", "resolve_robot_path"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_INERTIA_RTOL = 1e-6  # URDF values are rounded to a few digits; exact equalities may break by this much

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
    given = Path(text)
    if given.is_file():
        return given, [str(p) for p in given.resolve().parents[:3]]
    for path in (urdf_dir() / text, urdf_dir() / f"{text}.urdf"):
        if path.suffix == ".urdf" and path.is_file():
            return path, [str(path.parent)]
    if text in EXAMPLE_ROBOTS:
        share = _example_robot_data_share()
        return share / "robots" / EXAMPLE_ROBOTS[text], [str(share.parent), str(share / "robots")]
    if text.endswith(".urdf") or os.sep in text:
        raise RobotError(f"{text}: no such URDF file (looked at {given.absolute()} and in {urdf_dir()})")
    ours = sorted(p.stem for p in urdf_dir().glob("*.urdf"))
    known = ours + sorted(EXAMPLE_ROBOTS)
    close = difflib.get_close_matches(text, known, n=3)
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    raise RobotError(f"robot {text!r}: not a URDF file nor a known robot name{hint} (known: {', '.join(known)})")


# ---- building, with urdfdom's reason for a failure ----------------------------------------
def _urdf_call(path: Path, build: Callable[[], object]) -> object:
    """Run a Pinocchio URDF builder; on failure raise RobotError with urdfdom's reason.

    Pinocchio's exception says only "does not contain a valid URDF model"; urdfdom writes
    the reason to file descriptor 2, which is captured here for the duration of the call.
    """
    sys.stderr.flush()
    with tempfile.TemporaryFile(mode="w+b") as err:
        saved = os.dup(2)
        os.dup2(err.fileno(), 2)
        try:
            return build()
        except (ValueError, RuntimeError) as exc:
            failure: Exception = exc
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        err.seek(0)
        reason = err.read().decode(errors="replace")
    lines = [ln.strip().removeprefix("Error:").strip() for ln in reason.splitlines() if ln.strip().startswith("Error")]
    detail = "; ".join(lines) or str(failure)
    try:
        ET.parse(path)
    except ET.ParseError as exc:
        detail = f"malformed XML: {exc} (urdfdom: {detail})"
    raise RobotError(f"{path}: not a valid URDF: {detail}")


def _number(element: ET.Element | None, key: str, where: str) -> float:
    text = element.get(key, "0") if element is not None else "0"
    try:
        return float(text)
    except ValueError:
        raise RobotError(f"{where}: {key} must be a number, found {text!r}") from None


def _check_links(root: ET.Element, path: Path) -> None:
    """Masses and rotational inertias of every link (see the module docstring)."""
    for link in root.iter("link"):
        inertial = link.find("inertial")
        if inertial is None:
            continue
        where = f"{path}: link {link.get('name')!r}"
        mass = _number(inertial.find("mass"), "value", where)
        el = inertial.find("inertia")
        xx, yy, zz, xy, xz, yz = (_number(el, k, where) for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz"))
        inertia = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
        if not np.isfinite(mass) or mass < 0.0:
            raise RobotError(f"{where}: mass must be >= 0 [kg], found {mass}")
        if not np.all(np.isfinite(inertia)):
            raise RobotError(f"{where}: rotational inertia must be finite [kg·m²], found {inertia.tolist()}")
        if mass == 0.0:
            if np.any(inertia != 0.0):
                raise RobotError(
                    f"{where}: zero mass [kg] with a non-zero rotational inertia {inertia.tolist()} [kg·m²]: "
                    "give the link its mass, or drop the inertial for a massless frame link"
                )
            continue
        eig = np.linalg.eigvalsh(inertia)  # ascending
        tol = _INERTIA_RTOL * max(abs(eig).max(), 1e-300)
        moments = [float(f"{e:.6g}") for e in eig]
        if eig[0] < -tol:
            raise RobotError(
                f"{where}: rotational inertia is not positive (semi-)definite: principal moments {moments} [kg·m²]"
            )
        if eig[0] + eig[1] < eig[2] - tol:
            raise RobotError(
                f"{where}: principal moments {moments} [kg·m²] violate the triangle inequality "
                f"I1 + I2 >= I3 ({eig[0] + eig[1]:.6g} < {eig[2]:.6g}): no rigid body has this inertia"
            )


def _mesh_file(filename: str, path: Path, package_dirs: list[str]) -> Path | None:
    if filename.startswith("package://"):
        rest = filename.removeprefix("package://")
        dirs = package_dirs + [d for d in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if d]
        candidates = [Path(d) / rest for d in dirs]
    else:
        file = Path(filename.removeprefix("file://"))
        candidates = [file if file.is_absolute() else path.parent / file]
    return next((c for c in candidates if c.is_file()), None)


def _check_meshes(root: ET.Element, path: Path, package_dirs: list[str]) -> None:
    """Every visual mesh resolves to a file, checked without loading it (that is slow)."""
    for link in root.iter("link"):
        for mesh in link.findall("visual/geometry/mesh"):
            filename = mesh.get("filename", "")
            if _mesh_file(filename, path, package_dirs) is None:
                raise RobotError(
                    f"{path}: link {link.get('name')!r}: visual mesh {filename!r} not found "
                    f"(package dirs: {', '.join(package_dirs)})"
                )


def _check_limits(model: pin.Model, path: Path) -> None:
    lower, upper = model.lowerPositionLimit, model.upperPositionLimit
    for jid in range(1, model.njoints):
        sl = slice(model.idx_qs[jid], model.idx_qs[jid] + model.nqs[jid])
        if np.any(lower[sl] > upper[sl]):
            raise RobotError(f"{path}: joint {model.names[jid]!r}: "
                             f"lower limit {lower[sl].tolist()} > upper limit {upper[sl].tolist()}")


def _lock_reference(model: pin.Model, names: list[str], locked: dict[str, float], path: Path) -> np.ndarray:
    """Configuration holding each locked joint at its given value (default 0), within limits."""
    q_ref = pin.neutral(model)
    for name in names:
        jid = model.getJointId(name)
        i, nq, nv = model.idx_qs[jid], model.nqs[jid], model.nvs[jid]
        value = float(locked.get(name, 0.0))
        if nq == 1:
            lo, hi = model.lowerPositionLimit[i], model.upperPositionLimit[i]
            if not lo <= value <= hi:
                given = "" if name in locked else " (the default: give a value in locked)"
                raise RobotError(f"{path}: locked joint {name!r} at {value}{given} is outside its limits [{lo}, {hi}]")
            q_ref[i] = value
        elif nq == 2 and nv == 1:  # continuous joint: (cos θ, sin θ)
            q_ref[i:i + 2] = np.cos(value), np.sin(value)
        elif name in locked:
            raise RobotError(f"{path}: locked joint {name!r} has {nq} coordinates: only its neutral value is supported")
    return q_ref


def _build_visual(path: Path, package_dirs: list[str], full: pin.Model, lock_ids: list[int],
                  q_ref: np.ndarray) -> pin.GeometryModel:
    def build() -> pin.GeometryModel:
        return pin.buildGeomFromUrdf(full, str(path), pin.GeometryType.VISUAL, package_dirs=package_dirs)

    isolated_build(path, "buildGeomFromUrdf", build)
    visual = _urdf_call(path, build)
    if lock_ids:
        visual = pin.buildReducedModel(full, visual, lock_ids, q_ref)[1]
    return visual


class FrameTerms(NamedTuple):
    """Kinematics of one frame's origin at the last :meth:`Robot.update` (world-aligned)."""

    position: np.ndarray  #: p [m], shape (3,)
    velocity: np.ndarray  #: ṗ = J q̇ [m/s], shape (3,)
    jacobian: np.ndarray  #: J = ∂p/∂q, linear rows [m/rad or m/m], shape (3, nv)
    drift: np.ndarray  #: J̇ q̇ [m/s²], shape (3,)
    rotation: np.ndarray  #: frame orientation in the world, shape (3, 3)
    angular_jacobian: np.ndarray  #: ω = J_ω q̇ [rad/s per joint unit], shape (3, nv)


class Robot:
    """A fixed-base robot with only its active joints as degrees of freedom.

    Two Pinocchio data objects: ``data`` holds the state of the last :meth:`update` (read by
    :attr:`H`, :attr:`h`, :meth:`frame_terms`); the allocating convenience functions use their
    own, so calling them between an update and its reads changes nothing.
    """

    def __init__(self, model: pin.Model, source: str, gravity_compensation: float = 0.0, *,
                 locked: dict[str, float] | None = None,
                 visual: pin.GeometryModel | Callable[[], pin.GeometryModel] | None = None):
        self.model = model
        self.data = model.createData()
        self._aux = model.createData()
        self.source = source
        self.gravity_compensation = gravity_compensation  #: fraction of gravity compensated statically
        self.locked = dict(locked or {})  #: locked joint -> value [rad or m]
        self.nq, self.nv = model.nq, model.nv
        self.joint_names = [model.names[j] for j in range(1, model.njoints)]
        self._visual = visual
        if self.nq != self.nv:
            raise RobotError(
                f"{source}: joints with nq != nv (continuous or spherical) are not supported as active joints; "
                "lock them or give them limits"
            )
        diag = np.diag(pin.crba(model, self._aux, pin.neutral(model)))
        if np.any(diag <= 0.0):
            idle = [n for n, d in zip(self.joint_names, diag, strict=True) if d <= 0.0]
            raise RobotError(f"{source}: joint(s) {idle} move no mass or inertia (H(q0) is singular): "
                             "give the links they carry an inertial, or lock them")

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
        """Load a robot; keep ``active_joints`` (default: all not in ``locked``) and lock the rest.

        ``locked`` gives values [rad or m] for locked joints (default 0, which must lie within
        the joint's limits). ``gravity`` [m/s²]; ``gravity_compensation`` is the fraction of
        the gravity load removed by a static compensator (0 ≤ c ≤ 1; case 1 uses 0.7).
        Visual meshes are checked to exist now but loaded on first use of :attr:`visual_model`.
        """
        if not 0.0 <= gravity_compensation <= 1.0:
            raise RobotError(f"gravity_compensation must be in [0, 1], found {gravity_compensation}")
        path, package_dirs = resolve_robot_path(source)
        root = check_urdf_tree(path)  # before Pinocchio: a non-tree URDF crashes it
        isolated_build(path, "buildModelFromUrdf", lambda: pin.buildModelFromUrdf(str(path)))
        full: pin.Model = _urdf_call(path, lambda: pin.buildModelFromUrdf(str(path)))
        _check_links(root, path)
        _check_meshes(root, path, package_dirs)
        _check_limits(full, path)
        names = [full.names[j] for j in range(1, full.njoints)]
        locked = dict(locked or {})
        for name in list(locked) + list(active_joints or []):
            if name not in names:
                raise RobotError(f"{path}: no joint named {name!r}{_suggest(name, names)}; joints: {names}")
        if active_joints is not None:
            both = sorted(set(active_joints) & set(locked))
            if both:
                raise RobotError(f"{path}: joint(s) {both} are both active and locked")
            lock_names = [n for n in names if n not in active_joints]
        else:
            lock_names = [n for n in names if n in locked]
        lock_ids = [full.getJointId(n) for n in lock_names]
        q_ref = _lock_reference(full, lock_names, locked, path)
        model = pin.buildReducedModel(full, lock_ids, q_ref) if lock_ids else full
        model.gravity.linear = (1.0 - gravity_compensation) * np.asarray(gravity, dtype=float)
        values = {n: float(q_ref[full.idx_qs[full.getJointId(n)]]) for n in lock_names}
        visual = functools.partial(_build_visual, path, package_dirs, full, lock_ids, q_ref)
        return cls(model, str(path), gravity_compensation, locked=values, visual=visual)

    @property
    def visual_model(self) -> pin.GeometryModel:
        """Visual geometry with meshes resolved, built on first use (loading meshes takes ~0.3 s)."""
        if callable(self._visual):
            self._visual = self._visual()
        return self._visual

    def frame_id(self, name: str) -> int:
        """Index of a named frame; a clear error lists close matches."""
        if not self.model.existFrame(name):
            names = [f.name for f in self.model.frames]
            hint = _suggest(name, names) or f"; frames: {names}"
            raise RobotError(f"{self.source}: no frame named {name!r}{hint}")
        return self.model.getFrameId(name)

    # ---- the right-hand-side path: one update, then cheap reads ---------------------
    def update(self, q: np.ndarray, v: np.ndarray) -> None:
        """Compute H, h, joint Jacobians and the zero-acceleration kinematics at (q, q̇).

        q, v: float64 arrays of length nv [rad or m], [rad/s or m/s] (not checked here: hot path).
        """
        pin.computeAllTerms(self.model, self.data, q, v)

    @property
    def H(self) -> np.ndarray:
        """Joint-space inertia matrix [kg·m² / kg] at the last update (full, symmetric; a view)."""
        return self.data.M

    @property
    def h(self) -> np.ndarray:
        """Coriolis, centrifugal and uncompensated gravity terms [N·m / N] at the last update (a view)."""
        return self.data.nle

    def frame_terms(self, fid: int) -> FrameTerms:
        """Position, velocity, Jacobian and J̇q̇ of frame ``fid`` at the last update (new arrays)."""
        model, data = self.model, self.data
        placement = pin.updateFramePlacement(model, data, fid)
        J6 = pin.getFrameJacobian(model, data, fid, _LWA).reshape(6, self.nv)  # eigenpy gives (6,) for nv = 1
        return FrameTerms(
            placement.translation,  # placement is already a copy of data.oMf[fid]
            pin.getFrameVelocity(model, data, fid, _LWA).linear,
            J6[:3],
            pin.getFrameClassicalAcceleration(model, data, fid, _LWA).linear,
            placement.rotation,
            J6[3:],
        )

    # ---- convenience (allocating, own data) ---------------------------------------------
    def _fid(self, frame: str | int) -> int:
        return self.frame_id(frame) if isinstance(frame, str) else int(frame)

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """H(q) [kg·m² / kg], a copy."""
        return pin.crba(self.model, self._aux, np.asarray(q, float)).copy()

    def bias(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """h(q, q̇) = C(q, q̇)q̇ + (1 − compensation)·g(q) [N·m / N], a copy."""
        return pin.nonLinearEffects(self.model, self._aux, np.asarray(q, float), np.asarray(v, float)).copy()

    def gravity_torque(self, q: np.ndarray) -> np.ndarray:
        """Uncompensated part of the gravity load, (1 − compensation)·g(q) [N·m / N], a copy."""
        return pin.computeGeneralizedGravity(self.model, self._aux, np.asarray(q, float)).copy()

    def frame_placement(self, q: np.ndarray, frame: str | int) -> pin.SE3:
        """World placement of the frame [m, rotation matrix], a copy."""
        fid = self._fid(frame)
        pin.framesForwardKinematics(self.model, self._aux, np.asarray(q, float))
        return self._aux.oMf[fid].copy()

    def frame_position(self, q: np.ndarray, frame: str | int) -> np.ndarray:
        """World position of the frame's origin [m]."""
        return self.frame_placement(q, frame).translation.copy()

    def frame_jacobian(self, q: np.ndarray, frame: str | int) -> np.ndarray:
        """World-aligned 6×nv Jacobian (linear rows first) of the frame's origin."""
        fid = self._fid(frame)
        J = pin.computeFrameJacobian(self.model, self._aux, np.asarray(q, float), fid, _LWA)
        return J.reshape(6, self.nv).copy()  # eigenpy gives (6,) for nv = 1

    def frame_drift(self, q: np.ndarray, v: np.ndarray, frame: str | int) -> np.ndarray:
        """J̇q̇ of the world-aligned Jacobian: linear [m/s²] (classical) then angular [rad/s²], shape (6,)."""
        fid = self._fid(frame)
        model, data = self.model, self._aux
        pin.forwardKinematics(model, data, np.asarray(q, float), np.asarray(v, float), np.zeros(self.nv))
        pin.updateFramePlacement(model, data, fid)
        return pin.getFrameClassicalAcceleration(model, data, fid, _LWA).vector.copy()

    def kinetic_energy(self, q: np.ndarray, v: np.ndarray) -> float:
        """½ q̇ᵀ H q̇ [J]."""
        return float(pin.computeKineticEnergy(self.model, self._aux, np.asarray(q, float), np.asarray(v, float)))

    def potential_energy(self, q: np.ndarray) -> float:
        """Potential energy of the uncompensated gravity [J]."""
        return float(pin.computePotentialEnergy(self.model, self._aux, np.asarray(q, float)))

    def inverse_kinematics(self, frame: str, target: np.ndarray, q0: np.ndarray, *, tol: float = 1e-12) -> np.ndarray:
        """Joint values putting the frame's origin at ``target`` [m] (Gauss-Newton from q0)."""
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
