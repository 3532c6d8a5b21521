"""A mode packed for the pipeline: every table one right-hand-side call reads, as flat arrays (once per mode).

:func:`pack` (Python) lays out one (modes, phase) of a system as

- ``ints`` (int64): a header (the sizes and where each section starts, the slots named below), then the sections:
  frames, contacts, chains (each chain's own plan, :func:`contactdyn.model.chain_forces.pack`, copied in), pressing
  limits, stuck and sliding joints, launching contacts, servos, the controller's layout table (the controller
  ABI's, :mod:`contactdyn.laws.controllers.abi`), the drive table (:mod:`.drives`: per drive its coordinates and its
  kind's addresses);
- ``reals`` (float64): Baumgarte's ω [1/s] and the stick band [m/s], then the rigid-body table
  (:mod:`contactdyn.robot.rigid_body`), the frames' placements in their joints, the non-robot inertias [kg],
  the contacts' points, axes, tangents, slip references and friction coefficients, the chains' coefficients and
  law parameters, the limits [rad or m], the joints' damping and sliding friction, the servos, the reference, its
  moves and circles, the body carrying it, the force ramps, the controller's constants or declared parameters, per
  drive its voltage limit [V] and its kind's values, the rotors reflected on the joints [kg·m²];
- ``work`` (float64): the chains' node motion and stage states, the drives' outputs of the last call (scratch the
  call writes), then the diagnostics section (:func:`diag_starts`: what the output samples read, written when its
  switch is on).

A law enters by its address (an int64 of ``ints``: a stage law's in its chain's stage table, a friction law's in
its contact's row, a user controller's in the controller section, a drive kind's in its drive's row), so one
compiled call serves every law. The index constants below are the one place the layout is written; the call
(:mod:`.pipeline`) reads nothing else.

What the pipeline does not pack (:func:`unsupported` names it, and the run stops with it): a robot
or articulated body ``rigid_body`` does not compute (none the robot loader accepts: every joint it takes is a one-DOF
revolute or prismatic), an articulated body under another gravity than the robot's. A stage law, friction law,
drive kind or user controller numba cannot compile is packed as a declared Python stage (:func:`python_stages` names
them): the address of a ctypes callback of its Python function where its cfunc's would be
(:func:`contactdyn.laws.abi.python_stage_address`, :func:`contactdyn.laws.drive_abi.python_drive_addresses`,
:func:`contactdyn.laws.controllers.abi.python_controller_address`: the controller's own ``command`` on a
ControlInput rebuilt from its buffer, whose "keys" field (I_KEYS) holds what the
dictionaries need). A
chain's mass riding a turning surface is packed with its frame (``N_RIDING``): the call adds its coupling to M and
its bias to f (:func:`.contacts.add_riding`). A force-reading law over a turning surface (a robot frame's or an
articulated body's) folds as over a fixed one: the surface's rows are the state's (:func:`.contacts.turning_sides`),
and those that reach a body's coordinates enter the measured τ_c the fold probes (:mod:`.force_fold`). Several 2-D
slides launching from rest at once nest their Newtons (:mod:`.launch`).
An articulated body's joints are appended to the robot's in the rigid-body table
(:func:`contactdyn.robot.rigid_body.forest_table`, ``NF`` its columns), a frame or a point of it a packed frame as a
robot frame is; a free body's chart-B rows and frame placements are packed too (``N_CHARTS``), the call taking the
chart x holds (:func:`.robot_terms.table_at`). The controllers compiled in as kinds (``COMPILED_IN``: task PD,
operational space, the dynamic laws (A7 in task or joint space), joint PD, task force), a sampled law's held command
(torques or voltages), constant voltages and user laws of the controller ABI (their command torques or voltages
[V], a task or a joint-space reference) run; a force-reading law (its set-points along a contact's normal or a
tangential chain's direction) and a reference carried by a body (along the axis of its first coordinate, a
translating body's or an articulated body's, as ``phases.reference_at``) are folded through the drives
(:mod:`.force_fold`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...laws.abi import friction_address, python_friction_address, python_stage_address
from ...laws.controllers.abi import InputKeys, controller_address, layout_of, params_of, python_controller_address
from ...laws.controllers.sampled import SampledController
from ...laws.controllers.voltage import ConstantVoltage
from ...laws.friction_laws import FRICTION_LAWS
from ...laws.trajectory import CIRCLE_W, move_table, ramp_table
from ...numerics.compile_cache import njit
from ...numerics.native_call import handles
from ...robot.rigid_body import forest_table
from ..chain import NodeKind
from ..chain_forces import S_LAW
from ..chain_forces import pack as pack_chain
from ..evaluation import surface_keys
from ..friction import launching
from .control_laws import JOINT_DYNAMIC, kind_address
from .drives import DW_W, drive_table, python_drives

__all__ = ["Packed", "pack", "unsupported", "python_stages", "python_controller", "section", "diag_starts",
           "set_slip_references"]

# ---- the header of ``ints``: sizes, switches, then where each section starts -------------------------------------
(NV, NQ, NY, NX, N_DRIVES, N_FRAMES, N_CONTACTS, N_CHAINS, N_ROWS, N_LIMITS, N_SERVOS, TIP_FRAME, CTL_KIND,
 FEEDFORWARD, READS_ORIENTATION, NEEDS_GRAVITY, N_AXES, N_FORCES, N_MOVES, REF_DIMS, HAS_TOOL, HAS_RD, NJ,
 I_FRAMES, I_CONTACTS, I_CHAINS, I_LIMITS, I_SERVOS, I_LAYOUT, R_RIGID, R_FRAMES, R_MREST, R_LIMITS, R_SERVOS,
 R_REF, R_RAMPS, R_CTL, N_CTL_PARAMS, CTL_ADDRESS, W_SIZE, I_DRIVES, R_DRIVES, R_REFLECTED, W_DRIVES, ANY_MOTOR,
 W_DIAG, JOINT_FRICTION, N_HELD, N_SLIDING, I_JOINTS, R_JOINTS, X_HELD, CARRIER, R_CARRIER, R_CIRCLES,
 N_LAUNCH, I_LAUNCH, ENERGY, N_Z, Z_AT, READS_FORCES, I_FOLD, R_FOLD, A_CALL, A_CONTROLLER, A_SOLVE,
 A_LAUNCH_START, A_LAUNCH, A_LAUNCH_SETTLED, A_ENERGY, R_WEIGHTS, NF, N_CHARTS, I_CHARTS, R_FRAMES_B,
 N_RIDING, I_RIDING, R_RIDING, W_LEAST_SQUARES, I_KEYS, R_KEYS, A_SPLIT, W_SPLITS, HEADER) = range(84)
#: the controller's states (N_Z of them from y's slot Z_AT), whether it reads measured forces (folded), and where
#: I_FOLD's section starts: per set-point the contact whose normal force it reads (-1: a tangential chain's), then
#: per KKT row the contact whose normal it is (-1: another kind of row), as the fold probes them, then per set-point
#: the chain whose interface force it reads (-1: a normal set-point's, the contact's normal force) and its contact;
#: R_FOLD: per set-point the shift of its surface point from the contact's [m] (a tangential chain's anchor, u·offset)
#: A_*: the addresses of the call and of its stages compiled on their own (:func:`.pipeline.stage_addresses`, filled
#: by ``Pipeline``): the call itself, the controller's kind, the solve (direct or through a fold), a launch's start
#: and Newton, the energy audit, the split of redundant holds (A_SPLIT; 0 where the mode has none)
#: NF: the rigid-body table's columns (the robot's nv, then through the last articulated body's coordinates: H, h
#: and the frames' J span Q[:NF]; :func:`contactdyn.robot.rigid_body.forest_table`)
#: N_CHARTS: the free bodies (two charts each, :mod:`contactdyn.robot.free_chart`), I_CHARTS their rows (CHT_*
#: below), R_FRAMES_B the packed frames' placements in chart B (N_FRAMES rows of FR_W; only with a free body)
#: N_RIDING: the chain masses riding turning surfaces (``contact.RidingMass``), I_RIDING their ints (RI_*), R_RIDING
#: their reals (RR_*)
#: W_LEAST_SQUARES: the slot of ``work`` counting the calls whose KKT matrix was singular (solved by the minimum-norm
#: least squares, :func:`.kkt.solve_linear`: an Evaluation's ``regular`` False) since the packing; W_SPLITS: the slot
#: counting those whose redundant holds were split by their limits (:func:`.kkt.coulomb_split`)
#: I_KEYS: per key of the readable ControlInput's dictionaries (``evaluation.surface_keys``: per contact, then its
#: tangential chains) its contact and its chain (-1: the contact's normal); R_KEYS: per key the shift of its surface
#: point from the contact's [m] (u·offset: a tangential chain's anchor). A declared Python stage's "keys" field
#: (:func:`.force_fold.key_fields`)
#: ``reals``' first slots
RH_OMEGA, RH_SLIP_BAND, RH_SIZE = 0, 1, 2
#: controller kinds: none (τ = 0), the task PD law compiled in, a controller called by its address (its ABI)
#: (operational space and the dynamic laws by their address, as a user's law: control_laws.kind_address), a
#: sampled law's held command (τ = the state's held slots from x[X_HELD], laws.controllers.sampled), a constant
#: command per joint (open-loop voltages [V], ConstantVoltage, in the controller's reals), joint PD, task force
CTL_NONE, CTL_TASK_PD, CTL_ABI, CTL_HELD, CTL_CONSTANT, CTL_JOINT_PD, CTL_TASK_FORCE = 0, 1, 2, 3, 4, 5, 6
FF_NONE, FF_GRAVITY, FF_BIAS = 0, 1, 2  #: task PD's feedforward (joint PD's and task force's: their first constant)
FEEDFORWARDS = {"none": FF_NONE, "gravity": FF_GRAVITY, "bias": FF_BIAS}  #: a config's ``feedforward`` -> its code
#: a frame's ints: its joint (its row in the rigid-body table), the count and start (in ``ints``) of the velocity
#: columns (indices in Q) that move it, the slot in x of its free body's chart (-1: a frame of no free body; in
#: chart B its placement is R_FRAMES_B's row)
FI_JOINT, FI_N_SUPPORT, FI_SUPPORT, FI_CHART, FI_W = 0, 1, 2, 3, 4
#: a free body's ints: the slot in x of its chart (0: A, 1: B, as ``ArticulatedBody.chart_of`` reads it), its
#: joints' first row in the rigid-body table and their count, where its chart-B rows start in reals (the same rows
#: of its model turned by free_chart.C: ``free_chart.turned_model``)
CHT_SLOT, CHT_ROW, CHT_N, CHT_REALS, CHT_W = 0, 1, 2, 3, 4
FR_W = 12  #: a frame's reals: its placement in its joint's frame, r (3) [m] and rotation (9, by rows)
#: a riding mass's ints: the packed frame carrying its line, its ξ's index in Q; its reals: its mass [kg], the line's
#: direction d0 (3) and point p0 (3) [m] in that frame
RI_FRAME, RI_COORD, RI_W = 0, 1, 2
RR_MASS, RR_DIR, RR_POINT, RR_W = 0, 1, 4, 7
#: a contact's ints (frame: its packed frame, the zero frame after them for a body's point; coords: where its
#: bodies' coordinates are in ints, [n touching side, n surface side, their indices]; friction: FRICTION_* below;
#: rows: -1 none; law: the friction law's address, 0 constant μ_k; surface: the packed frame carrying the surface,
#: -1 for the ground or a body; bonded: 1 where the contact never separates)
(CI_FRAME, CI_COORDS, CI_TOUCHING, CI_FRICTION, CI_NT, CI_LAW, CI_N_FP, CI_FP_AT, CI_NORMAL, CI_FIRST_T, CI_N_T,
 CI_NORMAL_ROW, CI_STICK_ROW, CI_IMPULSE, CI_REALS, CI_SURFACE, CI_BONDED, CI_W) = range(18)
FRICTION_NONE, FRICTION_STICK, FRICTION_SLIDE, FRICTION_APART = 0, 1, 2, 3
#: a contact's reals: surface point [m], a touching body's point [m] (else 0), tangents (2 rows of 3), slip
#: reference r, μ_s, μ_k, viscous [N·s/m], the normal, then its bodies' coordinates' unit axes (3 each, as in
#: CI_COORDS); on a surface carried by a robot frame the point, tangents and normal are in that frame's coordinates
CR_POINT, CR_TOUCH, CR_T, CR_R, CR_MU_S, CR_MU_K, CR_VISCOUS, CR_N, CR_AXES = 0, 3, 6, 12, 14, 15, 16, 17, 20
#: a chain's ints: where its plan, stage table, coefficients and constants are (ints, reals), its buffers (work),
#: its bond row (-1: none) and the bond's two surface nodes (kind, coordinate), its anchor offset (reals)
(CH_PLAN, CH_STAGES, CH_NS, CH_COEF, CH_CONSTS, CH_NCONSTS, CH_MOTION, CH_NNODES, CH_STATE, CH_ROW, CH_ROBOT_KIND,
 CH_ROBOT_COORD, CH_ENV_KIND, CH_ENV_COORD, CH_OFFSET, CH_W) = range(16)
LI_JOINT, LI_SIDE, LI_W = 0, 1, 2  #: a pressing limit's ints (its value [rad or m] in reals)
#: the event values the call writes (``events``): per contact its gap [m], normal force [N], slip velocity [m/s]
#: and friction force [N] in tangent coordinates; then each pressing limit's torque [N·m or N], each held (stuck)
#: joint's holding torque [N·m or N], each sliding joint's speed [rad/s or m/s]; then the status
EV_GAP, EV_FN, EV_VT, EV_FF, EV_W = 0, 1, 2, 4, 6
#: status: 1 the call is complete (a singular KKT matrix too: solved by least squares, counted at
#: work[ints[W_LEAST_SQUARES]]); 0 its KKT system has a non-finite entry, -1 a compiled law gave no force
#: (Pipeline.failed_call)
TIP, ANCHOR, MASS = int(NodeKind.TIP), int(NodeKind.ANCHOR), int(NodeKind.MASS)
#: the diagnostics section of ``work`` (from ``ints[W_DIAG]``; :func:`.pipeline.record`): its switch (the call writes
#: the section when it is not 0), then per chain its interface force [N] (written always), then the drives' applied
#: forces (N_DRIVES) [N·m or N], the controller's τ (NV), the tip's position (3) [m], x_d (REF_DIMS) [m], the force
#: set-points (N_FORCES) [N], the rows' forces λ (N_ROWS) and the contacts' generalized force on the joints as a
#: sampled law measures it (NV) [N·m or N] (``PipelineMode.measurement``)
(D_TAU, D_CMD, D_TIP, D_XD, D_FD, D_LAM, D_TC, D_END) = range(8)


@njit(cache=True)
def diag_starts(ints):
    """Where each part of the diagnostics section starts in ``work`` (D_* order, then its end); its interface
    forces start at ``ints[W_DIAG] + 1``."""
    at = np.empty(D_END + 1, dtype=np.int64)
    at[D_TAU] = ints[W_DIAG] + 1 + ints[N_CHAINS]
    at[D_CMD] = at[D_TAU] + ints[N_DRIVES]
    at[D_TIP] = at[D_CMD] + ints[NV]
    at[D_XD] = at[D_TIP] + 3
    at[D_FD] = at[D_XD] + ints[REF_DIMS]
    at[D_LAM] = at[D_FD] + ints[N_FORCES]
    at[D_TC] = at[D_LAM] + ints[N_ROWS]
    at[D_END] = at[D_TC] + ints[NV]
    return at


@njit(cache=True, inline="always")
def section(arr, at, rows, width):
    """The rows × width table stored flat in ``arr`` from ``at`` (a view)."""
    return arr[at:at + rows * width].reshape((rows, width))


@dataclass
class Packed:
    """One mode's arrays and what names their outputs."""

    ints: np.ndarray
    reals: np.ndarray
    work: np.ndarray
    events: np.ndarray  #: the call's event values (EV_* per contact, the limits' torques, the status)
    row_meta: list[tuple[str, str, int]]  #: (owner, kind, index) per KKT row, as contactdyn.model.constraints
    contacts: list[str]
    limits: list[int]  #: the pressing joints' coordinates, in the order of their torques
    held: list[int]  #: the stuck joints with a row, in the order of their holding torques
    sliding: list[int]  #: the sliding joints, in the order of their speeds

    def joint_event_starts(self) -> tuple[int, int, int]:
        """Where in ``events`` the pressing limits' torques, the held joints' torques and the sliding joints' speeds
        start (after every contact's EV_W values; the status last)."""
        limits = EV_W * len(self.contacts)
        held = limits + len(self.limits)
        return limits, held, held + len(self.held)


