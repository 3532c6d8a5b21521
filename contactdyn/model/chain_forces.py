"""A deformation chain's forces at one state: stages, junctions, the bond row and the gap.

Part I's contact-zone models (a), (b), (c) and their generalisations are chains of
Kelvin–Voigt stages and equivalent masses along one direction u (:mod:`contactdyn.model.chain`).
At a state x, with the chain's touching plan (:class:`~contactdyn.model.contact.ChainPlan`):

1. node motion: the tip and the anchor move with the contact's two sides, the touching one (a robot frame or
   a body's point) and the surface (the ground or a body) (s = u·p [m], ṡ = u·ṗ [m/s]); masses are
   coordinates of Q; a damped junction j is a first-order state whose rate balances its stages,
   Σ_below (k (s_lower − s_j) + b (ṡ_lower − ṡ_j)) = Σ_above (k (s_j − s_upper) + b (ṡ_j − ṡ_upper)),
   an undamped one, or one whose stages share a time constant b/k (:func:`~contactdyn.model.chain.balanced`),
   sits where its springs balance; a damped free end is a state only while it relaxes after a
   separation, else it follows its stage's other node;
2. stage forces F = k x + b ẋ [N] at compression x = s_lower − s_upper (or the
   Hunt–Crossley law) push the upper node along +u and the lower one back; their sums act
   on the tip (a Cartesian force along u; on a touching body's coordinates too), the masses and the
   surface's body;
3. with both surface nodes solid and touching, the chain is *bonded*: a constraint row
   G Q̈ + γ = 0 on the two surfaces' relative motion, stabilised by Baumgarte,
   ë + 2ω ė + ω² e = 0 on the violation e (ω = ``solver.stabilization`` [1/s]).

Written once, over flat arrays: :func:`pack` lays a chain's plan out for one (touching, relaxing)
state, once; :func:`chain_call` (numba) is one call over them: node motion, the stage forces (each
law called by its compiled address, :mod:`contactdyn.laws.abi`), the loads, the energy audit's damper
power and the bond's γ. A stage whose law numba cannot compile is computed in Python between
:func:`chain_motion` and :func:`chain_loads`, the two halves of the call. :func:`chain_forces` packs,
calls and names the outputs (an impact's bond rows, :mod:`contactdyn.model.constraints`); the one
pipeline (:mod:`contactdyn.model.pipeline.contacts`) calls :func:`chain_call` over the same packed arrays: one
description of the law. Under ``NUMBA_DISABLE_JIT=1`` the same functions run interpreted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SimulationError
from ..laws.abi import call_stage, stage_address
from ..numerics.compile_cache import njit
from ..numerics.linalg import dot3
from ..numerics.twins import current
from .chain import NodeKind
from .contact import Contact, DirectionalChain, Kinematics

__all__ = ["chain_forces", "chain_axis", "chain_sides", "ChainArrays", "pack", "chain_call", "chain_motion",
           "chain_loads", "coordinate_row", "orient", "relative_sides"]

TIP, ANCHOR = int(NodeKind.TIP), int(NodeKind.ANCHOR)

#: the plan's header (int64): constants, then where each section starts (a section: its row count, its rows)
(H_NQ, H_ENERGY, H_COORDS, H_BOND, H_INTERFACE, H_ROBOT_SURFACE, H_ENV_SURFACE, H_ROBOT_KIND, H_ENV_KIND,
 H_SOLID, H_ALIASES_BEFORE, H_JUNCTIONS, H_ALIASES_AFTER, H_FREE_ENDS, H_ACTIVE, HEADER) = range(16)
#: the sections' rows: body coordinates (coordinate, the side it carries: ON_TIP or ON_ANCHOR, its u·axis in
#: ``consts[K_UA + slot]``: slot), solid (node, kind, coordinate), alias (node, node it follows), free end (node,
#: node it rests on, its state slot or -1), active (stage); a junction is (node, slot, algebraic, n) then n
#: (stage, below)
COORD_ROW, SOLID_ROW, ALIAS_ROW, FREE_END_ROW, JUNCTION_ROW, JUNCTION_STAGE_ROW = 3, 3, 2, 3, 4, 2
#: a stage's ints: its nodes, its law's address (0: Python), its parameters in ``consts``, where its force acts
S_LOWER, S_UPPER, S_LAW, S_PARAMS_AT, S_N_PARAMS, S_UPPER_ON, S_LOWER_ON = range(7)
ON_NOTHING, ON_TIP, ON_ANCHOR = -1, -2, -3  #: where a stage's force acts (a mass: its coordinate, >= 0)
#: a stage's coefficients: k [N/m], b [N·s/m]; (K, B) of an affine law, F = K x + B ẋ (nan for another)
C_K, C_B, C_KA, C_BA = range(4)
#: ``consts``: u (3), u·axis [-] of the touching body's coordinates (3 slots) and the surface body's (3), Baumgarte's
#: ω [1/s], then the stages' law parameters
K_U, K_UA, K_OMEGA, K_PARAMS = 0, 3, 9, 10
#: a stage's state at the last call: compression x [m], rate ẋ [m/s], force F [N], F at ẋ = 0 [N]
X, XDOT, F, F_ELASTIC = range(4)


@dataclass
class ChainArrays:
    """One chain's plan in one (touching, relaxing) state as flat arrays, with its buffers and names."""

    plan: np.ndarray  #: int64: the header, then the sections
    stages: np.ndarray  #: int64 (stages, 7)
    coef: np.ndarray  #: float (stages, 4)
    consts: np.ndarray  #: float: u, u·axis, ω, law parameters
    motion: np.ndarray  #: float (2, nodes): positions [m] and velocities [m/s] of the nodes at the last call
    stage_state: np.ndarray  #: float (stages, 4): x, ẋ, F, F at ẋ = 0 at the last call
    active: list[int]  #: stages carrying force
    python_stages: list  #: (stage index, ChainStage) of the active stages whose law numba cannot compile
    labels: list[str]  #: "<contact>.<direction>.<stage>" per stage (``Evaluation.stages``)
    bond: bool


