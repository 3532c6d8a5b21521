"""The constraint system: active rows, the KKT assembly and its solve (acceleration and impulse level).

In every mode the unknowns — Q̈ [m/s², rad/s²] and the forces λ [N] of the active rows —
come from one linear system

    [ M  −Cᵀ ] [Q̈]   [ f  ]
    [ G   0  ] [λ ] = [ −γ ]

where G Q̈ + γ = 0 are the acceleration-level constraints (rows) and C their force
columns: a row's own direction, tilted by sliding friction −μ_k d (eq. 27) when the row
is a sliding contact's normal. M is the mass matrix: the robot's H (plus rotor inertias
reflected through rigid gears), an articulated body's H_b, and the diagonal inertias of bodies, chain masses and
motors; f the generalized forces: −h and −h_b (Coriolis, centrifugal, gravity), stage forces,
friction, drives. At impulse level (impacts, :mod:`contactdyn.model.impact`) the same matrix
gives the velocity jump: M Q̇⁺ − Cᵀ Λ = M Q̇⁻, G Q̇⁺ = 0 (Λ [N·s]).

A row is one entry of :class:`Rows`: its generalized direction (a row of G), its force
column, its γ and who owns it, ``meta = (owner, kind, index)``. The kinds in use:

- ``(contact, "n", 0)``: a rigid or bonded contact's normal (force = the normal force F);
- ``(contact, "t", i)``: a sticking contact's tangent i (force = friction F_f,i);
- ``(contact, "t1" | "t2", i)``: a bonded tangential chain (force = its interface force);
- ``(joint, "limit", i)``: joint coordinate i pressing on its position limit (force = the limit's
  torque [N·m or N], :mod:`contactdyn.model.limits`);
- ``(joint, "joint", i)``: joint coordinate i stuck by its dry friction (force = the holding torque
  [N·m or N], :mod:`contactdyn.model.joint_friction`).

A new kind of row (a bilateral bond, ...) is a new ``rows.add(...)`` in the
evaluation plus a branch in :func:`record_row_forces` that says where its force goes.

A controller that reads measured forces is affine in them, τ = τ₀ + B λ; its columns B
fold into the matrix (:func:`solve_folded`), so the force it measures is the one the
solve returns (see :mod:`contactdyn.laws.controllers.base`).
"""

from __future__ import annotations

import numpy as np

from ..errors import SimulationError
from ..laws.controllers import ControlInput, Controller
from ..numerics.linalg import solve_vector
from .chain_forces import chain_forces
from .contact import Contact, Kinematics

__all__ = ["Rows", "solve_linear", "contact_row", "kkt_solve", "force_columns", "solve_folded", "record_row_forces",
           "velocity_rows", "impulse_solve"]

def solve_linear(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, bool]:
    """Solve A z = b; on a singular A fall back to the minimum-norm least-squares z."""
    with np.errstate(all="ignore"):
        z = solve_vector(A, b)
    if np.all(np.isfinite(z)) and np.linalg.norm(A @ z - b) <= 1e-9 * (1.0 + np.linalg.norm(b)):
        return z, True
    return np.linalg.lstsq(A, b, rcond=1e-12)[0], False


class Rows:
    """The active constraint rows of one evaluation, in order: G's rows, C's columns, γ, owners."""

    def __init__(self) -> None:
        self.rows: list[np.ndarray] = []  #: generalized directions (rows of G)
        self.cols: list[np.ndarray] = []  #: force columns (rows of C)
        self.gammas: list[float] = []  #: γ, the velocity-product and Baumgarte terms [m/s²]
        self.meta: list[tuple[str, str, int]] = []  #: (owner, kind, index), see the module docstring

    def add(self, row: np.ndarray, gamma: float, meta: tuple[str, str, int], col: np.ndarray | None = None) -> None:
        """Append a row; its force column is the row itself unless ``col`` is given."""
        self.rows.append(row)
        self.cols.append(row if col is None else col)
        self.gammas.append(gamma)
        self.meta.append(meta)

    def __len__(self) -> int:
        return len(self.rows)


