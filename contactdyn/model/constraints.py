"""The constraint system's rows at impulse level (impacts) and its matrix's condition; the acceleration level is the
one pipeline's (:mod:`contactdyn.model.pipeline.kkt`).

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

The pipeline packs the same rows for the call (:mod:`contactdyn.model.pipeline.contacts`); here they are built
for an impact's momentum law (:func:`velocity_rows`, :func:`impulse_solve`) and a failed integration's
diagnosis (:func:`kkt_condition`).
"""

from __future__ import annotations

import numpy as np

from ..errors import SimulationError
from ..numerics.linalg import solve_vector
from .chain_forces import chain_forces
from .contact import Contact, Kinematics

__all__ = ["Rows", "solve_linear", "contact_row", "velocity_rows", "impulse_solve", "kkt_condition"]


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
        _, row, _, _, _ = chain_forces(system, c, c.normal, True, 0.0, kin, x, dummy_f, dummy_y)
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
            _, trow, _, _, _ = chain_forces(system, c, dc, True, mode.offsets[i], kin, x, dummy_f, dummy_y)
            if trow is not None:
                rows.add(trow, 0.0, (c.name, dc.label, i))
    system.limits.add_rows(limits, x, system.nQ, rows, 0.0)
    system.joint_friction.add_rows(joint_modes, limits, x, system.nQ, rows, 0.0)
    return rows


def kkt_condition(system, x: np.ndarray, modes, phase) -> float:
    """2-norm condition number of the contact system [[M, −Gᵀ], [G, 0]] at x (1.0 without rows): the velocity rows
    of the touching contacts, the joints on a limit and the stuck joints (:func:`velocity_rows`; a slide's tilt of
    its normal column left out). A rigid or sticking contact at a singular pose makes its rows linearly dependent:
    what a failed integration's message says (``hybrid.loop``)."""
    system.update_at(x)
    rows = velocity_rows(system, x, modes, limits=phase.limits, joint_modes=phase.joint_modes)
    if not rows:
        return 1.0
    nQ, nr = system.nQ, len(rows)
    A = np.zeros((nQ + nr, nQ + nr))
    A[:nQ, :nQ] = mass_matrix(system)
    A[:nQ, nQ:] = -np.array(rows.cols).T
    A[nQ:, :nQ] = np.array(rows.rows)
    return float(np.linalg.cond(A))


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