def pack(system, c: Contact, dc: DirectionalChain, touching: bool, relaxing: bool) -> ChainArrays:
    """The arrays of ``dc``'s plan touching or not, its damped ends relaxing or not (once per state)."""
    plan = dc.plan(touching, relaxing)
    chain = dc.chain
    nodes, stages = chain.nodes, chain.stages
    junction_rows = [len(plan.junctions)]
    for j, active, slot, group, algebraic in plan.junctions:
        junction_rows += [j, slot, int(algebraic), len(active)]
        for k in active:
            junction_rows += [k, int(stages[k].upper in group)]  # below j: the stage pushes j up
    sides = ((c.touch_coords, ON_TIP, 0), (c.surface_coords, ON_ANCHOR, 3))
    ua = np.zeros(6)
    coords = []
    for side, on, first in sides:
        for k, (i, axis) in enumerate(side):
            ua[first + k] = float(dc.u @ axis)
            coords.append((i, on, first + k))
    sections = {
        H_COORDS: _section(coords),
        H_SOLID: _section([(i, int(nodes[i].kind), nodes[i].coord) for i in plan.solid]),
        H_ALIASES_BEFORE: _section([(a, b) for a, b in plan.aliases if b not in plan.junction_nodes]),
        H_JUNCTIONS: junction_rows,
        H_ALIASES_AFTER: _section([(a, b) for a, b in plan.aliases if b in plan.junction_nodes]),
        H_FREE_ENDS: _section([(a, b, nodes[a].state) for a, b in plan.free_ends]),
        H_ACTIVE: _section([(k,) for k in plan.active]),
    }
    header = [0] * HEADER
    header[H_NQ], header[H_ENERGY] = system.nQ, system.energy_slot
    header[H_BOND], header[H_INTERFACE] = int(plan.bond), plan.interface_stage
    header[H_ROBOT_SURFACE], header[H_ENV_SURFACE] = chain.robot_surface, chain.env_surface
    header[H_ROBOT_KIND], header[H_ENV_KIND] = int(nodes[chain.robot_surface].kind), int(nodes[chain.env_surface].kind)
    body: list[int] = []
    for h, rows in sections.items():
        header[h] = HEADER + len(body)
        body += rows
    stage_ints, coef, params = _stage_tables(nodes, stages, dict(plan.aliases))
    consts = np.array([*dc.u, *ua, system.stabilization, *params], dtype=float)
    python_stages = [(k, stages[k]) for k in plan.active if stage_ints[k, S_LAW] == 0]
    return ChainArrays(np.array(header + body, dtype=np.int64), stage_ints, coef, consts,
                       np.zeros((2, len(nodes))), np.zeros((len(stages), 4)), list(plan.active), python_stages,
                       [f"{c.name}.{dc.label}.{s.label}" for s in stages], plan.bond)