def unsupported(system, modes, phase) -> str:
    """Why the compiled call cannot pack (modes, phase) ("" when it can): the run then stops with it."""
    if reason := _bodies_unsupported(system, phase):
        return reason
    if system.robot.rigid_table is None:
        return "a robot rigid_body does not compute (its terms would be copied in from Pinocchio)"
    return ""


def python_stages(system, modes, phase) -> list[str]:
    """The laws of (modes, phase) numba cannot compile (stage, friction, drive kinds, the controller), each run in the
    compiled call as a declared Python stage (called back through ctypes,
    :func:`contactdyn.laws.abi.python_stage_address`), named with numba's reason."""
    out = []
    for c, m in zip(system.contacts, modes, strict=True):
        for dc in c.chains:
            for _, stage in pack_chain(system, c, dc, m.touching, m.relaxing and not m.touching).python_stages:
                out.append(f"stage law {stage.law!r} of {c.name}.{dc.label} is a Python stage "
                           f"({stage.law_class.compiled_reason})")
        fr = c.friction
        if fr is not None and not fr.constant and m.touching and not m.stuck and len(c.tangents):
            law = FRICTION_LAWS[fr.law]
            if not friction_address(law):
                out.append(f"friction law {fr.law!r} of {c.name} is a Python stage ({law.compiled_reason})")
    ctl = phase.controller
    sampled = isinstance(ctl, SampledController)  # (its law runs at the samples: hybrid.sampled_law)
    law = ctl.inner if sampled else ctl
    if python_controller(law):
        at_samples = "; at its samples" if sampled else ""
        out.append(f"controller {law.name!r} is a Python stage ({type(law).compiled_reason}{at_samples})")
    return list(dict.fromkeys(out + python_drives(system)))


