"""The system: robot + the parts a scene names, its state layout and its right-hand side.

State x = [Q, Q̇, y]. Q holds the second-order coordinates: the robot's active joints,
one coordinate per active environment body (a cart) and one per equivalent mass of a
deformation chain; y holds first-order states: massless chain junctions, controller
integrators, on request the energy audit, and the impulses ∫F dt, ∫F_f dt of each
friction contact (see ``impulse_slots``). A part the scene does not name has no slot and
costs nothing.

In every mode the unknowns (Q̈ and the forces of active constraint rows: bonds, rigid
contacts, sticking friction) come from one linear system

    [ M  −Cᵀ ] [Q̈]   [ f  ]
    [ G   0  ] [λ ] = [ −γ ]

where G Q̈ + γ = 0 are the acceleration-level constraints and C their force columns (a
row's own direction, tilted by sliding friction −μ d). The plastic impact map solves
the same matrix with velocity jumps (momentum law): M ΔQ̇ = Cᵀ Λ, G Q̇⁺ = 0.

Drives (:mod:`contactdyn.drives`) turn the controller's command into generalized forces:
rigid gears add their reflected rotor inertia to M's diagonal, elastic transmissions add
a motor angle to Q (after the chain masses). A controller that reads measured forces is
affine in them, τ = τ₀ + B λ; its columns B are folded into the matrix (−Cᵀ − B), so the
force it measures is the one the solve returns (see :mod:`contactdyn.controllers.base`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .chain import NodeKind
from .contact import Contact, ContactMode, DirectionalChain, Kinematics
from .controllers import CONTROLLERS, ControlInput, Controller
from .controllers.base import BindContext
from .drives import Drives
from .errors import RobotError, SceneError, SimulationError
from .limits import JointLimits
from .posture import start_posture
from .robot import Robot
from .scene import PhaseSpec, Scene
from .trajectory import Ramp, Reference

__all__ = ["System", "Phase", "Evaluation", "Impact"]

CONE_TOL = 1e-10  #: relative slack of the friction-cone tests |F_f| ≤ μ_s F (round-off of the solves)
FORCE_ABS_TOL = 1e-12  #: [N] absolute slack of the same tests

try:  # numpy's gufunc without the Python wrapper: ~4x cheaper on tiny systems
    from numpy.linalg import _umath_linalg

    _fast_solve = _umath_linalg.solve1
except (ImportError, AttributeError):  # pragma: no cover
    _fast_solve = np.linalg.solve


def solve_linear(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, bool]:
    """Solve A z = b; on a singular A fall back to the minimum-norm least-squares z."""
    with np.errstate(all="ignore"):
        z = _fast_solve(A, b)
    if np.all(np.isfinite(z)) and np.linalg.norm(A @ z - b) <= 1e-9 * (1.0 + np.linalg.norm(b)):
        return z, True
    return np.linalg.lstsq(A, b, rcond=1e-12)[0], False


@dataclass
class Phase:
    """A task phase at run time: its controller, reference and force set-points (absolute times)."""

    spec: PhaseSpec
    index: int
    t_start: float  #: [s]
    controller: Controller
    z_slice: slice
    reference: Reference | None = None
    forces: dict[str, Ramp] = field(default_factory=dict)
    #: (body coordinate, unit axis) when the reference rides on an active body (``reference.body``):
    #: x_d = axis · Q_b + reference (see :meth:`System.reference_at`)
    carrier: tuple[int, np.ndarray] | None = None
    #: joints pressing on a position limit: (coordinate, +1 lower / −1 upper), see contactdyn.limits
    limits: tuple[tuple[int, int], ...] = ()


@dataclass
class Impact:
    """A plastic impact at touch: impulses [N·s] and velocities before and after."""

    t: float
    contact: str
    normal_impulse: float  #: FΔt
    friction_impulse: np.ndarray  #: F_fΔt per tangent
    jammed: bool
    energy_loss: float  #: [J]
    v_before: np.ndarray  #: Q̇⁻
    v_after: np.ndarray  #: Q̇⁺
    slip_before: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: tangential velocity [m/s]
    slip_after: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: tangential velocity [m/s]
    direction: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: sliding direction d (0: none)


@dataclass
class Evaluation:
    """Everything the right-hand side computes at one (t, x) in one mode."""

    xdot: np.ndarray
    lam: np.ndarray  #: forces of the active rows [N]
    row_meta: list[tuple[str, str, int]]  #: (contact, "n" or "t", tangent index) per row
    normal_force: dict[str, float]  #: interface force per contact [N], > 0 pressing
    friction: dict[str, np.ndarray]  #: friction force per contact, tangent coordinates [N]
    slip: dict[str, np.ndarray]  #: slip velocity per contact, tangent coordinates [m/s]
    gap: dict[str, float]  #: normal gap [m] (0 while touching)
    stages: dict[str, tuple[float, float, float]]  #: label -> (x [m], ẋ [m/s], F [N])
    interface: dict[str, float]  #: tangential chain interface forces per "contact.t1" [N]
    tau: np.ndarray  #: joint torques [N·m or N]
    body_force: np.ndarray  #: drive force on each active body [N]
    p_tip: np.ndarray  #: controlled tip position [m]
    x_d: np.ndarray | None  #: reference
    force_d: dict[str, float]
    regular: bool = True  #: False when the linear solve fell back to least squares
    tau_cmd: np.ndarray | None = None  #: the controller's command per joint [N·m or N; V for voltage controllers]
    u: np.ndarray | None = None  #: motor voltage per drive (joints, then bodies) [V], NaN for ideal drives
    limit_torque: dict[int, float] = field(default_factory=dict)  #: joint -> limit torque [N·m or N] (pressing)


class System:
    """Build from a scene; evaluate; map impacts."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.posture: dict = {}  #: how the start posture was found (see contactdyn.posture.start_posture)
        rs = scene.robot
        try:
            self.robot = Robot.from_spec(rs)
            self.limits = JointLimits(self.robot, rs.joint_limits == "enforce")
            self.tip_fid = self.robot.frame_id(rs.tip)
        except RobotError as exc:
            raise SceneError("robot", "a loadable robot", str(exc), scene.file) from None
        nv = self.nv = self.robot.nv
        # ---- generalized coordinates ----
        diag: list[float] = []
        self.body_names = list(scene.bodies)
        self.body_index = {name: nv + i for i, name in enumerate(self.body_names)}
        diag += [b.mass for b in scene.bodies.values()]
        self.contacts: list[Contact] = []
        for spec in scene.contacts.values():
            try:
                fid = self.robot.frame_id(spec.frame)
            except RobotError as exc:
                raise SceneError(f"contact.{spec.name}.frame", "a frame of the robot", str(exc), scene.file) from None
            idx = self.body_index.get(spec.body, -1)
            axis = scene.bodies[spec.body].axis if spec.body in scene.bodies else np.zeros(3)
            self.contacts.append(Contact(spec, fid, idx, axis))
        self.mass_labels: list[str] = []
        n_first = 0
        for c in self.contacts:
            for dc in c.chains:
                for node in dc.chain.nodes:
                    if node.kind == NodeKind.MASS:
                        node.coord = nv + len(diag)
                        diag.append(node.mass)
                        self.mass_labels.append(f"{c.name}.{dc.label}.m{len(self.mass_labels) + 1}")
                chain = dc.chain
                for i, node in enumerate(chain.nodes):
                    stages_i = [chain.stages[k] for k in chain.stages_of(i)]
                    relaxes = i in (chain.env_surface, chain.robot_surface) and len(stages_i) == 1 and \
                        stages_i[0].b > 0.0 and stages_i[0].law == "linear"
                    if node.kind == NodeKind.FREE and (len(stages_i) == 2 or relaxes):
                        node.state = n_first  # a junction, or a damped surface end relaxing after separation
                        n_first += 1
                if chain.junction_when_touching:
                    es_state = chain.nodes[chain.env_surface].state
                    dc.junction_state = es_state if es_state >= 0 else n_first
                    n_first += 0 if es_state >= 0 else 1
        # ---- drives: elastic transmissions add motor angles after the chain masses ----
        self.drives = self._build_drives(nv + len(diag))
        diag += self.drives.motor_inertias
        self.nQ = nv + len(diag)
        self.M_rest = np.asarray(diag, float)  #: inertia of the non-robot coordinates [kg, kg·m² for motors]
        self.M_rest[: len(self.body_names)] += self.drives.reflected[nv:]  # rotor inertia through a wheel
        self._D = self.drives.reflected[:nv]  #: rotor inertias reflected on the joints (true system)
        self._D_ctl = self.drives.model_reflected[:nv]  #: the same in the controller's rigid model
        self._joint_motors = self.drives.motorized & (np.arange(len(self.drives.specs)) < nv)  #: voltage mask
        self.n_junctions = n_first
        # ---- controller states, energy audit ----
        self.controllers = [CONTROLLERS[p.controller.kind](p.controller, nv) for p in scene.phases]
        for i, (p, ctl) in enumerate(zip(scene.phases, self.controllers, strict=True)):
            ctl.bind(BindContext(scene, p, i, list(self.robot.joint_names), self.drives.motorized[:nv].copy(),
                                 f"phase[{i}].controller"))
        self.z_slices = []
        for ctl in self.controllers:
            self.z_slices.append(slice(n_first, n_first + ctl.n_states))
            n_first += ctl.n_states
        self.energy_slot = n_first if scene.solver.record_energy else -1
        n_first += 2 if scene.solver.record_energy else 0
        #: per friction contact, the impulses ∫F dt, ∫F_f dt [N·s] (normal, then one per tangent). A stuck
        #: robot's state may not move at all; their error control keeps the step size following the
        #: contact forces that the ``slip`` event watches (see simulate), instead of growing without bound.
        self.impulse_slots: dict[str, int] = {}
        for c in self.contacts:
            if c.friction is not None and len(c.tangents):
                self.impulse_slots[c.name] = n_first
                n_first += 1 + len(c.tangents)
        self.ny = n_first
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
        self.slip_band = scene.solver.stick_velocity  #: [m/s] stick/slip guard band (see simulate)

    def _build_drives(self, first_motor_coord: int) -> Drives:
        names = list(self.robot.joint_names)
        specs = self.scene.robot.drive.expand(self.nv, names)
        coords = list(range(self.nv))
        for name, b in self.scene.bodies.items():
            specs += b.drive.expand(1, [name])
            coords.append(self.body_index[name])
            names.append(name)
        return Drives(specs, coords, names, first_motor_coord)

    # ---- initial state ------------------------------------------------------------------
    def initial_state(self) -> tuple[np.ndarray, list[ContactMode]]:
        rs, robot = self.scene.robot, self.robot
        q, self.posture = start_posture(robot, rs, self.scene.phases[0].controller, self.scene.file)
        v = rs.v0.copy() if rs.v0 is not None else np.zeros(robot.nv)
        if len(v) != robot.nv:
            raise SceneError("robot.v0", f"{robot.nv} joint velocities", rs.v0.tolist(), self.scene.file)
        x = np.zeros(self.n)
        nQ, nv = self.nQ, self.nv
        x[:nv], x[nQ:nQ + nv] = q, v
        for name, b in self.scene.bodies.items():
            x[self.body_index[name]], x[nQ + self.body_index[name]] = b.position0, b.velocity0
        self.drives.initial(x, nQ)
        robot.update(q, v)
        modes = []
        for c in self.contacts:
            kin = self.kinematics(c, x)
            gap0 = float(c.normal.u @ (kin.p_tip - kin.p_env))  # chains start undeformed
            if gap0 < -1e-9 and not c.spec.bonded:
                raise SceneError(f"contact.{c.name}", "a start with the tip on or above the surface (gap >= 0)",
                                 f"gap {gap0:.6g} m", self.scene.file)
            touching = c.spec.bonded or gap0 <= 1e-12
            # masses start at rest where their chain puts them undeformed (zero rest lengths)
            for dc in c.chains:
                s_tip, s_anc = float(dc.u @ kin.p_tip), float(dc.u @ kin.p_env)
                v_tip, v_anc = float(dc.u @ kin.v_tip), float(dc.u @ kin.v_env)
                for node in dc.chain.nodes:
                    if node.kind == NodeKind.MASS:
                        on_robot = node.side == "robot"
                        x[node.coord] = s_tip if on_robot else s_anc
                        x[nQ + node.coord] = v_tip if on_robot else v_anc
                    if node.state >= 0:
                        x[2 * nQ + node.state] = s_tip if node.side == "robot" else s_anc
                if dc.junction_state >= 0:
                    x[2 * nQ + dc.junction_state] = s_anc
            modes.append(ContactMode(touching=touching, offsets=tuple(0.0 for _ in c.tangent_chains),
                                     slip=self._initial_slip(c, kin)))
        return x, modes

    def _initial_slip(self, c: Contact, kin: Kinematics) -> tuple[float, ...]:
        if c.friction is None:
            return ()
        vt = c.tangents @ (kin.v_tip - kin.v_env)
        norm = float(np.linalg.norm(vt))
        if norm == 0.0:
            return tuple(np.eye(len(vt))[0]) if len(vt) else ()
        return tuple(np.sign(vt)) if len(vt) == 1 else tuple(vt / norm)

    # ---- phases ---------------------------------------------------------------------------
    def start_phase(self, index: int, t: float, x: np.ndarray, previous: Phase | None) -> Phase:
        spec = self.scene.phases[index]
        controller = self.controllers[index]
        reference = carrier = None
        if spec.reference is not None:
            ref = spec.reference
            if ref.body != "ground":
                carrier = (self.body_index[ref.body], self.scene.bodies[ref.body].axis)
            if ref.start is not None:
                start = ref.start.copy()
            else:  # continue where the previous reference, or the tip, is (absolute), relative to the carrier
                if previous is not None and previous.reference is not None and \
                        previous.spec.reference is not None and previous.spec.reference.space == ref.space:
                    start = self.reference_at(previous, t, x)[0]
                else:
                    q = x[: self.nv]
                    start = self.robot.frame_position(q, self.tip_fid) if ref.space == "task" else q.copy()
                if carrier is not None:
                    start = start - carrier[1] * x[carrier[0]]
            dims = 3 if ref.space == "task" else self.nv
            if len(start) != dims:
                raise SceneError(f"phase[{index}].reference", f"{dims}-vectors in {ref.space} space",
                                 len(start), self.scene.file)
            moves = tuple(replace(m, start=m.start + t) for m in ref.moves)
            for m in moves:
                if len(m.delta) != dims:
                    raise SceneError(f"phase[{index}].reference.moves", f"{dims}-vectors", len(m.delta),
                                     self.scene.file)
            reference = Reference(start, moves)
        forces = {f.key: Ramp(f.ramp.value, f.ramp.start + t, f.ramp.duration, f.ramp.kind, f.ramp.initial)
                  for f in spec.forces}
        phase = Phase(spec, index, t, controller, self.z_slices[index], reference, forces, carrier,
                      previous.limits if previous is not None else ())
        return phase

    def reference_at(self, phase: Phase, t: float, x: np.ndarray):
        """The phase's reference (x_d, v_d, a_d) at (t, x), or Nones.

        A reference carried by a body adds the body's origin o = axis · Q_b and its velocity to
        x_d and v_d. Its acceleration axis · Q̈_b is an unknown of the linear system: ``evaluate``
        adds it to a_d there (folded, like measured forces), not here.
        """
        if phase.reference is None:
            return None, None, None
        x_d, v_d, a_d = phase.reference.at(t)
        if phase.carrier is not None:
            i, axis = phase.carrier
            x_d, v_d = x_d + axis * x[i], v_d + axis * x[self.nQ + i]
        return x_d, v_d, a_d

    # ---- kinematics ----------------------------------------------------------------------
    def kinematics(self, c: Contact, x: np.ndarray) -> Kinematics:
        """Contact kinematics at x; requires ``robot.update`` at x's (q, q̇) first."""
        ft = self.robot.frame_terms(c.fid)
        nQ = self.nQ
        if c.body_index >= 0:
            p_env = c.spec.point + c.body_axis * x[c.body_index]
            v_env = c.body_axis * x[nQ + c.body_index]
        else:
            p_env, v_env = c.spec.point, np.zeros(3)
        return Kinematics(ft.position, ft.velocity, ft.jacobian, ft.drift, p_env, v_env, ft)

    def _row(self, c: Contact, u: np.ndarray, kin: Kinematics) -> np.ndarray:
        """Generalized row of the relative tip–environment motion along u."""
        row = np.zeros(self.nQ)
        row[: self.nv] = u @ kin.J
        if c.body_index >= 0:
            row[c.body_index] -= u @ c.body_axis
        return row

    # ---- one chain ---------------------------------------------------------------------
    def _chain(self, c: Contact, dc: DirectionalChain, touching: bool, offset: float, kin: Kinematics,
               x: np.ndarray, f: np.ndarray, ydot: np.ndarray, ev: Evaluation | None, full: bool):
        """Apply a chain's stage forces; return (tip force along u [N], bond row or None, γ, interface F, gap)."""
        nQ, chain, u = self.nQ, dc.chain, dc.u
        plan = dc.plan(touching)
        nodes, stages = chain.nodes, chain.stages
        npos = len(nodes)
        pos = [0.0] * npos
        vel = [0.0] * npos
        s_tip, v_tip = float(u @ kin.p_tip), float(u @ kin.v_tip)
        s_anc, v_anc = float(u @ kin.p_env) + offset, float(u @ kin.v_env)
        for i in plan.solid:
            kind = nodes[i].kind
            if kind == NodeKind.TIP:
                pos[i], vel[i] = s_tip, v_tip
            elif kind == NodeKind.ANCHOR:
                pos[i], vel[i] = s_anc, v_anc
            else:
                pos[i], vel[i] = x[nodes[i].coord], x[nQ + nodes[i].coord]
        junction_nodes = {j for j, _, _, _ in plan.junctions}
        for a, b in plan.aliases:
            if b not in junction_nodes:
                pos[a], vel[a] = pos[b], vel[b]
        y = x[2 * nQ:]
        for j, active, slot, group in plan.junctions:
            num = den = kk = ks = 0.0
            for k in active:
                s = stages[k]
                if s.upper in group:  # stage below pushes j up
                    num += s.k * (pos[s.lower] - (y[slot] if slot >= 0 else 0.0)) + s.b * vel[s.lower]
                    ks += s.k * pos[s.lower]
                else:  # stage above pushes j down
                    num -= s.k * ((y[slot] if slot >= 0 else 0.0) - pos[s.upper]) - s.b * vel[s.upper]
                    ks += s.k * pos[s.upper]
                den += s.b
                kk += s.k
            if den > 0.0 and slot >= 0:
                pos[j], vel[j] = y[slot], num / den
                ydot[slot] = vel[j]
            else:  # undamped junction: algebraic force balance
                pos[j] = ks / kk if kk > 0 else 0.0
                vel[j] = sum(stages[k].k * vel[stages[k].lower if stages[k].upper in group else stages[k].upper]
                             for k in active) / kk if kk > 0 else 0.0
        for a, b in plan.aliases:
            if b in junction_nodes:
                pos[a], vel[a] = pos[b], vel[b]
        for a, b in plan.free_ends:
            pos[a], vel[a] = pos[b], vel[b]
        dc.last_positions = pos
        alias_of = dict(plan.aliases)
        tip_F = anchor_F = 0.0
        interface_F = 0.0
        for k in plan.active:
            s = stages[k]
            xs = pos[s.lower] - pos[s.upper]
            xd = vel[s.lower] - vel[s.upper]
            F = s.force(xs, xd)
            if k == plan.interface_stage:
                interface_F = F
            for node, sign in ((s.upper, 1.0), (s.lower, -1.0)):
                target = alias_of.get(node, node)
                kind = nodes[target].kind
                if kind == NodeKind.TIP:
                    tip_F += sign * F
                elif kind == NodeKind.ANCHOR:
                    anchor_F += sign * F
                elif kind == NodeKind.MASS:
                    f[nodes[target].coord] += sign * F
            if self.energy_slot >= 0:
                ydot[self.energy_slot + 1] += (F - s.force(xs, 0.0)) * xd  # damper power [W]
            if full and ev is not None:
                ev.stages[f"{c.name}.{dc.label}.{s.label}"] = (xs, xd, F)
        if full and ev is not None:
            for k in range(len(stages)):
                label = f"{c.name}.{dc.label}.{stages[k].label}"
                if label not in ev.stages:
                    ev.stages[label] = (0.0, 0.0, 0.0)
        if c.body_index >= 0 and anchor_F != 0.0:
            f[c.body_index] += anchor_F * float(u @ c.body_axis)
        row = None
        gamma = 0.0
        if plan.bond:
            row = np.zeros(nQ)
            for node, sign in ((chain.robot_surface, 1.0), (chain.env_surface, -1.0)):
                kind = nodes[node].kind
                if kind == NodeKind.TIP:
                    row[: self.nv] += sign * (u @ kin.J)
                    gamma += sign * float(u @ kin.drift)
                elif kind == NodeKind.ANCHOR:
                    if c.body_index >= 0:
                        row[c.body_index] += sign * float(u @ c.body_axis)
                else:
                    row[nodes[node].coord] += sign
        gap = pos[chain.robot_surface] - pos[chain.env_surface]
        if plan.bond:  # Baumgarte: the violation e obeys ë + 2ω ė + ω² e = 0, zero on the exact manifold
            w = self.stabilization
            gamma += 2.0 * w * (vel[chain.robot_surface] - vel[chain.env_surface]) + w * w * gap
        return tip_F, row, gamma, interface_F, (0.0 if touching else gap)

    # ---- the right-hand side -----------------------------------------------------------
    def evaluate(self, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase,
                 full: bool = False) -> Evaluation:
        nQ, nv = self.nQ, self.nv
        q, v = x[:nv], x[nQ:nQ + nv]
        robot = self.robot
        if any(m.from_rest and len(m.slip) == 2 for m in modes):
            modes = self._launch_directions(t, x, modes, phase)
        robot.update(q, v)
        f = np.zeros(nQ)
        f[:nv] = -robot.h
        ydot = np.zeros(self.ny)
        rows: list[np.ndarray] = []
        cols: list[np.ndarray] = []
        gammas: list[float] = []
        meta: list[tuple[str, str, int]] = []
        ev = Evaluation(np.empty(0), np.empty(0), meta, {}, {}, {}, {}, {}, {}, np.empty(0), np.empty(0),
                        np.empty(0), None, {})
        kins: list[Kinematics] = []
        pending_friction: list[tuple[Contact, np.ndarray, float, np.ndarray]] = []
        for c, mode in zip(self.contacts, modes, strict=True):
            kin = self.kinematics(c, x)
            kins.append(kin)
            tip_force = np.zeros(3)
            # normal
            tip_F, row, gamma, F_n, gap = self._chain(c, c.normal, mode.touching, 0.0, kin, x, f, ydot, ev, full)
            tip_force += tip_F * c.normal.u
            ev.gap[c.name] = gap
            # tangential chains (bonded while the normal touches)
            for i, dc in enumerate(c.tangent_chains):
                tF, trow, tgamma, tint, _ = self._chain(c, dc, mode.touching, mode.offsets[i], kin, x, f, ydot, ev,
                                                        full)
                tip_force += tF * dc.u
                ev.interface[f"{c.name}.{dc.label}"] = tint
                if trow is not None:
                    rows.append(trow)
                    cols.append(trow)
                    gammas.append(tgamma)
                    meta.append((c.name, dc.label, i))
            # friction
            col = row
            if c.friction is not None and len(c.tangents):
                T = c.tangents
                vt = self.slip_velocity(c, kin)
                ev.slip[c.name] = vt
                if mode.touching:
                    R_T = np.zeros((len(T), nQ))  # generalized rows of the tangential slip
                    R_T[:, :nv] = T @ kin.J
                    if c.body_index >= 0:
                        R_T[:, c.body_index] -= T @ c.body_axis
                if mode.touching and mode.stuck:
                    for i in range(len(T)):
                        rows.append(R_T[i])
                        cols.append(R_T[i])
                        gammas.append(float(T[i] @ kin.drift) + self.stabilization * float(vt[i]))
                        meta.append((c.name, "t", i))
                elif mode.touching:
                    fr = c.friction
                    d = self._slip_direction(vt, mode)
                    visc = -fr.viscous * vt if fr.viscous else np.zeros(len(T))
                    if row is not None:  # normal force is an unknown: tilt its column by −μ_k d
                        col = row - fr.mu_k * (d @ R_T)
                        pending_friction.append((c, d, 0.0, visc))
                        if fr.viscous:
                            f += visc @ R_T
                    else:
                        ff = -fr.mu_k * max(F_n, 0.0) * d + visc
                        pending_friction.append((c, d, F_n, visc))
                        ev.friction[c.name] = ff
                        f += ff @ R_T
                    if self.energy_slot >= 0:
                        ydot[self.energy_slot + 1] += float(fr.viscous * vt @ vt)
                else:
                    ev.friction[c.name] = np.zeros(len(T))
            if row is not None:
                rows.append(row)
                cols.append(col)
                gammas.append(gamma)
                meta.append((c.name, "n", 0))
            ev.normal_force[c.name] = F_n
            if np.any(tip_force):
                f[:nv] += kin.J.T @ tip_force
        if phase.limits:  # joints pressing on a position limit (contactdyn.limits)
            l_rows, l_gammas, l_meta = self.limits.rows(phase.limits, x, nQ, self.stabilization)
            rows += l_rows
            cols += l_rows
            gammas += l_gammas
            meta += l_meta
        # controller
        ft = next((k.frame for c, k in zip(self.contacts, kins, strict=True) if c.fid == self.tip_fid), None)
        if ft is None:
            ft = robot.frame_terms(self.tip_fid)
        p_tip, v_tip, J, drift = ft.position, ft.velocity, ft.jacobian, ft.drift
        x_d, v_d, a_d = self.reference_at(phase, t, x)
        force_d = {name: ramp.at(t) for name, ramp in phase.forces.items()}
        ctl = phase.controller
        z = x[2 * nQ + phase.z_slice.start: 2 * nQ + phase.z_slice.stop]
        drives = self.drives
        inp = ControlInput(t, q, v, robot.H + np.diag(self._D_ctl) if drives.any_motor else robot.H, robot.h,
                           robot.gravity_torque(q) if ctl.needs_gravity else None,
                           p_tip, v_tip, J, drift, x_d, v_d, a_d, {**ev.normal_force, **ev.interface}, force_d,
                           self.force_directions, z, R_tip=ft.rotation, J_ang=ft.angular_jacobian)
        if ctl.uses_forces:
            inp.tau_contact = f[:nv] + robot.h
            inp.surfaces = {c.name: (k.p_env, k.v_env) for c, k in zip(self.contacts, kins, strict=True)}
            for c, k, m in zip(self.contacts, kins, modes, strict=True):  # tangential chains: their anchors
                for i, dc in enumerate(c.tangent_chains):
                    inp.surfaces[f"{c.name}.{dc.label}"] = (k.p_env + dc.u * m.offsets[i], k.v_env)
            inp.touching = {c.name: m.touching for c, m in zip(self.contacts, modes, strict=True)}
        tau, zdot = ctl.command(inp)
        carried = None  # a reference on a body: the command's part proportional to the body's acceleration
        if phase.carrier is not None and x_d is not None:
            i_b, axis = phase.carrier
            tau_b, zdot_b = ctl.command(replace(inp, a_d=a_d + axis))
            if np.any(tau_b != tau):
                carried = (i_b, tau_b - tau, None if zdot is None else zdot_b - zdot)
        cmd = np.zeros(len(drives.specs))  # per drive: joints, then bodies
        cmd[:nv] = tau
        for idx, v_ref, gain in self.servo:
            cmd[idx] = gain * (v_ref - x[nQ + idx])  # body coordinate idx = drive idx
        vmask = self._joint_motors if ctl.outputs == "voltage" else None
        # drives, folded measured forces, solve
        if (ctl.uses_forces and rows) or carried is not None:
            out, qdd, lam, regular, cmd, zdot = self._solve_folded(inp, ctl, cmd, zdot, f, rows, cols, gammas,
                                                                    meta, x, vmask, carried)
        else:
            out = drives.apply(cmd, x, nQ, f, voltage=vmask)
            qdd, lam, regular = self._solve(f, rows, cols, gammas, None)
        if zdot is not None:
            ydot[phase.z_slice] = zdot
        if self.energy_slot >= 0:
            ydot[self.energy_slot] = out.power
            ydot[self.energy_slot + 1] += out.dissipation
        xdot = np.concatenate([x[nQ:2 * nQ], qdd, ydot])
        ev.xdot, ev.lam, ev.tau, ev.body_force, ev.p_tip, ev.x_d = xdot, lam, out.applied[:nv], out.applied[nv:], \
            p_tip, x_d
        ev.tau_cmd, ev.u = cmd[:nv], out.u
        ev.force_d = {k: val[0] for k, val in force_d.items()}
        ev.regular = regular
        for (name, kind, i), value in zip(meta, lam, strict=True):
            if kind == "n":
                ev.normal_force[name] = float(value)
            elif kind == "t":
                ev.friction.setdefault(name, np.zeros(len(self._contact(name).tangents)))[i] = value
            elif kind == "limit":
                ev.limit_torque[i] = float(value)
            else:
                ev.interface[f"{name}.{kind}"] = float(value)
        for c, d, _, visc in pending_friction:
            if c.name not in ev.friction:
                ev.friction[c.name] = -c.friction.mu_k * max(ev.normal_force[c.name], 0.0) * d + visc
        if self.energy_slot >= 0:
            for c, d, _, _ in pending_friction:
                ydot[self.energy_slot + 1] += float(c.friction.mu_k * max(ev.normal_force[c.name], 0.0)
                                                    * (d @ ev.slip[c.name]))
            xdot[2 * nQ + self.energy_slot + 1] = ydot[self.energy_slot + 1]
        for name, slot in self.impulse_slots.items():
            if name in ev.friction:
                i0 = 2 * nQ + slot
                xdot[i0] = ev.normal_force[name]
                xdot[i0 + 1: i0 + 1 + len(ev.friction[name])] = ev.friction[name]
        return ev

    def _solve(self, f: np.ndarray, rows: list, cols: list, gammas: list, fold: np.ndarray | None,
               fold_q: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, bool]:
        """Q̈ and the row forces λ of [[M − fold_q, −Cᵀ − fold], [G, 0]] [Q̈; λ] = [f; −γ]."""
        nQ, nv = self.nQ, self.nv
        M = self._M
        M[:nv, :nv] = self.robot.H + np.diag(self._D) if self.drives.any_motor else self.robot.H
        if rows or fold_q is not None:
            nr = len(rows)
            A = np.zeros((nQ + nr, nQ + nr))
            A[:nQ, :nQ] = M if fold_q is None else M - fold_q
            if nr:
                A[:nQ, nQ:] = -np.array(cols).T
                if fold is not None:
                    A[:nQ, nQ:] -= fold
                A[nQ:, :nQ] = np.array(rows)
            b = np.concatenate([f, -np.asarray(gammas, float)])
            z_all, regular = solve_linear(A, b)
            return z_all[:nQ], z_all[nQ:], regular
        qdd = np.empty(nQ)
        qdd[:nv], regular = solve_linear(M[:nv, :nv], f[:nv])
        qdd[nv:] = f[nv:] / self.M_rest if nQ > nv else f[nv:]
        return qdd, np.empty(0), regular

    def _solve_folded(self, inp: ControlInput, ctl: Controller, cmd: np.ndarray, zdot, f: np.ndarray, rows, cols,
                      gammas, meta, x: np.ndarray, vmask, carried=None):
        """Solve with a force-reading controller whose measured forces include unknown row forces λ.

        The controller is probed with a unit force on each row (its generalized column on the
        joints, and +1 N on the contact's normal force for a normal row): B_j = τ(e_j) − τ₀.
        B folds into the matrix for drives whose voltage does not clip; a clipped drive gives
        a force independent of λ. The clipping pattern is re-checked with the solved λ.
        A row whose force acts on the robot alone (rigid contact or stick on the fixed ground)
        stays out of the measured joint force: cancelling it would leave it undetermined.

        ``carried = (i_b, b, d)``: a reference carried by body coordinate i_b makes the command
        affine in that body's acceleration too, τ += b Q̈_b, ż += d Q̈_b; b folds into the matrix's
        column i_b the same way (the reference's acceleration is then exact, not lagged).
        """
        nQ, nv, drives = self.nQ, self.nv, self.drives
        nr = len(rows)
        B = np.zeros((nv, nr))
        Dz = np.zeros((len(zdot), nr)) if zdot is not None else None
        for j, (name, kind, _) in enumerate(meta):
            if not ctl.uses_forces:
                break
            fed_back = bool(np.any(cols[j][nv:]))
            if kind != "n" and not fed_back:
                continue
            forces = inp.forces if kind != "n" else {**inp.forces, name: inp.forces[name] + 1.0}
            tau_c = inp.tau_contact + cols[j][:nv] if fed_back else inp.tau_contact
            tau_j, zdot_j = ctl.command(replace(inp, forces=forces, tau_contact=tau_c))
            B[:, j] = tau_j - cmd[:nv]
            if Dz is not None:
                Dz[:, j] = zdot_j - zdot
        sat_cmd = cmd
        full = cmd.copy()
        for _ in range(nv + 2):
            fk = f.copy()
            out = drives.apply(cmd, x, nQ, fk, voltage=vmask, sat_cmd=sat_cmd)
            fold = np.zeros((nQ, nr))
            fold_q = np.zeros((nQ, nQ)) if carried is not None else None
            for i in range(nv):
                if not out.saturated[i]:
                    fold[drives.targets[i]] += drives.gains[i] * B[i]
                    if carried is not None:
                        fold_q[drives.targets[i], carried[0]] += drives.gains[i] * carried[1][i]
            qdd, lam, regular = self._solve(fk, rows, cols, gammas, fold, fold_q)
            full = cmd.copy()
            full[:nv] += B @ lam
            if carried is not None:
                full[:nv] += carried[1] * qdd[carried[0]]
            check = drives.apply(full, x, nQ, np.zeros(nQ), voltage=vmask)
            if np.array_equal(check.saturated, out.saturated):
                break
            sat_cmd = full
        f[:] = fk
        if Dz is not None:
            zdot = zdot + Dz @ lam
            if carried is not None and carried[2] is not None:
                zdot = zdot + carried[2] * qdd[carried[0]]
        return check, qdd, lam, regular, full, zdot

    def separate(self, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase, contact: Contact
                 ) -> np.ndarray:
        """State at separation: damped surface ends start relaxing from where they are (modes: still touching)."""
        self.evaluate(t, x, modes, phase)
        x = x.copy()
        for dc in contact.chains:
            chain = dc.chain
            for node_i in (chain.env_surface, chain.robot_surface):
                slot = chain.nodes[node_i].state
                if chain.nodes[node_i].kind == NodeKind.FREE and slot >= 0:
                    x[2 * self.nQ + slot] = dc.last_positions[node_i]
        return x

    def _contact(self, name: str) -> Contact:
        return next(c for c in self.contacts if c.name == name)

    def _slip_direction(self, vt: np.ndarray, mode: ContactMode) -> np.ndarray:
        """Unit sliding direction d in tangent coordinates (1-D: ±1).

        The slip velocity's own direction v_t/|v_t| (eqs 21–24; 1-D: sgn, eqs 43–44)
        while it points ahead of the mode's reference r (v_t·r > v_ε, the stick band);
        otherwise r itself. The segment ends at a ``stop`` event where v_t·r falls to v_ε,
        and 2-D ``turn`` events keep r within 60° of v_t, so the second branch only serves
        a slip just started from rest (|v_t| ≤ v_ε) and the integrator's trial stages past
        a stop: the force stays continuous across the stop instead of flipping there,
        which would make the step size collapse. Never a smoothed sgn.
        """
        r = np.asarray(mode.slip, float)
        if float(vt @ r) > self.slip_band:
            return r if len(vt) == 1 else vt / math.sqrt(float(vt @ vt))
        return r

    def slip_acceleration(self, c: Contact, x: np.ndarray, xdot: np.ndarray) -> np.ndarray:
        """Tangential tip–environment acceleration [m/s²] in tangent coordinates at (x, ẋ)."""
        nQ, nv = self.nQ, self.nv
        self.robot.update(x[:nv], x[nQ:nQ + nv])
        kin = self.kinematics(c, x)
        qdd = xdot[nQ:2 * nQ]
        a_env = c.body_axis * qdd[c.body_index] if c.body_index >= 0 else np.zeros(3)
        return c.tangents @ (kin.J @ qdd[:nv] + kin.drift - a_env)

    def _launch_directions(self, t: float, x: np.ndarray, modes: list[ContactMode], phase: Phase
                           ) -> list[ContactMode]:
        """Modes whose 2-D slides from rest, still inside the stick band, slide the consistent way.

        A slip from rest starts where it accelerates: d with a_t(d) = λ d, λ ≥ 0, a_t the
        tangential acceleration when friction is −μ_k F d. With an anisotropic arm (tangential
        mobility differing by direction) this is not the direction of the holding force, and
        a slide that started along that one would swing round at |v_t| ≈ v_ε, where the
        direction dynamics are stiff (rate ∝ 1/|v_t|). Newton on the angle (at most 4
        iterations, two evaluations each); the reference r if it does not converge.
        """
        nQ, nv = self.nQ, self.nv
        self.robot.update(x[:nv], x[nQ:nQ + nv])
        out = list(modes)
        for i, (c, mode) in enumerate(zip(self.contacts, modes, strict=True)):
            if not (mode.from_rest and len(mode.slip) == 2 and mode.touching and not mode.stuck):
                continue
            r = np.asarray(mode.slip, float)
            if float(self.slip_velocity(c, self.kinematics(c, x)) @ r) > self.slip_band:
                out[i] = mode.with_(from_rest=False)  # launched: the slip's own direction from here on
                continue
            theta = float(np.arctan2(r[1], r[0]))
            best = r
            for _ in range(4):
                phi, d, ahead = self._launch_cross(t, x, out, i, phase, theta)
                if ahead >= 0.0 and abs(phi) <= 1e-9 * (abs(ahead) + abs(phi)):
                    best = d
                    break
                dphi = (self._launch_cross(t, x, out, i, phase, theta + 1e-7)[0] - phi) / 1e-7
                if not dphi < 0.0:  # a stable direction turns the acceleration back onto d
                    break
                theta -= float(np.clip(phi / dphi, -0.5, 0.5))
            out[i] = mode.with_(slip=tuple(best), from_rest=False)
        self.robot.update(x[:nv], x[nQ:nQ + nv])
        return out

    def _launch_cross(self, t: float, x: np.ndarray, modes: list[ContactMode], i: int, phase: Phase,
                      theta: float) -> tuple[float, np.ndarray, float]:
        """Sliding contact i along d = (cos θ, sin θ): (d × a_t, d, a_t · d) [m/s²]."""
        c = self.contacts[i]
        d = np.array([np.cos(theta), np.sin(theta)])
        trial = list(modes)
        trial[i] = modes[i].with_(slip=tuple(d), from_rest=False)
        a = self.slip_acceleration(c, x, self.evaluate(t, x, trial, phase).xdot)
        return float(d[0] * a[1] - d[1] * a[0]), d, float(a @ d)

    def slip_velocity(self, c: Contact, kin: Kinematics, qd: np.ndarray | None = None) -> np.ndarray:
        """Tangential tip–environment velocity [m/s] in tangent coordinates (at Q̇ = qd if given)."""
        if qd is None:
            return c.tangents @ (kin.v_tip - kin.v_env)
        v_env = c.body_axis * qd[c.body_index] if c.body_index >= 0 else np.zeros(3)
        return c.tangents @ (kin.J @ qd[: self.nv] - v_env)

    def rhs(self, modes: list[ContactMode], phase: Phase):
        """The function solve_ivp integrates in one mode and phase."""

        def f(t: float, x: np.ndarray) -> np.ndarray:
            return self.evaluate(t, x, modes, phase).xdot

        return f

    # ---- plastic impact ----------------------------------------------------------------
    def impact(self, t: float, x: np.ndarray, modes: list[ContactMode], contact: Contact,
               limits: tuple = ()) -> tuple[np.ndarray, Impact]:
        """Velocity jump when ``contact`` touches (its mode already says touching).

        Momentum law over Δt → 0 (eqs 27–31, 35–38): M(Q̇⁺ − Q̇⁻) = Cᵀ Λ with every bond,
        stick and the new contact holding at velocity level, G Q̇⁺ = 0. With friction the
        tip first slides in its pre-impact slip direction d (friction impulse −μ_k FΔt d,
        the normal column tilted as in eq. 27). If the tangential velocity after the
        impact points against d the assumption is wrong and the impact jams (eqs 30–31):
        zero tangential velocity, friction impulse F_fΔt an unknown. A tip that arrives
        without slip (|v_t| within the stick band) is tried jammed first; if holding it
        needs more than μ_s FΔt it slides where that impulse pushes.
        """
        nQ, nv = self.nQ, self.nv
        q, v = x[:nv], x[nQ:nQ + nv]
        self.robot.update(q, v)
        qd_minus = x[nQ:2 * nQ].copy()
        M = self.mass_matrix()
        i_c = self.contacts.index(contact)
        kin = self.kinematics(contact, x)
        fr, k = contact.friction, len(contact.tangents)
        vt_minus = self.slip_velocity(contact, kin, qd_minus) if k else np.zeros(0)

        def solve(slide=None, jam=False):
            rows, cols, meta = self._velocity_rows(x, modes, slide=(contact, slide) if slide is not None else None,
                                                   jam=contact if jam else None, limits=limits)
            z, _ = self._impact_solve(M, rows, cols, qd_minus)
            lam = {m: z[nQ + j] for j, m in enumerate(meta)}
            P_n = float(lam[(contact.name, "n", 0)])
            P_t = np.array([lam.get((contact.name, "t", i), 0.0) for i in range(k)])
            return z[:nQ], P_n, P_t

        jammed = False
        d = np.zeros(k)
        if fr is None or not k or modes[i_c].stuck:
            qd_plus, P_n, P_t = solve()
        else:
            speed = float(np.linalg.norm(vt_minus))
            if speed > self.slip_band:
                d = vt_minus / speed
                qd_plus, P_n, _ = solve(slide=d)
                P_t = -fr.mu_k * P_n * d
                jammed = float(self.slip_velocity(contact, kin, qd_plus) @ d) < 0.0
            else:
                jammed = True
            if jammed:
                qd_plus, P_n, P_t = solve(jam=True)
                if float(np.linalg.norm(P_t)) > fr.mu_s * P_n * (1.0 + CONE_TOL) + FORCE_ABS_TOL:
                    # holding needs more than the cone gives: slide where the impulse pushes
                    d = -P_t / float(np.linalg.norm(P_t))
                    qd_plus, P_n, _ = solve(slide=d)
                    P_t = -fr.mu_k * P_n * d
                    jammed = False
        x_new = x.copy()
        x_new[nQ:2 * nQ] = qd_plus
        energy_loss = 0.5 * float(qd_minus @ M @ qd_minus - qd_plus @ M @ qd_plus)
        vt_plus = self.slip_velocity(contact, kin, qd_plus) if k else np.zeros(0)
        return x_new, Impact(t, contact.name, P_n, P_t, jammed, energy_loss, qd_minus, qd_plus, vt_minus, vt_plus, d)

    def mass_matrix(self) -> np.ndarray:
        """M at the last ``robot.update``, a copy: H plus rigid gears' rotor inertias, then the other coordinates."""
        M = self._M.copy()
        M[:self.nv, :self.nv] = self.robot.H + np.diag(self._D)
        return M

    def project_velocity(self, x: np.ndarray, modes: list[ContactMode], limits: tuple = ()) -> np.ndarray:
        """x with Q̇ moved onto every active velocity constraint (bonds, rigid contacts, sticks).

        The smallest change in the kinetic-energy norm, M ΔQ̇ = Gᵀ Λ, G Q̇⁺ = 0: an impulse
        that removes what the constraints forbid (used when a slide stops inside the stick
        band, where the residual slip is at most ``solver.stick_velocity``).
        """
        nQ, nv = self.nQ, self.nv
        self.robot.update(x[:nv], x[nQ:nQ + nv])
        rows, cols, _ = self._velocity_rows(x, modes, limits=limits)
        if not rows:
            return x
        M = self.mass_matrix()
        z, _ = self._impact_solve(M, rows, cols, x[nQ:2 * nQ])
        x_new = x.copy()
        x_new[nQ:2 * nQ] = z[:nQ]
        return x_new

    def _velocity_rows(self, x, modes, slide: tuple[Contact, np.ndarray] | None = None, jam: Contact | None = None,
                       limits: tuple = ()):
        """Velocity constraints of the touching contacts (bond rows, sticks, tangential chain bonds) and
        of the joints pressing on ``limits`` (see contactdyn.limits).

        ``slide = (contact, d)`` tilts that contact's normal column by the sliding friction
        −μ_k d; ``jam`` adds stick rows for a contact that is not (yet) stuck.
        """
        rows, cols, meta = [], [], []
        dummy_f, dummy_y = np.zeros(self.nQ), np.zeros(self.ny)
        for c, mode in zip(self.contacts, modes, strict=True):
            if not mode.touching:
                continue
            kin = self.kinematics(c, x)
            _, row, _, _, _ = self._chain(c, c.normal, True, 0.0, kin, x, dummy_f, dummy_y, None, False)
            if row is not None:
                col = row
                if slide is not None and slide[0] is c:
                    d = slide[1]
                    col = row - sum(c.friction.mu_k * d[i] * self._row(c, c.tangents[i], kin)
                                    for i in range(len(c.tangents)))
                rows.append(row)
                cols.append(col)
                meta.append((c.name, "n", 0))
            if c.friction is not None and len(c.tangents) and (mode.stuck or jam is c):
                for i, t_dir in enumerate(c.tangents):
                    r = self._row(c, t_dir, kin)
                    rows.append(r)
                    cols.append(r)
                    meta.append((c.name, "t", i))
            for i, dc in enumerate(c.tangent_chains):
                _, trow, _, _, _ = self._chain(c, dc, True, mode.offsets[i], kin, x, dummy_f, dummy_y, None, False)
                if trow is not None:
                    rows.append(trow)
                    cols.append(trow)
                    meta.append((c.name, dc.label, i))
        l_rows, _, l_meta = self.limits.rows(limits, x, self.nQ, 0.0)
        return rows + l_rows, cols + l_rows, meta + l_meta

    def _impact_solve(self, M, rows, cols, qd_minus):
        nQ, nr = self.nQ, len(rows)
        A = np.zeros((nQ + nr, nQ + nr))
        A[:nQ, :nQ] = M
        A[:nQ, nQ:] = -np.array(cols).T
        A[nQ:, :nQ] = np.array(rows)
        b = np.concatenate([M @ qd_minus, np.zeros(nr)])
        z, regular = solve_linear(A, b)
        if not np.all(np.isfinite(z)):
            raise SimulationError("impact map: the momentum-law system has no finite solution")
        return z, regular