def _section(rows: list[tuple[int, ...]]) -> list[int]:
    return [len(rows)] + [v for row in rows for v in row]


def _stage_tables(nodes, stages, alias_of: dict[int, int]) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """(the stages' ints, their coefficients, their laws' parameters in a row)."""
    ints = np.zeros((len(stages), 7), dtype=np.int64)
    coef = np.full((len(stages), 4), np.nan)
    params: list[float] = []

    def acts_on(node: int) -> int:
        target = alias_of.get(node, node)  # a free surface node merged into what it touches
        kind = nodes[target].kind
        return ON_TIP if kind == NodeKind.TIP else ON_ANCHOR if kind == NodeKind.ANCHOR else \
            nodes[target].coord if kind == NodeKind.MASS else ON_NOTHING

    for k, s in enumerate(stages):
        ints[k] = (s.lower, s.upper, stage_address(s.law_class), K_PARAMS + len(params), len(s.params),
                   acts_on(s.upper), acts_on(s.lower))
        coef[k, C_K], coef[k, C_B] = s.k, s.b
        if s.kelvin_voigt is not None:
            coef[k, C_KA], coef[k, C_BA] = s.kelvin_voigt
        params += s.params
    return ints, coef, params


def chain_forces(system, c: Contact, dc: DirectionalChain, touching: bool, offset: float, kin: Kinematics,
                 x: np.ndarray, f: np.ndarray, ydot: np.ndarray):
    """Apply a chain's stage forces; return (tip force along u [N], bond row or None, γ, interface F, gap).

    Adds the stages' forces on masses and the bodies' coordinates to ``f`` [N], junction rates and the
    energy audit's damper power to ``ydot``. ``offset`` [m] shifts the anchor (tangential chains anchored at touch).
    (The impulse level's rows, :func:`contactdyn.model.constraints.velocity_rows`; the call's chains are
    :mod:`contactdyn.model.pipeline.contacts`'.)
    """
    key = (touching, False)
    a = dc.arrays.get(key)
    if a is None:
        a = dc.arrays[key] = pack(system, c, dc, touching, key[1])
    u, p_tip, v_tip, p_env, v_env = chain_sides(c, dc, kin)
    if c.turning:  # (each numba function here called as current() gives it: its twin in an interpreted run)
        current(orient)(a.plan, a.consts, u, c.touch_axes)
    if a.python_stages:
        current(chain_motion)(a.plan, a.stages, a.coef, a.consts, x, p_tip, v_tip, p_env, v_env, float(offset), ydot,
                              a.motion, a.stage_state)
        _python_forces(a, system.energy_slot >= 0)
        tip_F, gamma, interface_F, gap = current(chain_loads)(a.plan, a.stages, a.consts, kin.drift, f, ydot,
                                                              a.motion, a.stage_state)
    else:
        call = current(chain_call)
        tip_F, gamma, interface_F, gap, finite = call(a.plan, a.stages, a.coef, a.consts, x, p_tip, v_tip, p_env, v_env,
                                                      kin.drift, float(offset), f, ydot, a.motion, a.stage_state)
        if not finite:  # a compiled law raised (its call gives NaN) or gave NaN
            _law_error(a, dc)
    row = _bond_row(system, c, dc, kin, u) if a.bond else None
    return tip_F, row, gamma, interface_F, (0.0 if touching else gap)