def _bodies_unsupported(system, phase) -> str:
    """Why the articulated bodies keep the mode off the pipeline ("" when their joints join the robot's in the
    rigid-body table: :func:`contactdyn.robot.rigid_body.forest_table`)."""
    for name, body in system.articulated.items():
        if any(robot.rigid_table is None for robot in body.robots):  # (a free body: both charts' models)
            return f"body {name!r}: a joint rigid_body does not compute"
        if not np.array_equal(body.robots[0].model.gravity.linear, system.robot.model.gravity.linear):
            return f"body {name!r}: its model's gravity is not the robot's (one universe row in the rigid-body table)"
    return ""


#: the built-in controllers compiled into the call as kinds (their laws' own compiled functions)
COMPILED_IN = ("task_pd", "operational_space", "position_dynamic", "force_dynamic", "hybrid", "joint_pd",
               "task_force")
DYNAMIC_LAWS = COMPILED_IN[2:5]
BY_ADDRESS = COMPILED_IN[1:5]  #: built-in laws of the controller ABI's shape, called by address (control_laws)


def python_controller(ctl) -> bool:
    """Is the phase's controller a user's law numba cannot compile (its reason in ``compiled_reason``), run in the
    compiled call as a declared Python stage (:func:`contactdyn.laws.controllers.abi.python_controller_address`)?
    (A sampled law's held command is read off the state: its law is asked at the samples, on a pipeline of its own,
    hybrid.sampled_law; the kinds compiled in and constant voltages are not the ABI's.)"""
    return not isinstance(ctl, (SampledController, ConstantVoltage)) and ctl.name not in COMPILED_IN and \
        not _addressable(type(ctl))