def record_row_forces(system, ev, rows: Rows, lam: np.ndarray) -> None:
    """Put each row's solved force where its kind says: normal force, stick friction or chain interface.

    Kinds without a home here (none yet) keep their force in ``ev.lam`` beside ``ev.row_meta`` only.
    """
    for (name, kind, i), value in zip(rows.meta, lam, strict=True):
        if kind == "n":
            ev.normal_force[name] = float(value)
        elif kind == "t":
            ev.friction.setdefault(name, np.zeros(len(system.contact(name).tangents)))[i] = value
        elif kind == "limit":
            ev.limit_torque[i] = float(value)
        elif kind == "joint":
            ev.joint_hold[i] = float(value)
        elif kind[:1] == "t" and kind[1:].isdigit():  # a tangential chain's bond ("t1", "t2")
            ev.interface[f"{name}.{kind}"] = float(value)


def contact_row(system, c: Contact, u: np.ndarray, kin: Kinematics) -> np.ndarray:
    """Generalized row [m/m or m/rad] of the relative tip–environment motion along the unit direction u."""
    row = np.zeros(system.nQ)
    row[: system.nv] = u @ kin.J
    c.add_columns(row[None], u[None])
    kin.add_columns(row[None], u[None])
    return row


def mass_matrix(system) -> np.ndarray:
    """M [kg, kg·m²] of the system's coordinates at the robot's current state: H (and the motors' reflected rotors on
    its diagonal), then the bodies' masses, an articulated body's H_b, a riding mass's coupling with what carries it
    (at their last update; the system's own buffer, rewritten)."""
    nv = system.nv
    M = system._M
    M[:nv, :nv] = system.robot.H + np.diag(system._D) if system.drives.any_motor else system.robot.H
    for body in system.articulated.values():  # an articulated body's H_b (at its last update)
        M[body.first:body.first + body.nb, body.first:body.first + body.nb] = body.H
    for rm in system.riding:  # a point mass on its carrier: [J | n]ᵀ m [J | n] (its own m already on the diagonal)
        c, i = rm.carrier, rm.coord
        M[np.ix_(c, c)] += rm.mass * (rm.J.T @ rm.J)
        M[c, i] = M[i, c] = rm.mass * (rm.J.T @ rm.n)
    return M


def kkt_condition(system, rows: Rows) -> float:
    """2-norm condition number of the contact system [[M, −Cᵀ], [G, 0]] at the robot's current state (1.0 without
    rows): a rigid or sticking contact at a singular pose makes its rows linearly dependent."""
    if not rows:
        return 1.0
    nQ, nr = system.nQ, len(rows)
    A = np.zeros((nQ + nr, nQ + nr))
    A[:nQ, :nQ] = mass_matrix(system)
    A[:nQ, nQ:] = -np.array(rows.cols).T
    A[nQ:, :nQ] = np.array(rows.rows)
    return float(np.linalg.cond(A))


def kkt_solve(system, f: np.ndarray, rows: Rows, fold: np.ndarray | None,
           fold_q: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, bool]:
    """Q̈ and the row forces λ of [[M − fold_q, −Cᵀ − fold], [G, 0]] [Q̈; λ] = [f; −γ]."""
    nQ, nv = system.nQ, system.nv
    M = mass_matrix(system)
    if rows or fold_q is not None or system.articulated or system.riding:  # (else M is H beside a diagonal)
        nr = len(rows)
        A = np.zeros((nQ + nr, nQ + nr))
        A[:nQ, :nQ] = M if fold_q is None else M - fold_q
        if nr:
            A[:nQ, nQ:] = -np.array(rows.cols).T
            if fold is not None:
                A[:nQ, nQ:] -= fold
            A[nQ:, :nQ] = np.array(rows.rows)
        b = np.concatenate([f, -np.asarray(rows.gammas, float)])
        z_all, regular = solve_linear(A, b)
        return z_all[:nQ], z_all[nQ:], regular
    qdd = np.empty(nQ)
    qdd[:nv], regular = solve_linear(M[:nv, :nv], f[:nv])
    qdd[nv:] = f[nv:] / system.M_rest if nQ > nv else f[nv:]
    return qdd, np.empty(0), regular


def force_columns(inp: ControlInput, ctl: Controller, tau: np.ndarray, zdot, meta: list, cols: list, nv: int):
    """(B, D_z): how a force-reading controller's command τ and state rates ż change per unit force
    of each row (meta[j], force column cols[j] on the coordinates), probed by calling the law:
    +1 N on the contact's measured normal force for a normal row, the row's column on the joints'
    measured contact torque where it reaches a coordinate beyond the robot (else the row acts on
    the robot alone and stays out of the measurement)."""
    nr = len(meta)
    B = np.zeros((nv, nr))
    Dz = np.zeros((len(zdot), nr)) if zdot is not None else None
    if not ctl.uses_forces:
        return B, Dz
    for j, (name, kind, _) in enumerate(meta):
        fed_back = bool(np.any(cols[j][nv:]))
        if kind != "n" and not fed_back:
            continue
        forces = inp.forces if kind != "n" else {**inp.forces, name: inp.forces[name] + 1.0}
        tau_c = inp.tau_contact + cols[j][:nv] if fed_back else inp.tau_contact
        tau_j, zdot_j = ctl.command(inp.replaced(forces=forces, tau_contact=tau_c))
        B[:, j] = tau_j - tau
        if Dz is not None:
            Dz[:, j] = zdot_j - zdot
    return B, Dz


