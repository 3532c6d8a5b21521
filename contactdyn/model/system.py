"""The system: the robot and the parts a scene names, assembled once; the model's entry points.

:class:`System` builds, from a scene, the robot (Pinocchio), the contacts with their
deformation chains and friction (:mod:`contactdyn.model.contact`), the drives
(:mod:`contactdyn.laws.drives`), one controller per task phase (:mod:`contactdyn.laws.controllers`)
and the state layout (below). The physics lives in modules named after
the paper's concepts; the methods here are the entry points the hybrid loop and the tests
call:

- the right-hand side in one mode is the one pipeline's call (:mod:`contactdyn.model.pipeline`; its answers at an
  instant: :mod:`contactdyn.model.evaluation`);
- :meth:`System.impact` — the plastic impact map (:mod:`contactdyn.model.impact`);
- :meth:`System.project_velocity` — velocities onto the active constraints (same module);
- :meth:`System.start_phase` — a task phase at run time (:mod:`contactdyn.model.phases`);
- the joints' position limits as constraint rows (:attr:`System.limits`, :mod:`contactdyn.model.limits`);
- the joints' damping and dry friction, a stuck joint a row (:attr:`System.joint_friction`,
  :mod:`contactdyn.model.joint_friction`);
- the start posture solved from the task (:mod:`contactdyn.robot.posture`);
- friction's slip velocity (:meth:`System.slip_velocity`, :mod:`contactdyn.model.friction`).

The state layout: which part of the scene owns which slot of the state x
(:func:`assign_chain_slots`, :func:`assign_first_order_slots`; :class:`System` keeps the sizes
``nv``, ``nQ``, ``ny``, ``n = 2 nQ + ny``; a part the scene does not name has no slot):

    x = [Q, Q̇, y]

Q [m, rad] holds the second-order coordinates, in this order:

1. the robot's active joints (nv of them);
2. per active environment body its coordinates (one for a cart; up to three orthogonal ones), along their
   axes [m];
3. one per equivalent mass of a deformation chain (Part I's models a, b), along the
   chain's direction [m];
4. one motor angle per elastic transmission [rad] (:mod:`contactdyn.laws.drives`).

y holds first-order states, in this order:

1. massless chain junctions (two damped stages meeting, or a damped surface end that
   relaxes after a separation) [m];
2. each phase's controller states (integrators of force errors, …);
3. on request (``solver.record_energy``) the energy audit: work done by the drives and
   energy dissipated [J];
4. per friction contact the impulses ∫F dt, ∫F_f dt [N·s] (normal, then one per tangent):
   a stuck robot's state may not move at all; their error control keeps the step size
   following the contact forces the ``slip`` event watches (:mod:`contactdyn.hybrid.events`);
5. per joint with dry friction its friction impulse ∫τ_f dt [N·m·s or N·s] (the holding torque while stuck): for
   the same reason, the ``joint_slip`` event's.

The compiled right-hand side of a mode is the one pipeline (:mod:`contactdyn.model.pipeline`) over this system's
tables; :mod:`contactdyn.model.paths` says which path each mode takes.
"""

from __future__ import annotations

import numpy as np

from ..errors import FrameError, RobotError, SceneError
from ..laws.controllers import CONTROLLERS
from ..laws.controllers.base import BindContext, Controller
from ..laws.controllers.sampled import SampledController
from ..laws.drives import Drives
from ..laws.failures import checked_affine_in_forces, checked_flags, counted_states, is_users, naming_laws
from ..numerics.twins import current
from ..robot.body import ArticulatedBody
from ..robot.posture import start_posture
from ..robot.robot import Robot
from ..scene.scene_file import Scene
from .chain import NodeKind
from .chain_forces import chain_sides
from .constraints import mass_matrix as constraints_mass_matrix
from .contact import Contact, ContactMode, Kinematics, riding_masses, riding_terms, turning_surface
from .evaluation import Evaluation, sample_inputs
from .friction import initial_slip, slip_velocity
from .impact import Impact, impact, project_velocity
from .joint_friction import JointFriction
from .limits import JointLimits
from .phases import Phase, reference_at, start_phase

__all__ = ["System", "Phase", "Evaluation", "Impact", "assign_chain_slots", "assign_first_order_slots"]