def _addressable(cls: type) -> bool:
    """A controller of the ABI compiled to its address. Interpreted (handles, a first run), none: every user law runs
    its own ``command`` on the readable ControlInput, as a declared Python stage does (whether numba would compile it
    is not asked: that would compile it)."""
    if not handles():
        return controller_address(cls) != 0
    cls.compiled_reason = "the call runs interpreted"
    return False


class _Builder:
    """Appends sections to ``ints`` and ``reals``; the header's slots point at them."""

    def __init__(self) -> None:
        self.ints: list[int] = [0] * HEADER
        self.reals: list[float] = [0.0] * RH_SIZE
        self.work = 0

    def int_section(self, slot: int | None, values) -> int:
        at = len(self.ints)
        if slot is not None:
            self.ints[slot] = at
        self.ints += [int(v) for v in values]
        return at

    def real_section(self, slot: int | None, values) -> int:
        at = len(self.reals)
        if slot is not None:
            self.ints[slot] = at
        self.reals += [float(v) for v in np.ravel(values)]
        return at


def pack(system, modes, phase) -> Packed:
    """The arrays of (modes, phase) (:func:`unsupported` must be "")."""
    b = _Builder()
    h = b.ints
    nv, nQ = system.nv, system.nQ
    h[NV], h[NQ], h[NY], h[NX], h[N_DRIVES] = nv, nQ, system.ny, system.n, len(system.drives.specs)
    h[ENERGY] = system.energy_slot
    b.reals[RH_OMEGA], b.reals[RH_SLIP_BAND] = system.stabilization, system.slip_band
    bodies = system.articulated.values()
    table, starts = forest_table(system.robot.rigid_table, [(body.robots[0].rigid_table, body.first)
                                                            for body in bodies])  # (chart A's: robots[0])
    h[NJ], h[NF] = table.shape[0], max([nv, *(body.first + body.nb for body in bodies)])
    b.real_section(R_RIGID, table)
    starts = dict(zip(system.articulated, starts, strict=True))
    _charts(b, system, starts)
    m_rest = system.M_rest.copy()
    for body in bodies:  # H_b is M's block there (constraints.mass_matrix writes it over the diagonal)
        m_rest[body.first - nv:body.first - nv + body.nb] = 0.0
    b.real_section(R_MREST, m_rest)
    b.real_section(R_WEIGHTS, system.weights)  # [N] the non-robot coordinates' weights (a body's m g·axis)
    frames = [k for k in dict.fromkeys([system.tip_fid, *(_touch_frame(c) for c in system.contacts),
                                        *(_surface_frame(c) for c in system.contacts)]) if k is not None]
    _frames(b, system, frames, starts)
    h[TIP_FRAME] = 0
    meta = _contacts(b, system, modes, frames)
    _riding(b, system, frames)
    h[N_LIMITS] = len(phase.limits)
    b.int_section(I_LIMITS, [v for i, side in phase.limits for v in (i, side)])
    b.real_section(R_LIMITS, [system.limits.by_index[i].lower if side > 0 else system.limits.by_index[i].upper
                              for i, side in phase.limits])
    meta += [(system.limits.by_index[i].name, "limit", i) for i, _ in phase.limits]
    held, sliding = _joint_friction(b, system, phase)
    meta += [(system.joint_friction.names[i], "joint", i) for i in held]
    h[N_ROWS] = len(meta)
    launches = [ci for ci, m in enumerate(modes) if launching(m)]
    h[N_LAUNCH] = len(launches)
    b.int_section(I_LAUNCH, launches)
    h[N_SERVOS] = len(system.servo)
    b.int_section(I_SERVOS, [idx for idx, _, _ in system.servo])
    b.real_section(R_SERVOS, [v for _, v_ref, gain in system.servo for v in (v_ref, gain)])
    _reference(b, system, phase)
    _controller(b, system, phase)
    _drives(b, system, phase)
    _fold(b, system, modes, phase, meta)
    h[W_LEAST_SQUARES], h[W_SPLITS] = b.work, b.work + 1  # (one slot each: the counts)
    h[W_DIAG] = b.work = b.work + 2
    b.work = int(diag_starts(np.array(h, dtype=np.int64))[D_END])
    h[W_SIZE] = b.work
    n_events = EV_W * len(system.contacts) + len(phase.limits) + len(held) + len(sliding) + 1
    return Packed(np.array(h, dtype=np.int64), np.array(b.reals), np.zeros(max(b.work, 1)), np.zeros(n_events),
                  meta, [c.name for c in system.contacts], [i for i, _ in phase.limits], held, sliding)