def chain_axis(c: Contact, dc: DirectionalChain, kin: Kinematics) -> np.ndarray:
    """The unit direction [-] the chain runs along at this state: its own, or on a turning surface the state's
    normal or tangent."""
    if not c.turning:
        return dc.u
    return kin.normal if dc is c.normal else kin.tangents[c.tangent_chains.index(dc)]


def chain_sides(c: Contact, dc: DirectionalChain, kin: Kinematics):
    """(u, p_tip [m], v_tip [m/s], p_env, v_env) a chain reads at this state: its direction (:func:`chain_axis`) and
    its two sides; on a turning surface measured from the surface (:func:`relative_sides`; a rigid bond's gap is
    the same either way: its rounding kept as it was)."""
    u = chain_axis(c, dc, kin)
    if c.turning and dc.chain.stages:
        return (u, *relative_sides(kin.p_tip, kin.v_tip, kin.p_env, kin.v_env))
    return u, kin.p_tip, kin.v_tip, kin.p_env, kin.v_env


def _law_error(a: ChainArrays, dc: DirectionalChain) -> None:
    """A stage whose compiled law gave no finite force: its Python law at the same (x, ẋ) raises the law's own
    error here; a law that gives NaN in Python too keeps it (as a Python law would); one that raised compiled
    only is an error that says so."""
    st = a.stage_state
    for k in a.active:
        if np.isfinite(st[k, F]):
            continue
        stage, xs, xd = dc.chain.stages[k], float(st[k, X]), float(st[k, XDOT])
        if np.isfinite(stage.force(xs, xd)):
            raise SimulationError(f"{a.labels[k]}: stage law {stage.law!r} failed in its compiled form at "
                                  f"x = {xs:.6g} m, ẋ = {xd:.6g} m/s (its Python form gives a force there): "
                                  "an index past an array's end, or an operation numba treats otherwise")


def _python_forces(a: ChainArrays, energy: bool) -> None:
    """The forces of the stages whose law numba cannot compile, by their Python function."""
    st = a.stage_state
    for k, stage in a.python_stages:
        xs, xd = float(st[k, X]), float(st[k, XDOT])
        st[k, F] = stage.force(xs, xd)
        if energy:
            st[k, F_ELASTIC] = stage.force(xs, 0.0)


def _bond_row(system, c: Contact, dc: DirectionalChain, kin: Kinematics, u: np.ndarray) -> np.ndarray:
    """Row of the two surfaces' relative motion along u (the chain's, or a turning surface's normal at this state;
    its γ is :func:`chain_loads`')."""
    nQ, chain = system.nQ, dc.chain
    nodes = chain.nodes
    row = np.zeros(nQ)
    for node, sign in ((chain.robot_surface, 1.0), (chain.env_surface, -1.0)):
        kind = nodes[node].kind
        if kind == NodeKind.TIP:
            row[: system.nv] += sign * (u @ kin.J)
            for i, axis in c.touch_coords:
                row[i] += sign * float(u @ axis)
            for i, col in kin.columns:  # an articulated side's (the relative motion's columns)
                row[i] += sign * float(u @ col)
        elif kind == NodeKind.ANCHOR:
            for i, axis in c.surface_coords:
                row[i] += sign * float(u @ axis)
        else:
            row[nodes[node].coord] += sign
    return row


# ---- one call over the arrays (numba) ----------------------------------------------------------------------------