class System:
    """Build from a scene; evaluate; map impacts."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.posture: dict = {}  #: how the start posture was found (see contactdyn.robot.posture.start_posture)
        self._q_start: np.ndarray | None = None  #: the solved start posture (solved once: ~0.2 s on a 7-DOF arm)
        rs = scene.robot
        try:
            self.robot = Robot.from_spec(rs)
            self.limits = JointLimits(self.robot, rs.joint_limits == "enforce")
            #: the joints' damping and dry friction (contactdyn.model.joint_friction)
            self.joint_friction = JointFriction(self.robot, rs, scene.file)
            self.tip_fid = self.robot.frame_id(rs.tip)
        except FrameError as exc:  # (the robot's load finds its tip first)
            raise SceneError("robot.tip", "a frame of the robot", exc, scene.file) from None
        except RobotError as exc:  # (a joint name of active_joints or locked: that key)
            expected = "joints of the robot (each active or locked, not both)" if exc.key else "a loadable robot"
            raise SceneError(exc.key or "robot.urdf", expected, exc, scene.file) from None
        nv = self.nv = self.robot.nv
        # ---- generalized coordinates: robot, bodies, chain masses, motors (the state layout, below) ----
        self.body_names = list(scene.bodies)
        #: per body, its coordinates' (index in Q, unit axis): one for a cart, up to three orthogonal ones
        self.body_coords: dict[str, list[tuple[int, np.ndarray]]] = {}
        coords = [(name, c) for name, b in scene.bodies.items() for c in b.coordinates]
        for i, (name, c) in enumerate(coords):
            self.body_coords.setdefault(name, []).append((nv + i, c.axis))
        self.body_index = {name: cs[0][0] for name, cs in self.body_coords.items()}  #: a body's first coordinate
        #: per body coordinate: (its name: <b> for a one-coordinate body, else <b>.<joint>; its index in Q); its
        #: channels are body.<name>.*
        self.body_channels = _coordinate_names(scene, nv)
        #: the bodies with revolute joints, by name (their H_b, h_b and frames: contactdyn.robot.body.ArticulatedBody)
        self.articulated = {name: _articulated(scene, name, b, self.body_coords[name][0][0])
                            for name, b in scene.bodies.items() if b.articulated}
        diag: list[float] = [c.mass for _, c in coords]
        self.contacts = [self._contact_of(spec) for spec in scene.contacts.values()]
        self.mass_labels, n_first = assign_chain_slots(self.contacts, nv, diag)
        self.riding = riding_masses(self.contacts, nv)  #: chain masses riding turning surfaces (contact.RidingMass)
        self.drives = self._build_drives(nv + len(diag))  # elastic transmissions: motor angles after the masses
        diag += self.drives.motor_inertias
        self.nQ = nv + len(diag)
        self.M_rest = np.asarray(diag, float)  #: inertia of the non-robot coordinates [kg, kg·m² for motors]
        #: [N] the non-robot coordinates' weights: a body's m g·axis (g the world's, robot.gravity), 0 for the others
        self.weights = np.zeros(len(diag))
        self.weights[: len(coords)] = [c.mass * float(scene.robot.gravity @ c.axis) for _, c in coords]
        self.M_rest[: len(coords)] += self.drives.reflected[nv:]  # rotor inertia through a wheel
        self._D = self.drives.reflected[:nv]  #: rotor inertias reflected on the joints (true system)
        #: [kg·m²] (nv, nv) the rotors reflected on the joints in the controller's rigid model (zero: no motor)
        self._D_ctl = np.diag(self.drives.model_reflected[:nv])
        # ---- controllers, then the first-order slots after the junctions ----
        self.controllers = _bound_controllers(scene, list(self.robot.joint_names), self.drives.has_voltage[:nv], nv)
        #: impulse_slots: per friction contact y's slot of ∫F dt; joint_impulse_slot: the first joint with dry
        #: friction's ∫τ_f dt (one per such joint, in JointFriction.dry's order)
        self.z_slices, self.energy_slot, self.impulse_slots, self.joint_impulse_slot, self.ny = \
            assign_first_order_slots(n_first, [ctl.n_states for ctl in self.controllers], scene.solver.record_energy,
                                     self.contacts, len(self.joint_friction.dry))
        for body in (b for b in self.articulated.values() if b.free):  # a free body's chart: one slot
            body.chart_index, self.ny = 2 * self.nQ + self.ny, self.ny + 1
        self.n = 2 * self.nQ + self.ny
        self.stabilization = scene.solver.stabilization  #: Baumgarte rate ω of constraint rows [1/s]
        self._M = np.zeros((self.nQ, self.nQ))
        self._M[nv:, nv:] = np.diag(self.M_rest)
        self.servo = [(self.body_index[n], b.servo_velocity, b.servo_gain)
                      for n, b in scene.bodies.items() if b.servo_velocity is not None]
        self.stage_labels = [f"{c.name}.{dc.label}.{s.label}" for c in self.contacts for dc in c.chains
                             for s in dc.chain.stages]
        #: unit direction of each force set-point key (see ForceSpec.key): the robot pushes along −u
        self.force_directions = {c.name: c.normal.u for c in self.contacts}
        self.force_directions.update({f"{c.name}.t{i + 1}": t for c in self.contacts for i, t in enumerate(c.tangents)})
        self.slip_band = scene.solver.stick_velocity  #: [m/s] stick/slip guard band (see contactdyn.model.friction)
        _force_readers_checked(self)

    def _contact_of(self, spec) -> Contact:
        """A contact: its touching side a robot frame or a body's point (``frame_point``), its surface the ground,
        a body (each body side by its coordinates; an articulated one by a frame of it) or a robot frame
        (``surface_frame``)."""
        surface_link = _link(self, spec, spec.body, "surface_frame", spec.surface_frame)
        surface_coords = [] if surface_link else self.body_coords.get(spec.body, [])
        surface_fid = -1 if surface_link else self._surface_fid(spec)
        if spec.frame_point is not None:  # a body touches
            if self.robot.model.existFrame(spec.frame):
                raise SceneError(f"contact.{spec.name}.frame", "a name that is a body's or a robot frame's, not "
                                 "both (rename the body)", f"{spec.frame!r}, both", self.scene.file)
            touch_link = _link(self, spec, spec.frame, "body_frame", spec.body_frame)
            contact = Contact(spec, -1, [] if touch_link else self.body_coords[spec.frame], surface_coords,
                              surface_fid, touch_link, surface_link)
            if surface_fid < 0 and not touch_link and not surface_link:  # their axes alone carry the normal
                row = np.zeros((1, self.nv + len(self.body_channels)))
                contact.add_columns(row, spec.normal[None])
                if not np.any(np.abs(row) > 1e-12):
                    raise SceneError(f"contact.{spec.name}.normal.direction", "a normal along which a side moves "
                                     "(the bodies' axes are all orthogonal to it: nothing would carry its force)",
                                     spec.normal.tolist(), self.scene.file)
            return contact
        try:
            fid = self.robot.frame_id(spec.frame)
        except RobotError as exc:
            hint = f" (a body's point touches with frame_point = [x, y, z] beside frame = {spec.frame!r})" \
                if spec.frame in self.body_coords else ""
            raise SceneError(f"contact.{spec.name}.frame", f"a frame of the robot{hint}", exc,
                             self.scene.file) from None
        if fid == surface_fid:
            raise SceneError(f"contact.{spec.name}.surface_frame", "a robot frame other than the touching one",
                             spec.surface_frame, self.scene.file)
        return Contact(spec, fid, [], surface_coords, surface_fid, None, surface_link)

    def _surface_fid(self, spec) -> int:
        """The robot frame carrying the contact's surface (``body = "robot"``), -1 for the ground or a body."""
        if spec.surface_frame is None:
            return -1
        try:
            return self.robot.frame_id(spec.surface_frame)
        except RobotError as exc:
            raise SceneError(f"contact.{spec.name}.surface_frame", "a frame of the robot", exc,
                             self.scene.file) from None

    def _build_drives(self, first_motor_coord: int) -> Drives:
        names = list(self.robot.joint_names)
        specs = self.scene.robot.drive.expand(self.nv, names)
        coords = list(range(self.nv))
        for (name, index), body in zip(self.body_channels, self._coordinate_bodies(), strict=True):
            specs += body.drive.expand(1, [name])  # (a body with several coordinates: no drive, an ideal one each)
            coords.append(index)
            names.append(name)
        return Drives(specs, coords, names, first_motor_coord)

    def _coordinate_bodies(self) -> list:
        """The BodySpec of each body coordinate, in Q's order."""
        return [b for b in self.scene.bodies.values() for _ in b.coordinates]

    @property
    def rotor_inertias(self) -> np.ndarray:
        """[kg·m²] (nv,) the rotors reflected on the joints (rigid gears; zero without a motor)."""
        return self._D

    def controller_inertia(self, H: np.ndarray) -> np.ndarray:
        """[kg·m²] The controller's H: the robot's ``H`` (one sample or a stack) with the rotors reflected."""
        return H + self._D_ctl if self.drives.any_motor else H

    # ---- initial state ------------------------------------------------------------------
    def initial_state(self) -> tuple[np.ndarray, list[ContactMode]]:
        rs, robot = self.scene.robot, self.robot
        if self._q_start is None:  # every compiled mode's self-check starts here too
            self._q_start, self.posture = start_posture(robot, rs, self.scene.phases[0].controller, self.scene.file)
        q = self._q_start.copy()
        v = rs.v0.copy() if rs.v0 is not None else np.zeros(robot.nv)
        if len(v) != robot.nv:
            raise SceneError("robot.v0", f"{robot.nv} joint velocities", rs.v0.tolist(), self.scene.file)
        x = np.zeros(self.n)
        nQ, nv = self.nQ, self.nv
        x[:nv], x[nQ:nQ + nv] = q, v
        for name, b in self.scene.bodies.items():
            for (i, _), c in zip(self.body_coords[name], b.coordinates, strict=True):
                x[i], x[nQ + i] = c.position0, c.velocity0
        for body in self.articulated.values():  # a free body near pitch ±90° starts in chart B
            x = body.start_chart(x, nQ)
        self.drives.initial(x, nQ)
        robot.update(q, v)
        modes = []
        for c in self.contacts:
            kin = self.kinematics(c, x)
            gap0 = kin.gap  # chains start undeformed
            pressed_in = gap0 < -1e-9 and not c.spec.bonded  # a compliant surface starts deformed (a warning)
            if pressed_in and c.spec.normal_chain.rigid:
                raise SceneError(f"contact.{c.name}", "a start with the tip on or above the rigid surface (gap >= 0)",
                                 f"gap {gap0:.6g} m", self.scene.file)
            touching = c.spec.bonded or gap0 <= 1e-12
            # masses start at rest where their chain puts them undeformed (zero rest lengths)
            for dc in c.chains:
                u, p_tip, v_tip, p_env, v_env = chain_sides(c, dc, kin)
                s_tip, s_anc, v_tip, v_anc = float(u @ p_tip), float(u @ p_env), float(u @ v_tip), float(u @ v_env)
                for node in dc.chain.nodes:
                    if node.kind == NodeKind.MASS:
                        on_robot = node.side == "robot" or pressed_in
                        x[node.coord] = s_tip if on_robot else s_anc
                        x[nQ + node.coord] = v_tip if on_robot else v_anc
                    if node.state >= 0:
                        x[2 * nQ + node.state] = s_tip if node.side == "robot" else s_anc
                if dc.junction_state >= 0:
                    x[2 * nQ + dc.junction_state] = s_anc
            modes.append(ContactMode(touching=touching, offsets=tuple(0.0 for _ in c.tangent_chains),
                                     slip=initial_slip(c, kin)))
        return x, modes

    # ---- phases ---------------------------------------------------------------------------
    def start_phase(self, index: int, t: float, x: np.ndarray, previous: Phase | None) -> Phase:
        """Phase ``index`` starting at t [s] in state x (see :func:`contactdyn.model.phases.start_phase`)."""
        return start_phase(self, index, t, x, previous)

    def reference_at(self, phase: Phase, t: float, x: np.ndarray):
        """The phase's reference (x_d, v_d, a_d) at (t, x), or Nones (:func:`contactdyn.model.phases.reference_at`)."""
        return reference_at(self, phase, t, x)

    # ---- kinematics and inertia ------------------------------------------------------------
    def kinematics(self, c: Contact, x: np.ndarray) -> Kinematics:
        """Contact kinematics at x; requires ``robot.update`` at x's (q, q̇) first (an articulated body's side is
        computed here at x's coordinates)."""
        columns: tuple = ()
        if c.touch_link is not None:  # an articulated body's point touches: its joints move it
            body, fid = c.touch_link
            body.update(x, self.nQ)
            p_tip, v_tip, J_b, drift = body.point(fid, c.spec.frame_point)
            J, ft = np.zeros((3, self.nv)), None
            columns = tuple((i, J_b[:, k]) for k, i in enumerate(body.indices))
        elif c.fid < 0:  # a body's point touches: no robot joint moves it
            p_tip, v_tip = c.toucher(x, self.nQ)
            J, drift, ft = np.zeros((3, self.nv)), np.zeros(3), None
        else:
            ft = self.robot.frame_terms(c.fid)
            p_tip, v_tip, J, drift = ft.position, ft.velocity, ft.jacobian, ft.drift
        if c.surface_link is not None:
            return _on_body_frame(self, c, x, p_tip, v_tip, J, drift, ft, columns)
        if c.surface_fid < 0:
            p_env, v_env = c.surface(x, self.nQ)
            return Kinematics(p_tip, v_tip, J, drift, p_env, v_env, ft, c.normal.u, c.tangents, columns)
        fs = self.robot.frame_terms(c.surface_fid)  # the surface turns with a robot frame
        spec = c.spec
        J, drift, p_env, v_env, n, T = current(turning_surface)(  # (its twin in an interpreted run)
            p_tip, v_tip, J, drift, fs.position, fs.velocity, fs.jacobian, fs.drift, fs.rotation,
            fs.angular_jacobian @ x[self.nQ:self.nQ + self.nv], fs.angular_jacobian, fs.angular_drift, spec.point,
            spec.normal, spec.tangents)
        return Kinematics(p_tip, v_tip, J, drift, p_env, v_env, ft, n, T, columns)

    def update_at(self, x: np.ndarray) -> None:
        """The robot's terms at x's (q [rad or m], q̇) and the articulated bodies' and riding masses' (what
        :meth:`kinematics` and :meth:`mass_matrix` read)."""
        self.robot.update(x[:self.nv], x[self.nQ:self.nQ + self.nv])
        self.update_bodies(x)

    def update_bodies(self, x: np.ndarray) -> None:
        """The articulated bodies' terms at x (H_b, h_b, their frames; each skipped when its state is unchanged) and
        the riding masses' (after ``robot.update`` at x)."""
        for body in self.articulated.values():
            body.update(x, self.nQ)
        _update_riding(self, x)

    def mass_matrix(self) -> np.ndarray:
        """M [kg, kg·m²] at the last ``robot.update`` (and ``update_bodies``), a copy of
        :func:`contactdyn.model.constraints.mass_matrix`'s."""
        return constraints_mass_matrix(self).copy()

    def slip_velocity(self, c: Contact, kin: Kinematics, qd: np.ndarray | None = None) -> np.ndarray:
        """Tangential tip–environment velocity [m/s] (:func:`contactdyn.model.friction.slip_velocity`)."""
        return slip_velocity(self, c, kin, qd)

    # ---- impacts, separation ----------------------------------------------------------------------------
    def impact(self, t: float, x: np.ndarray, modes: list[ContactMode], contact: Contact,
               limits: tuple = ()) -> tuple[np.ndarray, Impact]:
        """Velocity jump when ``contact`` touches, joints pressing on ``limits`` held
        (:func:`contactdyn.model.impact.impact`)."""
        return impact(self, t, x, modes, contact, limits)

    def project_velocity(self, x: np.ndarray, modes: list[ContactMode], limits: tuple = ()) -> np.ndarray:
        """x with Q̇ moved onto every active velocity constraint, the joints pressing on ``limits`` included
        (:func:`contactdyn.model.impact.project_velocity`)."""
        return project_velocity(self, x, modes, limits)

    def separate(self, x: np.ndarray, contact: Contact, ev: Evaluation) -> np.ndarray:
        """State at separation: damped surface ends start relaxing from where they are (``ev``: the model at x in
        the modes before, still touching)."""
        x = x.copy()
        for dc in contact.chains:
            chain, positions = dc.chain, ev.node_positions[f"{contact.name}.{dc.label}"]
            for node_i in (chain.env_surface, chain.robot_surface):
                slot = chain.nodes[node_i].state
                if chain.nodes[node_i].kind == NodeKind.FREE and slot >= 0:
                    x[2 * self.nQ + slot] = positions[node_i]
        return x