def _touch_frame(c):
    """The packed frame's key of a contact's touching side: its robot frame's id, an articulated body's point
    (body, frame id, the point in that frame [m]), or None (a translating body's point)."""
    if c.touch_link is not None:
        return c.touch_link[0].name, c.touch_link[1], tuple(float(v) for v in c.spec.frame_point)
    return c.fid if c.fid >= 0 else None


def _surface_frame(c):
    """The packed frame's key of the frame carrying a contact's surface: a robot frame's id, an articulated body's
    frame (body, frame id, its origin), or None (the ground, a translating body)."""
    if c.surface_link is not None:
        return c.surface_link[0].name, c.surface_link[1], (0.0, 0.0, 0.0)
    return c.surface_fid if c.surface_fid >= 0 else None


def _riding(b: _Builder, system, frames: list) -> None:
    """Per chain mass riding a turning surface its carrying frame (its index among the packed ``frames``) and ξ's
    index in Q (ints), its mass [kg], the line's direction and point in that frame [m] (reals)."""
    b.ints[N_RIDING] = len(system.riding)
    b.int_section(I_RIDING, [v for rm in system.riding for v in (frames.index(_surface_frame(rm.contact)), rm.coord)])
    b.real_section(R_RIDING, [v for rm in system.riding for v in (rm.mass, *rm.direction, *rm.contact.spec.point)])


def _charts(b: _Builder, system, starts: dict[str, int]) -> None:
    """Per free body its chart's slot in x and its joints' rows in the rigid-body table (chart A's there), and those
    rows in chart B (its model turned by free_chart.C: the roll link's inertia, its children's placements), which
    :func:`.robot_terms.table_at` puts in while x is in chart B (``starts``: each body's first row in the table)."""
    free = [(name, body) for name, body in system.articulated.items() if body.free]
    b.ints[N_CHARTS] = len(free)
    rows = []  # (each body's rows depend on its own table only: one forest of every body's last chart serves all)
    turned, _ = forest_table(system.robot.rigid_table, [(body.robots[-1].rigid_table, body.first)
                                                        for body in system.articulated.values()])
    for name, body in free:
        row = starts[name]
        rows += [body.chart_index, row, body.nb, b.real_section(None, turned[row:row + body.nb])]
    b.int_section(I_CHARTS, rows)


def _frames(b: _Builder, system, keys: list, starts: dict[str, int]) -> None:
    """Per frame its joint (its row in the rigid-body table), the columns that move it (indices in Q), its free
    body's chart slot (-1: none) and its placement in its joint (translation [m], rotation by rows; a free body's
    frame also its chart B's, R_FRAMES_B), as :func:`.robot_terms.frame_terms` reads them. A robot frame by its id;
    an articulated body's point (body, frame id, point [m]) as a frame of its joint placed at that point
    (``starts``: each body's first row in the table)."""
    b.ints[N_FRAMES] = len(keys)
    rows, supports, consts, turned = [], [], [], []
    for key in keys:
        body, fid, point = (None, key, None) if isinstance(key, int) else key
        art = system.articulated[body] if body is not None else None
        models = [robot.model for robot in art.robots] if art is not None else [system.robot.model]
        first, row0 = (art.first, starts[body] - 1) if art is not None else (0, 0)
        frame = models[0].frames[fid]  # (the joints and supports are the same in either chart)
        cols = [first + k for jj in models[0].supports[frame.parentJoint][1:]
                for k in range(models[0].joints[jj].idx_v, models[0].joints[jj].idx_v + models[0].joints[jj].nv)]
        chart = art.chart_index if art is not None and art.free else -1
        rows.append((row0 + frame.parentJoint, len(cols), len(supports), chart))
        supports += cols
        consts += _placement(frame, point)
        turned += _placement(models[-1].frames[fid], point)  # (chart B's: its frames on the roll joint turned by C)
    at = b.int_section(I_FRAMES, [0] * (FI_W * len(keys)))
    support_at = b.int_section(None, supports)
    for k, (joint, n, start, chart) in enumerate(rows):
        b.ints[at + FI_W * k:at + FI_W * (k + 1)] = [joint, n, support_at + start, chart]
    b.real_section(R_FRAMES, consts)
    if b.ints[N_CHARTS]:
        b.real_section(R_FRAMES_B, turned)


def _placement(frame, point) -> list[float]:
    """A packed frame's reals: its placement in its joint, translation [m] (moved to ``point`` [m] in the frame, a
    body's point) and rotation by rows."""
    r = frame.placement.translation if point is None else \
        frame.placement.translation + frame.placement.rotation @ np.array(point)
    return [*r, *frame.placement.rotation.ravel()]