@njit(cache=True)
def relative_sides(p_tip, v_tip, p_env, v_env):
    """A chain on a turning surface measures its nodes from the surface: (p_tip − p_env [m], v_tip − v_env [m/s],
    zeros, zeros). Along the state's normal n, n·(p_tip − p_env) is the gap and n·(v_tip − v_env) its rate exactly
    (v_env is the velocity of the material point under the tip, :func:`~contactdyn.model.contact.turning_surface`),
    so the junctions' states are deformations, not positions that the turning n would shift."""
    return p_tip - p_env, v_tip - v_env, np.zeros(3), np.zeros(3)


@njit(cache=True)
def orient(plan, consts, u, touch_axes):
    """Point a packed chain along the unit direction u (on a turning surface: its normal or tangent at this state):
    u into ``consts`` and u·axis [-] of the touching body's coordinates (``touch_axes`` (k, 3), the plan's H_COORDS
    rows on the tip; a turning surface's carrier has no translating coordinates of its own)."""
    for i in range(3):
        consts[K_U + i] = u[i]
    for r in range(plan[plan[H_COORDS]]):
        _, on, slot = coordinate_row(plan, r)
        if on == ON_TIP:
            consts[K_UA + slot] = dot3(u, touch_axes[slot])


@njit(cache=True)
def chain_call(plan, stages, coef, consts, x, p_tip, v_tip, p_env, v_env, drift, offset, f, ydot, motion,
               stage_state):
    """One call of a chain whose laws all compile: :func:`chain_motion`, then :func:`chain_loads`; with
    (tip F, γ, interface F, gap), whether every active stage's force is finite (a law that raised gives NaN)."""
    chain_motion(plan, stages, coef, consts, x, p_tip, v_tip, p_env, v_env, offset, ydot, motion, stage_state)
    tip_F, gamma, interface_F, gap = chain_loads(plan, stages, consts, drift, f, ydot, motion, stage_state)
    return tip_F, gamma, interface_F, gap, _forces_finite(plan, stage_state)


@njit(cache=True, inline="always")
def _forces_finite(plan, stage_state):
    """Every active stage's force F [N] is finite."""
    at = plan[H_ACTIVE]
    for r in range(plan[at]):
        if not np.isfinite(stage_state[plan[at + 1 + r], F]):
            return False
    return True


@njit(cache=True)
def chain_motion(plan, stages, coef, consts, x, p_tip, v_tip, p_env, v_env, offset, ydot, motion, stage_state):
    """The nodes' positions [m] and velocities [m/s] along u into ``motion``, the junctions' rates into ``ydot``,
    each active stage's (x, ẋ) and, for the laws that compile, F (and F at ẋ = 0) into ``stage_state``.

    The tip and the anchor move with the robot's frame and the environment's point (p, ṗ [m, m/s], world),
    the anchor shifted by ``offset`` [m]; masses are coordinates of x = [Q, Q̇, y].
    """
    u = consts[K_U:K_U + 3]
    pos, vel = motion[0], motion[1]
    _solid_nodes(plan, x, dot3(u, p_tip), dot3(u, v_tip), dot3(u, p_env) + offset, dot3(u, v_env), pos, vel)
    _aliases(plan, plan[H_ALIASES_BEFORE], pos, vel)
    _junctions(plan, stages, coef, x, ydot, pos, vel)
    _aliases(plan, plan[H_ALIASES_AFTER], pos, vel)
    _free_ends(plan, ydot, pos, vel)
    _stage_forces(plan, stages, coef, consts, pos, vel, stage_state)


@njit(cache=True)
def _solid_nodes(plan, x, s_tip, v_tip, s_anc, v_anc, pos, vel):
    """Tip, anchor and masses: positions [m] and velocities [m/s] along u."""
    nQ = plan[H_NQ]
    at = plan[H_SOLID]
    for r in range(plan[at]):
        row = at + 1 + SOLID_ROW * r
        node, kind, coord = plan[row], plan[row + 1], plan[row + 2]
        if kind == TIP:
            pos[node], vel[node] = s_tip, v_tip
        elif kind == ANCHOR:
            pos[node], vel[node] = s_anc, v_anc
        else:
            pos[node], vel[node] = x[coord], x[nQ + coord]