# ---- articulated bodies (bodies with revolute joints) ------------------------------------------------------
def _articulated(scene: Scene, name: str, spec, first: int) -> ArticulatedBody:
    """The run-time model of body ``name``, whose URDF has revolute joints (gravity the world's), its first
    coordinate at ``first`` in Q."""
    try:
        robot = Robot.load(spec.urdf, gravity=tuple(scene.robot.gravity), free=spec.free, body=True)
    except RobotError as exc:
        raise SceneError(f"body.{name}.urdf", "a loadable URDF", exc, scene.file) from None
    return ArticulatedBody(name, robot, first, spec.free)


def _link(system: System, spec, body: str, key: str, frame: str | None) -> tuple | None:
    """(ArticulatedBody, frame id) of ``frame`` on ``body`` if it is articulated (``key``: the contact's key naming
    the frame), else None."""
    if body not in system.articulated:
        return None
    art = system.articulated[body]
    try:
        return art, art.robot.frame_id(frame)
    except RobotError as exc:
        raise SceneError(f"contact.{spec.name}.{key}", f"a frame of body {body!r}", exc,
                         system.scene.file) from None


def _update_riding(system: System, x: np.ndarray) -> None:
    """The riding masses' terms at x (:func:`~contactdyn.model.contact.riding_terms`; the robot and the articulated
    bodies updated at x)."""
    nQ = system.nQ
    for rm in system.riding:
        c = rm.contact
        frame = c.surface_link[0].frame(c.surface_link[1]) if c.surface_link is not None else \
            system.robot.frame_terms(c.surface_fid)
        w = frame.angular_jacobian @ x[nQ + rm.carrier]  # ω [rad/s]
        riding_terms(rm, frame, w, float(x[rm.coord]), float(x[nQ + rm.coord]))