def _contacts(b: _Builder, system, modes, frames: list) -> list[tuple[str, str, int]]:
    """The contacts' and chains' rows; the KKT rows' meta, in order (per contact: its tangential
    chains' bonds, its stick rows, its normal row)."""
    h = b.ints
    h[N_CONTACTS] = len(system.contacts)
    chains = [(c, m, dc, i - 1) for c, m in zip(system.contacts, modes, strict=True) for i, dc in enumerate(c.chains)]
    h[N_CHAINS] = len(chains)
    contact_at = b.int_section(I_CONTACTS, [0] * (CI_W * len(system.contacts)))
    chain_at = b.int_section(I_CHAINS, [0] * (CH_W * len(chains)))
    meta: list[tuple[str, str, int]] = []
    k = 0
    for ci, (c, m) in enumerate(zip(system.contacts, modes, strict=True)):
        first = k
        rows_of = {}
        for i, dc in enumerate(c.tangent_chains):
            rows_of[k + 1 + i] = _tangent_row(meta, c, dc, m, i)
        nt = len(c.tangents) if c.friction is not None else 0
        stick_row = len(meta) if nt and m.touching and m.stuck else -1
        if stick_row >= 0:
            meta += [(c.name, "t", i) for i in range(nt)]
        normal_row = len(meta) if m.touching and c.normal.chain.bonded_when_touching else -1
        if normal_row >= 0:
            meta.append((c.name, "n", 0))
        rows_of[first] = normal_row
        for _ in c.chains:
            _chain(b, system, *chains[k][:3], chains[k][3], chain_at + CH_W * k, rows_of.get(k, -1))
            k += 1
        friction = FRICTION_NONE if not nt else FRICTION_APART if not m.touching else \
            FRICTION_STICK if m.stuck else FRICTION_SLIDE
        fr = c.friction
        law = (friction_address(FRICTION_LAWS[fr.law]) or python_friction_address(fr)) if nt and not fr.constant \
            else 0
        fp_at = b.real_section(None, fr.params if nt else ())
        T = np.zeros((2, 3))  # the tangents of its friction or of its tangential chains
        T[:len(c.tangents)] = c.tangents
        r = np.zeros(2)
        r[:len(m.slip)] = m.slip
        coords = [*c.touch_coords, *c.surface_coords]
        coords_at = b.int_section(None, [len(c.touch_coords), len(c.surface_coords), *(i for i, _ in coords)])
        touch = c.spec.frame_point if c.fid < 0 else np.zeros(3)
        reals_at = b.real_section(None, [*c.spec.point, *touch, *T.ravel(), *r,
                                         *((fr.mu_s, fr.mu_k, fr.viscous) if nt else (0.0, 0.0, 0.0)),
                                         *c.spec.normal, *(v for _, axis in coords for v in axis)])
        touching, surface = _touch_frame(c), _surface_frame(c)  # (a translating body's point: the zero frame after
        frame = frames.index(touching) if touching is not None else len(frames)  # the others; the ground: none)
        h[contact_at + CI_W * ci:contact_at + CI_W * (ci + 1)] = [
            frame, coords_at, int(m.touching), friction, nt, law, len(fr.params) if nt else 0, fp_at,
            first, first + 1, len(c.tangent_chains), normal_row, stick_row, system.impulse_slots.get(c.name, -1),
            reals_at, frames.index(surface) if surface is not None else -1, int(c.spec.bonded)]
    return meta


def set_slip_references(ints: np.ndarray, reals: np.ndarray, modes) -> None:
    """Write each contact's 2-D slip reference r (tangent coordinates) of ``modes`` into ``reals``: a ``turn``
    refreshes r in a packed mode (the same :func:`~contactdyn.model.contact.structure`)."""
    for ci, m in enumerate(modes):
        if len(m.slip) == 2:
            at = ints[ints[I_CONTACTS] + CI_W * ci + CI_REALS] + CR_R
            reals[at:at + 2] = m.slip


def _tangent_row(meta: list, c, dc, m, i: int) -> int:
    """The row of tangential chain ``dc`` (its bond, while touching) appended to ``meta``; -1 without one."""
    if not (m.touching and dc.chain.bonded_when_touching):
        return -1
    meta.append((c.name, dc.label, i))
    return len(meta) - 1


def _chain(b: _Builder, system, c, m, dc, tangent: int, at: int, row: int) -> None:
    """One chain's arrays (its plan in the mode, chain_forces.pack) copied into ints, reals and work."""
    a = pack_chain(system, c, dc, m.touching, m.relaxing and not m.touching)
    chain = dc.chain
    plan_at = b.int_section(None, a.plan)
    stages = a.stages.copy()
    for k, stage in a.python_stages:  # a law numba cannot compile: its declared Python stage's address
        stages[k, S_LAW] = python_stage_address(stage.law_class)
    stages_at = b.int_section(None, stages.ravel())
    coef_at = b.real_section(None, a.coef)
    consts_at = b.real_section(None, a.consts)
    offset_at = b.real_section(None, [m.offsets[tangent] if tangent >= 0 else 0.0])
    motion_at, state_at = b.work, b.work + a.motion.size
    b.work += a.motion.size + a.stage_state.size

    def surface(node: int) -> tuple[int, int]:
        n = chain.nodes[node]
        return int(n.kind), n.coord  # (a tip's and an anchor's coordinates: the plan's H_COORDS)

    b.ints[at:at + CH_W] = [plan_at, stages_at, len(chain.stages), coef_at, consts_at, a.consts.size, motion_at,
                            len(chain.nodes), state_at, row, *surface(chain.robot_surface),
                            *surface(chain.env_surface), offset_at]