@njit(cache=True)
def _aliases(plan, at, pos, vel):
    """Free surface nodes merged into what they touch move with it (the section of aliases at ``at``)."""
    for r in range(plan[at]):
        row = at + 1 + ALIAS_ROW * r
        a, b = plan[row], plan[row + 1]
        pos[a], vel[a] = pos[b], vel[b]


@njit(cache=True)
def _junctions(plan, stages, coef, x, ydot, pos, vel):
    """Massless junctions: a damped one is a state whose rate balances its stages (into ``ydot``); an undamped
    or balanced one sits where its springs balance, its state slot (if any) following it."""
    y0 = 2 * plan[H_NQ]
    at = plan[H_JUNCTIONS]
    row = at + 1
    for _ in range(plan[at]):
        j, slot, algebraic, n = plan[row], plan[row + 1], plan[row + 2], plan[row + 3]
        first = row + JUNCTION_ROW
        row = first + JUNCTION_STAGE_ROW * n
        y_j = x[y0 + slot] if slot >= 0 else 0.0
        num = den = kk = ks = 0.0
        for r in range(n):
            k, below = plan[first + JUNCTION_STAGE_ROW * r], plan[first + JUNCTION_STAGE_ROW * r + 1]
            K, B = coef[k, C_KA], coef[k, C_BA]  # a junction joins affine stages only (chain._check)
            lower, upper = stages[k, S_LOWER], stages[k, S_UPPER]
            if below:  # stage below pushes j up
                num += K * (pos[lower] - y_j) + B * vel[lower]
                ks += K * pos[lower]
            else:  # stage above pushes j down
                num -= K * (y_j - pos[upper]) - B * vel[upper]
                ks += K * pos[upper]
            den += B
            kk += K
        if den > 0.0 and not algebraic:
            pos[j], vel[j] = x[y0 + slot], num / den
            ydot[slot] = vel[j]
        else:  # undamped or balanced junction: algebraic force balance
            pos[j] = ks / kk if kk > 0 else 0.0
            v = 0.0
            for r in range(n):
                k, below = plan[first + JUNCTION_STAGE_ROW * r], plan[first + JUNCTION_STAGE_ROW * r + 1]
                v += coef[k, C_KA] * vel[stages[k, S_LOWER] if below else stages[k, S_UPPER]]
            vel[j] = v / kk if kk > 0 else 0.0
            if den > 0.0 and slot >= 0:  # its slot of y follows it, ready for a mode that needs it as a state
                ydot[slot] = vel[j]


@njit(cache=True)
def _free_ends(plan, ydot, pos, vel):
    """A free end rests on its stage's other node (a massless stage carries no force unloaded); its slot of y,
    if it has one, follows it: its position stays ready for relaxing after a separation, with no stiff term."""
    at = plan[H_FREE_ENDS]
    for r in range(plan[at]):
        row = at + 1 + FREE_END_ROW * r
        a, b, slot = plan[row], plan[row + 1], plan[row + 2]
        pos[a], vel[a] = pos[b], vel[b]
        if slot >= 0:
            ydot[slot] = vel[a]