def _on_body_frame(system: System, c: Contact, x: np.ndarray, p_tip, v_tip, J, drift, ft, columns: tuple
                   ) -> Kinematics:
    """A surface carried by a frame of an articulated body: :func:`turning_surface` over the robot's joints and the
    body's, the Jacobians side by side ([robot | body]); the body's part of J_rel its columns (``columns``: the
    touching side's so far)."""
    body, fid = c.surface_link
    nQ, nv, nb = system.nQ, system.nv, body.nb
    body.update(x, nQ)
    fs = body.frame(fid)
    w = fs.angular_jacobian @ x[nQ + body.first:nQ + body.first + nb]  # ω [rad/s]
    J_ext = np.hstack([J, np.zeros((3, nb))])
    J_o = np.hstack([np.zeros((3, nv)), fs.jacobian])
    J_w = np.hstack([np.zeros((3, nv)), fs.angular_jacobian])
    spec = c.spec
    J_rel, a_rel, p_env, v_env, n, T = current(turning_surface)(
        p_tip, v_tip, J_ext, drift, fs.position, fs.velocity, J_o, fs.drift, fs.rotation, w, J_w, fs.angular_drift,
        spec.point, spec.normal, spec.tangents)
    columns = columns + tuple((i, J_rel[:, nv + k]) for k, i in enumerate(body.indices))
    return Kinematics(p_tip, v_tip, J_rel[:, :nv].copy(), a_rel, p_env, v_env, ft, n, T, columns)