def solve_folded(system, inp: ControlInput, ctl: Controller, cmd: np.ndarray, zdot, f: np.ndarray, rows: Rows,
                 x: np.ndarray, vmask, carried=None):
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
    nQ, nv, drives = system.nQ, system.nv, system.drives
    nr = len(rows)
    B, Dz = force_columns(inp, ctl, cmd[:nv], zdot, rows.meta, rows.cols, nv)
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
        qdd, lam, regular = kkt_solve(system, fk, rows, fold, fold_q)
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


def velocity_rows(system, x, modes, slides: dict[str, tuple[np.ndarray, float]] | None = None,
                  jam: Contact | None = None, limits: tuple = (), joint_modes: tuple = ()):
    """Velocity constraints of the touching contacts (bond rows, sticks, tangential chain bonds), of
    the joints pressing on ``limits`` (:mod:`contactdyn.model.limits`) and of the joints stuck in
    ``joint_modes`` (:mod:`contactdyn.model.joint_friction`).

    ``slides`` (contact name -> (d, μ)) tilts each such contact's normal column by its sliding friction
    −μ d; ``jam`` adds stick rows for a contact that is not (yet) stuck.
    """
    rows = Rows()
    dummy_f, dummy_y = np.zeros(system.nQ), np.zeros(system.ny)
    for c, mode in zip(system.contacts, modes, strict=True):
        if not mode.touching:
            continue
        kin = system.kinematics(c, x)
        _, row, _, _, _ = chain_forces(system, c, c.normal, True, 0.0, kin, x, dummy_f, dummy_y, None, False)
        if row is not None:
            col = row
            if slides and c.name in slides:
                d, mu = slides[c.name]
                col = row - sum(mu * d[i] * contact_row(system, c, kin.tangents[i], kin)
                                for i in range(len(c.tangents)))
            rows.add(row, 0.0, (c.name, "n", 0), col)
        if c.friction is not None and len(c.tangents) and (mode.stuck or jam is c):
            for i, t_dir in enumerate(kin.tangents):
                r = contact_row(system, c, t_dir, kin)
                rows.add(r, 0.0, (c.name, "t", i))
        for i, dc in enumerate(c.tangent_chains):
            _, trow, _, _, _ = chain_forces(system, c, dc, True, mode.offsets[i], kin, x, dummy_f, dummy_y, None,
                                            False)
            if trow is not None:
                rows.add(trow, 0.0, (c.name, dc.label, i))
    system.limits.add_rows(limits, x, system.nQ, rows, 0.0)
    system.joint_friction.add_rows(joint_modes, limits, x, system.nQ, rows, 0.0)
    return rows


def impulse_solve(system, M: np.ndarray, rows: Rows, qd_minus: np.ndarray) -> tuple[np.ndarray, bool]:
    """[Q̇⁺; Λ] of [[M, −Cᵀ], [G, 0]] [Q̇⁺; Λ] = [M Q̇⁻; 0]: the momentum law with every row held.

    Solved for the jump ΔQ̇ = Q̇⁺ − Q̇⁻ (right-hand side [0; −G Q̇⁻]), so a coordinate no row
    reaches (an elastic drive's motor, eq. 58) keeps its velocity exactly."""
    nQ, nr = system.nQ, len(rows)
    A = np.zeros((nQ + nr, nQ + nr))
    A[:nQ, :nQ] = M
    A[:nQ, nQ:] = -np.array(rows.cols).T
    A[nQ:, :nQ] = G = np.array(rows.rows)
    b = np.concatenate([np.zeros(nQ), -(G @ qd_minus) if nr else np.zeros(0)])
    z, regular = solve_linear(A, b)
    if not np.all(np.isfinite(z)):
        raise SimulationError("impact map: the momentum-law system has no finite solution")
    z[:nQ] += qd_minus
    return z, regular