@njit(cache=True)
def _stage_forces(plan, stages, coef, consts, pos, vel, stage_state):
    """Each active stage's compression x [m] and rate ẋ [m/s]; its force F [N] by its law's address (and F at
    ẋ = 0, the elastic part, for the energy audit); a stage of address 0 is left to Python."""
    energy = plan[H_ENERGY] >= 0
    at = plan[H_ACTIVE]
    for r in range(plan[at]):
        k = plan[at + 1 + r]
        xs = pos[stages[k, S_LOWER]] - pos[stages[k, S_UPPER]]
        xd = vel[stages[k, S_LOWER]] - vel[stages[k, S_UPPER]]
        stage_state[k, X], stage_state[k, XDOT] = xs, xd
        law, p_at, n_p = stages[k, S_LAW], stages[k, S_PARAMS_AT], stages[k, S_N_PARAMS]
        if law != 0:
            stage_state[k, F] = call_stage(law, coef[k, C_K], coef[k, C_B], consts, p_at, n_p, xs, xd)
            if energy:
                stage_state[k, F_ELASTIC] = call_stage(law, coef[k, C_K], coef[k, C_B], consts, p_at, n_p, xs, 0.0)


@njit(cache=True)
def chain_loads(plan, stages, consts, drift, f, ydot, motion, stage_state):
    """The active stages' forces on the tip, the anchor and the masses (into ``f`` [N]; the tip's and the anchor's on
    the bodies' coordinates that carry them, H_COORDS),
    the dampers' power [W] (into ``ydot``'s audit slot); (tip force along u [N], bond γ [m/s²], interface F [N],
    gap [m]). γ is the surfaces' J̇q̇ along u (``drift`` [m/s²], the tip's) plus Baumgarte's 2ω ė + ω² e."""
    energy = plan[H_ENERGY]
    interface = plan[H_INTERFACE]
    tip_F = anchor_F = interface_F = 0.0
    at = plan[H_ACTIVE]
    for r in range(plan[at]):
        k = plan[at + 1 + r]
        force = stage_state[k, F]
        if k == interface:
            interface_F = force
        tip_F, anchor_F = _act(stages[k, S_UPPER_ON], 1.0 * force, tip_F, anchor_F, f)
        tip_F, anchor_F = _act(stages[k, S_LOWER_ON], -1.0 * force, tip_F, anchor_F, f)
        if energy >= 0:
            ydot[energy + 1] += (force - stage_state[k, F_ELASTIC]) * stage_state[k, XDOT]  # damper power [W]
    for r in range(plan[plan[H_COORDS]]):  # the bodies' coordinates carrying the tip (a touching body) or the anchor
        i, on, slot = coordinate_row(plan, r)
        force = tip_F if on == ON_TIP else anchor_F
        if force != 0.0:
            f[i] += force * consts[K_UA + slot]
    pos, vel = motion[0], motion[1]
    rs, es = plan[H_ROBOT_SURFACE], plan[H_ENV_SURFACE]
    gap = pos[rs] - pos[es]
    gamma = 0.0
    if plan[H_BOND]:
        u = consts[K_U:K_U + 3]
        if plan[H_ROBOT_KIND] == TIP:
            gamma += 1.0 * dot3(u, drift)
        if plan[H_ENV_KIND] == TIP:
            gamma += -1.0 * dot3(u, drift)
        w = consts[K_OMEGA]  # Baumgarte: the violation e obeys ë + 2ω ė + ω² e = 0, zero on the exact manifold
        gamma += 2.0 * w * (vel[rs] - vel[es]) + w * w * gap
    return tip_F, gamma, interface_F, gap


@njit(cache=True)
def coordinate_row(plan, r):
    """Row r of the plan's H_COORDS section: (a body coordinate, the node it carries: ON_TIP or ON_ANCHOR, the slot
    of its u·axis in the chain's constants, K_UA + slot)."""
    at = plan[H_COORDS] + 1 + COORD_ROW * r
    return plan[at], plan[at + 1], plan[at + 2]


@njit(cache=True)
def _act(on, force, tip_F, anchor_F, f):
    """A stage's force [N] on one of its nodes: summed on the tip or the anchor, or into a mass's ``f``."""
    if on == ON_TIP:
        tip_F += force
    elif on == ON_ANCHOR:
        anchor_F += force
    elif on >= 0:
        f[on] += force
    return tip_F, anchor_F