def _joint_friction(b: _Builder, system, phase) -> tuple[list[int], list[int]]:
    """The joints' damping b (nv) [N·m·s/rad or N·s/m], the stuck joints that carry a row, the sliding ones with
    (s, τ_k [N·m or N]) (model.joint_friction), then the same joints' impulse states (x's index of ∫τ_f dt), then the
    held joints' static limits τ_s [N·m or N]; (the held joints in their rows' order, the sliding ones)."""
    jf, h = system.joint_friction, b.ints
    held = jf.held(phase.joint_modes, phase.limits) if jf.any else []
    sliding = [(i, m) for i, m in phase.joint_modes if m != 0] if jf.any else []
    h[JOINT_FRICTION], h[N_HELD], h[N_SLIDING] = int(jf.any), len(held), len(sliding)
    slot = {i: 2 * system.nQ + system.joint_impulse_slot + k for k, i in enumerate(jf.dry)}  # (x's index of ∫τ_f dt)
    b.int_section(I_JOINTS, [*held, *(i for i, _ in sliding), *(slot[i] for i in held), *(slot[i] for i, _ in sliding)])
    b.real_section(R_JOINTS, [*jf.damping, *(v for i, m in sliding for v in (m, jf.kinetic[i])),
                              *(jf.static[i] for i in held)])
    return held, [i for i, _ in sliding]


def _reference(b: _Builder, system, phase) -> None:
    """The reference's start and moves (trajectory.move_table, then each move's Δ), the body that carries it
    (its coordinate, -1 none, and unit axis), the force ramps and the set-points' directions (the controller's
    normals), in the phase's order."""
    h = b.ints
    ref = phase.reference
    h[REF_DIMS] = len(ref.start) if ref is not None else 0
    h[N_MOVES] = len(ref.moves) if ref is not None else 0
    if ref is not None:
        b.real_section(R_REF, [*ref.start, *move_table(ref.moves).ravel(), *(v for mv in ref.moves for v in mv.delta)])
    else:
        h[R_REF] = len(b.reals)
    moves = ref.moves if ref is not None else ()
    b.real_section(R_CIRCLES, [[1.0, 2.0 * math.pi * m.turns, *m._circle_terms.ravel()] if m.kind == "circle" else
                               [0.0] * CIRCLE_W for m in moves])
    h[CARRIER] = phase.carrier[0] if phase.carrier is not None else -1
    b.real_section(R_CARRIER, phase.carrier[1] if phase.carrier is not None else np.zeros(3))
    keys = list(phase.forces)
    h[N_FORCES] = len(keys)
    b.real_section(R_RAMPS, [*ramp_table([phase.forces[k] for k in keys]).ravel(),
                             *(v for k in keys for v in system.force_directions[k])])


def _controller(b: _Builder, system, phase) -> None:
    """task PD: its constants (TaskPD.constants) and feedforward; constant voltages: one per joint; operational
    space: its constants; a controller of the ABI: the layout of its inputs (x_d, v_d, a_d of the reference's
    coordinates: 3 or nv), its address and its declared parameters; a dynamic law: the same layout and its constants
    (:func:`_dynamic_constants`; A7 in joint space: K_p, K_v per joint and the rotors taken out of H); a sampled
    law: where its held command is in x."""
    h = b.ints
    ctl = phase.controller
    h[READS_ORIENTATION], h[NEEDS_GRAVITY] = int(ctl.reads_orientation), int(ctl.needs_gravity)
    if isinstance(ctl, SampledController):
        h[CTL_KIND], h[X_HELD] = CTL_HELD, 2 * system.nQ + phase.z_slice.start + ctl.held.start
        b.int_section(I_LAYOUT, ())
        return
    if ctl.name == "task_pd":
        axes, kp, kd, tool_axis, target, R_d, ko, do, kd_joint, kd_normal = ctl.constants
        h[CTL_KIND], h[N_AXES], h[HAS_TOOL], h[HAS_RD] = CTL_TASK_PD, len(axes), int(tool_axis.size > 0), \
            int(R_d.shape[0] > 0)
        h[FEEDFORWARD] = FEEDFORWARDS[ctl.config.feedforward]
        h[NEEDS_GRAVITY] = int(h[FEEDFORWARD] == FF_GRAVITY)
        b.real_section(R_CTL, [*axes.ravel(), *kp, *kd, *_tool(tool_axis, target),
                               *(R_d.ravel() if R_d.shape[0] else np.zeros(9)), ko, do, kd_joint, kd_normal])
        b.int_section(I_LAYOUT, ())
        return
    if isinstance(ctl, ConstantVoltage):  # its voltages [V] as they are (the drive table takes them)
        h[CTL_KIND] = CTL_CONSTANT
        b.real_section(R_CTL, np.broadcast_to(ctl.config.u, (system.nv,)))
        b.int_section(I_LAYOUT, ())
        return
    if ctl.name in ("joint_pd", "task_force"):  # control_laws.joint_pd_command, task_force_command
        h[CTL_KIND] = CTL_JOINT_PD if ctl.name == "joint_pd" else CTL_TASK_FORCE
        ff = FEEDFORWARDS[ctl.config.feedforward]
        f, rate, start, ramp, amp, freq, ph, osc = ctl.constants if ctl.name == "task_force" else (None,) * 8
        b.real_section(R_CTL, [ff, *ctl.gains[0], *ctl.gains[1]] if ctl.name == "joint_pd" else
                       [ff, *f, *rate, start, ramp, *amp, freq, *ph, float(osc)])
        b.int_section(I_LAYOUT, ())
        return
    in_python = python_controller(ctl)  # its declared Python stage reads what the readable ControlInput has
    absent = (*(("gravity",) if not ctl.needs_gravity else ()),
              *(("x_d", "v_d", "a_d") if phase.reference is None else ()),
              *(("R_tip", "J_ang", "drift_ang") if not (ctl.reads_orientation or in_python) else ()),
              *(("tau_contact", "surface_p", "surface_v", "touch") if not ctl.uses_forces else ()))
    h[N_Z], h[Z_AT], h[READS_FORCES] = ctl.n_states, phase.z_slice.start, int(ctl.uses_forces)
    dims = len(phase.reference.start) if phase.reference is not None else 3  # (3: x_d absent, its size unread)
    keys = surface_keys(system)  # (the readable ControlInput's dictionaries' keys, I_KEYS' order)
    b.int_section(I_LAYOUT, layout_of(system.nv, ctl.n_states, absent, len(phase.forces), dims,
                                      len(keys) if in_python else 0))
    h[CTL_KIND] = CTL_ABI
    cls = type(ctl)
    if in_python:
        h[CTL_ADDRESS] = python_controller_address(ctl, InputKeys(
            tuple(keys), tuple(c.name for c in system.contacts), tuple(phase.forces), system.force_directions,
            ctl.uses_forces))
        params = np.zeros(0)
    elif ctl.name == "position_dynamic" and ctl.config.space == "joint":  # A7 in joint space (its own kind)
        h[CTL_ADDRESS] = kind_address(JOINT_DYNAMIC)
        params = np.array([*ctl.joint_gains[0], *ctl.joint_gains[1], *ctl._rotor])
    elif ctl.name in BY_ADDRESS:  # a built-in law of the ABI's shape (control_laws), its constants the params
        h[CTL_ADDRESS] = kind_address(ctl.name)
        params = np.array(_dynamic_constants(ctl, phase) if ctl.name in DYNAMIC_LAWS else
                          _operational_constants(ctl, phase))
    else:
        h[CTL_ADDRESS] = _handle(cls) if handles() else controller_address(cls)
        params = params_of(ctl.config)
    h[N_CTL_PARAMS] = params.size
    b.real_section(R_CTL, params)