# ---- the state layout (see the module docstring) --------------------------------------------------------
def _coordinate_names(scene: Scene, nv: int) -> list[tuple[str, int]]:
    """Per body coordinate (its name, its index in Q): the body's for a one-coordinate body, else <body>.<joint>;
    two that would share a name (a body "a.b" beside a body "a" with a joint "b") are one SceneError."""
    out: list[tuple[str, int]] = []
    for name, b in scene.bodies.items():
        for c in b.coordinates:
            label = name if len(b.coordinates) == 1 else f"{name}.{c.joint}"
            if any(label == other for other, _ in out):
                raise SceneError(f"body.{name}", "body names whose coordinates' channels differ",
                                 f"two coordinates named {label!r} (body.{label}.x)", scene.file)
            out.append((label, nv + len(out)))
    return out


def assign_chain_slots(contacts: list[Contact], nv: int, diag: list[float]) -> tuple[list[str], int]:
    """Give every chain mass a coordinate of Q and every chain junction a slot of y.

    ``diag`` holds the inertias of Q's non-robot coordinates so far (the bodies' masses
    [kg]); each chain mass appends its own. Returns (mass labels, number of junction slots).
    """
    mass_labels: list[str] = []
    n_first = 0
    for c in contacts:
        for dc in c.chains:
            for node in dc.chain.nodes:
                if node.kind == NodeKind.MASS:
                    node.coord = nv + len(diag)
                    diag.append(node.mass)
                    mass_labels.append(f"{c.name}.{dc.label}.m{len(mass_labels) + 1}")
            chain = dc.chain
            for i, node in enumerate(chain.nodes):
                stages_i = [chain.stages[k] for k in chain.stages_of(i)]
                relaxes = i in (chain.env_surface, chain.robot_surface) and len(stages_i) == 1 and \
                    stages_i[0].kelvin_voigt is not None and stages_i[0].kelvin_voigt[1] > 0.0
                if node.kind == NodeKind.FREE and (len(stages_i) == 2 or relaxes):
                    node.state = n_first  # a junction, or a damped surface end relaxing after separation
                    n_first += 1
            if chain.junction_when_touching:
                es_state = chain.nodes[chain.env_surface].state
                dc.junction_state = es_state if es_state >= 0 else n_first
                n_first += 0 if es_state >= 0 else 1
    return mass_labels, n_first