def _drives(b: _Builder, system, phase) -> None:
    """The drive table (.drives.drive_table): its rows, values and reflected rotor inertias; its outputs in work."""
    rows, reals, reflected = drive_table(system, phase)
    b.ints[ANY_MOTOR] = int(system.drives.any_motor)
    b.int_section(I_DRIVES, rows.ravel())
    b.real_section(R_DRIVES, reals)
    b.real_section(R_REFLECTED, reflected)
    b.ints[W_DRIVES] = b.work
    b.work += DW_W * len(system.drives.specs) + 2


def _operational_constants(ctl, phase) -> list[float]:
    """Operational space's constants (control_laws' O_*), from OperationalSpace.constants: its force directions in
    the phase's order of set-points (the buffer's F_d's; the law's are in ``force_keys``' order)."""
    axes, forced, kp, kd, tool_axis, target, ko, do, k_null, kd_normal = ctl.constants
    forced = forced[[ctl.force_keys.index(key) for key in phase.forces]].reshape(-1, 3)
    return [len(axes), float(tool_axis.size > 0), *axes.ravel(), *forced.ravel(), *kp, *kd, *_tool(tool_axis, target),
            ko, do, k_null, kd_normal]


def _tool(tool_axis, target) -> list[float]:
    """A task law's tool axis and its target direction (3 + 3), zeros without a tool."""
    return [*tool_axis, *target] if tool_axis.size else [0.0] * 6


def _dynamic_constants(ctl, phase) -> list[float]:
    """A bound task-space dynamic law's constants (D_*), per set-point in the phase's order."""
    cfg = ctl.config
    kp, kv = ctl._gains3
    force_law = ctl.name != "position_dynamic"
    P = ctl.P if force_law else np.zeros((3, 3))
    envs = [ctl.envs.get(key) for key in phase.forces]
    env = [v for e in envs for v in ((e.k, e.b, e.m) if e is not None else (1.0, 0.0, 0.0))]
    return [float(force_law), float(getattr(ctl, "tracks_position", True)),
            float(force_law and cfg.cancel == "target"), float(bool(ctl.envs) and not force_law),
            float(getattr(cfg, "kf", 0.0)), float(cfg.k_null), *kp, *kv, *P.ravel(), *env, *ctl._rotor]


def _fold(b: _Builder, system, modes, phase, meta: list[tuple[str, str, int]]) -> None:
    """I_FOLD: per set-point the contact whose normal force it reads (-1 for a tangential chain's), then per row the
    contact whose normal it is (-1: a stick, a tangential bond, a limit), then per set-point the chain whose
    interface force it reads (-1: a normal one) and its contact; R_FOLD: per set-point its surface point's shift
    from the contact's [m] (a tangential chain's anchor: u · offset, where it is undeformed since the latest touch)."""
    names = [c.name for c in system.contacts]
    first = np.cumsum([0, *(len(c.chains) for c in system.contacts)])
    chain, owner, shift = [], [], []
    for key in phase.forces:
        name, _, label = key.partition(".")
        ci = names.index(name)
        i = next((i for i, dc in enumerate(system.contacts[ci].tangent_chains) if dc.label == label), -1)
        owner.append(ci)
        chain.append(int(first[ci]) + 1 + i if label else -1)
        shift.append(system.contacts[ci].tangent_chains[i].u * modes[ci].offsets[i] if label else np.zeros(3))
    b.int_section(I_FOLD, [*(names.index(key) if key in names else -1 for key in phase.forces),
                           *(names.index(owner) if kind == "n" else -1 for owner, kind, _ in meta), *chain, *owner])
    b.real_section(R_FOLD, shift)
    keys = [(ci, int(first[ci]) + 1 + i if i >= 0 else -1, c.tangent_chains[i].u * modes[ci].offsets[i] if i >= 0
             else np.zeros(3)) for ci, c in enumerate(system.contacts) for i in range(-1, len(c.tangent_chains))]
    b.int_section(I_KEYS, [v for ci, chain_at, _ in keys for v in (ci, chain_at)])  # (evaluation.surface_keys' order)
    b.real_section(R_KEYS, [v for _, _, shift_k in keys for v in shift_k])


#: handle -> controller class: the controller's Python ``command`` under NUMBA_DISABLE_JIT (the address's twin)
PYTHON_CONTROLLERS: dict[int, type] = {}


def _handle(cls: type) -> int:
    PYTHON_CONTROLLERS[id(cls)] = cls
    return id(cls)