def assign_first_order_slots(n_first: int, controller_states: list[int], record_energy: bool,
                             contacts: list[Contact], dry_joints: int = 0
                             ) -> tuple[list[slice], int, dict[str, int], int, int]:
    """Slots of y after the junctions: (controller slices, energy slot or −1, the friction contacts' impulse slots,
    the first of the ``dry_joints`` joints' impulse slots, ny)."""
    z_slices = []
    for n_states in controller_states:
        z_slices.append(slice(n_first, n_first + n_states))
        n_first += n_states
    energy_slot = n_first if record_energy else -1
    n_first += 2 if record_energy else 0
    impulse_slots: dict[str, int] = {}
    for c in contacts:
        if c.friction is not None and len(c.tangents):
            impulse_slots[c.name] = n_first
            n_first += 1 + len(c.tangents)
    return z_slices, energy_slot, impulse_slots, n_first, n_first + dry_joints


def _bound_controllers(scene: Scene, joint_names: list[str], motorized: np.ndarray, nv: int) -> list[Controller]:
    """The phases' controllers, built and bound: a user's law raising there is its LawError, its n_states and flags
    are checked, and a law that gives voltages needs a motor on every joint (else its voltages would act as torques)."""
    controllers = []
    with naming_laws():
        for i, p in enumerate(scene.phases):
            ctl = _controller_of(p, nv)
            context = BindContext(scene, p, i, joint_names, motorized.copy(), p.controller_key)
            ctl.bind(context)
            law = ctl.inner if isinstance(ctl, SampledController) else ctl
            counted_states(law)  # (a sampled one's: its law's, named; the hold adds nv slots of its own)
            checked_flags(law)
            if law.outputs == "voltage":
                context.require_motors(f"{p.controller_key}.kind", f"a controller that gives voltages ({law.name!r})")
            controllers.append(ctl)
    return controllers


def _force_readers_checked(system: System) -> None:
    """Each phase's law of a user that reads forces (``uses_forces``) checked affine in them at ControlInputs of its
    phase (:func:`~contactdyn.laws.failures.checked_affine_in_forces` at :func:`.evaluation.sample_inputs`: at rest and
    moving): the solve folds them in. The package's own force-reading laws are affine by their construction
    (tested)."""
    for spec, ctl in zip(system.scene.phases, system.controllers, strict=True):
        law = ctl.inner if isinstance(ctl, SampledController) else ctl
        if law.uses_forces and is_users(type(law)):
            for inp in sample_inputs(system, spec, law):
                checked_affine_in_forces(law, inp)


def _controller_of(spec, nv: int) -> Controller:
    """The controller of a phase: its kind's law, wrapped in a zero-order hold when it is sampled."""
    law = CONTROLLERS[spec.controller.kind](spec.controller, nv)
    return law if spec.sampling is None else SampledController(law, spec.sampling, nv)
