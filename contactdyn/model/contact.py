"""A contact interface: a robot frame meeting an environment point, one model per direction.

Along the normal a :class:`~contactdyn.model.chain.Chain` (rigid when empty); along the
tangential directions nothing (``free``), Coulomb friction, or a chain per direction that
bonds at touch (case 1's horizontal deformations). A contact's *mode* says whether it
touches and, with friction, whether it sticks or in which direction it slides (and, after a
separation, that its chains' damped ends relax); the mode only changes at located events
(:mod:`contactdyn.hybrid.events`, :mod:`contactdyn.hybrid.transitions`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..numerics.compile_cache import njit
from ..numerics.linalg import contiguous, cross3
from ..robot.robot import FrameTerms
from ..scene.scene_file import ContactSpec
from .chain import Chain, NodeKind, balanced, build_chain

__all__ = ["Contact", "ContactMode", "ChainPlan", "Kinematics", "RidingMass", "riding_masses", "riding_terms",
           "riding_point", "structure", "turning_surface"]

ANY_2D = (0.0, 0.0)  #: a 2-D reference direction in a mode's :func:`structure`: never a real one


@dataclass(frozen=True)
class ContactMode:
    """What a contact is doing during a smooth phase."""

    touching: bool = False
    stuck: bool = False
    #: sliding direction in tangent coordinates, fixed for the phase (1-D: ±1);
    #: 2-D sliding uses the state's own slip direction, this is only its reference.
    slip: tuple[float, ...] = ()
    #: anchor offsets of the tangential chains [m], captured at touch
    offsets: tuple[float, ...] = ()
    #: the slide started from rest (2-D: until the slip leaves the stick band its direction is
    #: the consistent one, where the slip accelerates, rather than the fixed reference)
    from_rest: bool = False
    #: not touching since a separation: the chains' damped surface ends relax from the deformation
    #: they had (first-order states, rate 1/τ = k/b). Else (chains start undeformed, a touch ends it)
    #: they sit at zero compression and follow their stages' other nodes: no state to integrate.
    relaxing: bool = False

    def with_(self, **changes) -> ContactMode:
        return replace(self, **changes)

    def separated(self) -> ContactMode:
        """The mode after the contact lets go: not touching, not stuck, its damped chain ends relaxing."""
        return replace(self, touching=False, stuck=False, relaxing=True)


def structure(modes) -> tuple[ContactMode, ...]:
    """What shapes a mode's compiled call: the modes with each 2-D reference direction r blanked. r is data the
    call reads: a ``turn`` event refreshes it without packing the mode again."""
    return tuple(m.with_(slip=ANY_2D) if len(m.slip) == 2 else m for m in modes)


@dataclass
class Kinematics:
    """Tip and environment point kinematics of one contact at one state (world frame).

    On a surface carried by a robot frame (:func:`turning_surface`) ``J`` and ``drift`` are the relative motion's
    (touching point − the surface's material point under it), ``v_env`` that material point's velocity; the robot's
    part of a row along u is then u J, its γ u·drift, for any direction u."""

    p_tip: np.ndarray  #: [m]
    v_tip: np.ndarray  #: [m/s]
    J: np.ndarray  #: (3, nv)
    drift: np.ndarray  #: J̇q̇ [m/s²]
    p_env: np.ndarray  #: [m]
    v_env: np.ndarray  #: [m/s]
    frame: FrameTerms | None = None  #: the tip frame's full terms (orientation, angular Jacobian)
    normal: np.ndarray | None = None  #: the world normal n at this state (unit)
    tangents: np.ndarray | None = None  #: (k, 3) the world tangents T at this state (unit)
    #: per coordinate of a body with revolute joints on either side: (its index in Q, the relative motion's
    #: (touching − surface) column at this state [m/rad or m/m]); the translating bodies' constant axes are the
    #: Contact's (:meth:`Contact.add_columns`), their J̇q̇ part in ``drift``
    columns: tuple = ()

    @property
    def gap(self) -> float:
        """[m] n·(p_tip − p_env): the touching point's height over the undeformed surface (< 0: pressed in)."""
        return float(self.normal @ (self.p_tip - self.p_env))

    def add_columns(self, rows: np.ndarray, U: np.ndarray) -> None:
        """Add to ``rows`` (k, nQ) the articulated bodies' part of the relative motion along U (k, 3) [m/m]."""
        for i, col in self.columns:
            rows[:, i] += U @ col

    def column_rates(self, qd: np.ndarray) -> np.ndarray:
        """The articulated bodies' part of the relative velocity [m/s] at coordinate rates ``qd`` (Q̇; Q̈ for the
        accelerations [m/s²], their J̇q̇ being in ``drift``)."""
        v = np.zeros(3)
        for i, col in self.columns:
            v = v + col * qd[i]
        return v


@dataclass
class ChainPlan:
    """How to evaluate one chain in one touching state (compiled once per state)."""

    solid: list[int]
    aliases: list[tuple[int, int]]  #: (free node, node it follows)
    #: (node, active neighbour stages, state index or -1, nodes merged into it, algebraic: it sits where
    #: its springs balance, its state (if any) only following it)
    junctions: list[tuple[int, list[int], int, frozenset[int], bool]]
    free_ends: list[tuple[int, int]]  #: (free node, node it rests on)
    active: list[int]  #: stages carrying force
    bond: bool
    interface_stage: int  #: stage whose force is the interface force (-1: bond or none)
    junction_nodes: frozenset[int]  #: the nodes of ``junctions`` (a membership test per evaluation)


def _plan(chain: Chain, touching: bool, junction_state: int, relaxing: bool) -> ChainPlan:
    nodes, stages = chain.nodes, chain.stages
    solid = [i for i, n in enumerate(nodes) if n.kind != NodeKind.FREE]
    aliases: list[tuple[int, int]] = []
    junction_nodes: list[int] = []
    es, rs = chain.env_surface, chain.robot_surface
    if touching:
        e_free, r_free = nodes[es].kind == NodeKind.FREE, nodes[rs].kind == NodeKind.FREE
        if e_free and not r_free:
            aliases.append((es, rs))
        elif r_free and not e_free:
            aliases.append((rs, es))
        elif e_free and r_free:
            junction_nodes.append(es)
            aliases.append((rs, es))
    aliased = {a for a, _ in aliases}
    interior = [i for i, n in enumerate(nodes)
                if n.kind == NodeKind.FREE and len(chain.stages_of(i)) == 2 and i not in aliased]
    junction_nodes += [i for i in interior if i not in junction_nodes]
    if not touching and relaxing:  # damped surface ends relax on their own: k x + b ẋ = 0
        junction_nodes += [i for i in (es, rs) if nodes[i].kind == NodeKind.FREE and nodes[i].state >= 0
                           and i not in junction_nodes]
    # a node is "loaded" when its position is determined by something other than its stage
    loaded = set(solid) | aliased | set(junction_nodes)
    free_ends = []
    for i, n in enumerate(nodes):
        if n.kind == NodeKind.FREE and i not in loaded:
            (s,) = chain.stages_of(i)
            other = stages[s].lower if stages[s].upper == i else stages[s].upper
            free_ends.append((i, other))
    free_set = {i for i, _ in free_ends}
    active = [k for k, s in enumerate(stages) if s.lower not in free_set and s.upper not in free_set]
    junctions = []
    for j in junction_nodes:
        group = {j} | {a for a, b in aliases if b == j}  # the interface junction is both surface nodes
        stages_j = sorted({k for n in group for k in chain.stages_of(n) if k in active})
        slot = junction_state if touching and j in (es, rs) else nodes[j].state
        algebraic = slot < 0 or (len(stages_j) > 1 and balanced([stages[k] for k in stages_j]))
        junctions.append((j, stages_j, slot, frozenset(group), algebraic))
    bond = touching and chain.bonded_when_touching
    interface_stage = -1
    if touching and not bond:  # the stage that meets the other side carries the interface force
        if nodes[es].kind == NodeKind.FREE:
            interface_stage = next(k for k, s in enumerate(stages) if s.upper == es)
        else:
            interface_stage = next(k for k, s in enumerate(stages) if s.lower == rs)
    return ChainPlan(solid, aliases, junctions, free_ends, active, bond, interface_stage, frozenset(junction_nodes))


@dataclass
class DirectionalChain:
    """A chain placed along a world direction u of a contact."""

    chain: Chain
    u: np.ndarray
    label: str  #: "n", "t1", "t2"
    junction_state: int = -1  #: state slot of the interface junction (when touching), set by the system
    plans: dict[tuple[bool, bool], ChainPlan] = field(default_factory=dict)
    #: the plans as flat arrays, what a call reads (:func:`contactdyn.model.chain_forces.pack`), by the same key
    arrays: dict[tuple[bool, bool], object] = field(default_factory=dict)

    def __getstate__(self) -> dict:
        """Pickled (or copied) without its packed arrays: they hold laws' machine addresses, valid in this
        process only; a call packs them again."""
        return {**self.__dict__, "arrays": {}}

    def plan(self, touching: bool, relaxing: bool = False) -> ChainPlan:
        """How to evaluate the chain touching or not, with its damped ends relaxing (see ContactMode)."""
        key = (touching, relaxing and not touching)
        if key not in self.plans:
            self.plans[key] = _plan(self.chain, touching, self.junction_state, key[1])
        return self.plans[key]


class Contact:
    """Runtime of one contact interface; the system gives it coordinates and state slots.

    Its two sides: the touching one, a robot frame (``fid``) or a body's point (``fid`` −1, the spec's
    ``frame_point``), and the surface, the ground or a body. An articulated body's side (``touch_link``,
    ``surface_link``) moves by its joints, its columns the state's (:attr:`Kinematics.columns`). A translating body
    side moves by its coordinates:
    ``touch_coords`` and ``surface_coords`` list each (index in Q, unit axis), so a point of it is its place at
    the coordinates 0 plus Σ axis Q [m]."""

    def __init__(self, spec: ContactSpec, fid: int, touch_coords: list, surface_coords: list, surface_fid: int = -1,
                 touch_link: tuple | None = None, surface_link: tuple | None = None):
        self.spec = spec
        #: (ArticulatedBody, its frame id) whose point ``frame_point`` touches (``body_frame``), or None
        self.touch_link = touch_link
        #: (ArticulatedBody, its frame id) carrying the surface (``surface_frame`` on such a body), or None
        self.surface_link = surface_link
        self.name = spec.name
        self.fid = fid
        #: the robot frame carrying the surface (``body = "robot"``: point, normal, tangents in its coordinates); -1
        self.surface_fid = surface_fid
        self.touch_coords = tuple(touch_coords)  #: the touching body's (coordinate, axis); () for a robot frame
        #: (k, 3) the touching body's axes [-], in touch_coords' order (what a chain on a turning surface reorients)
        self.touch_axes = np.array([axis for _, axis in self.touch_coords], float).reshape(-1, 3)
        self.surface_coords = tuple(surface_coords)  #: the surface body's (coordinate, axis); () for the ground
        where = f"contact.{spec.name}"
        self.normal = DirectionalChain(build_chain(spec.normal_chain, f"{where}.normal"), spec.normal, "n")
        self.tangent_chains: list[DirectionalChain] = []
        if spec.tangent_chain is not None:
            for i, t in enumerate(spec.tangents):
                self.tangent_chains.append(
                    DirectionalChain(build_chain(spec.tangent_chain, f"{where}.tangent"), t, f"t{i + 1}")
                )
        self.friction = spec.friction
        self.tangents = spec.tangents

    @property
    def chains(self) -> list[DirectionalChain]:
        return [self.normal, *self.tangent_chains]

    @property
    def turning(self) -> bool:
        """Its surface turns: carried by a robot frame or an articulated body's (its directions the state's)."""
        return self.surface_fid >= 0 or self.surface_link is not None

    def relaxation_time(self, mode: ContactMode) -> float:
        """[s] The shortest time constant b / k of the damped ends relaxing in this mode (inf: none)."""
        taus = []
        for dc in self.chains:
            for j, _, slot, _, algebraic in dc.plan(mode.touching, mode.relaxing).junctions:
                if slot >= 0 and not algebraic:  # a junction integrated as a state
                    stages = (dc.chain.stages[k] for k in dc.chain.stages_of(j))
                    kvs = (s.kelvin_voigt for s in stages)  # (K, B): a junction joins affine stages only
                    taus += [B / K for K, B in kvs if K > 0.0]
        return min(taus, default=math.inf)

    def surface(self, x: np.ndarray, nQ: int) -> tuple[np.ndarray, np.ndarray]:
        """(p_env [m], v_env [m/s]): the contact point on the environment, carried by its body if any."""
        return _carried(self.spec.point, self.surface_coords, x, nQ)

    def toucher(self, x: np.ndarray, nQ: int) -> tuple[np.ndarray, np.ndarray]:
        """(p [m], v [m/s]) of a touching body's point (``fid`` −1)."""
        return _carried(self.spec.frame_point, self.touch_coords, x, nQ)

    def add_columns(self, rows: np.ndarray, U: np.ndarray) -> None:
        """Add to ``rows`` (k, nQ) the body coordinates' part of the relative motion (touching side − surface) along
        the unit directions U (k, 3) [m/m] (the robot's part is U J)."""
        for coords, sign in ((self.touch_coords, 1.0), (self.surface_coords, -1.0)):
            for i, axis in coords:
                rows[:, i] += sign * (U @ axis)

    def rates(self, qd: np.ndarray) -> tuple[np.ndarray | None, np.ndarray]:
        """(the touching body's point's velocity or None, the surface point's) [m/s] at coordinate rates ``qd``
        (Q̇, or Q̈ for the accelerations [m/s²]: the axes are fixed)."""
        def moved(coords):
            v = np.zeros(3)
            for i, axis in coords:
                v = v + axis * qd[i]
            return v
        return (moved(self.touch_coords) if self.touch_coords else None), moved(self.surface_coords)


def _carried(point: np.ndarray, coords, x: np.ndarray, nQ: int) -> tuple[np.ndarray, np.ndarray]:
    """(p [m], v [m/s]) of a point that is ``point`` at the coordinates 0 and moves with ``coords``."""
    if not coords:
        return point, np.zeros(3)
    (i, axis), *more = coords
    p, v = point + axis * x[i], axis * x[nQ + i]
    for i, axis in more:
        p, v = p + axis * x[i], v + axis * x[nQ + i]
    return p, v


@njit(cache=True)
def turning_surface(p, v, J, a, o, v_o, J_o, a_o, R, w, J_w, alpha, p0, n0, T0):
    """The relative motion of a touching point on a surface carried by a robot frame (it moves and turns).

    In: the touching point p [m], v [m/s], its Jacobian J (3, nv) and J̇q̇ a [m/s²] (a body's point: zeros); the
    surface frame's origin o, v_o, linear Jacobian J_o, J̇_o q̇ a_o, rotation R, angular velocity ω = w [rad/s], its
    Jacobian J_w and J̇_w q̇ α = alpha [rad/s²] (world-aligned, as FrameTerms); the surface's point p0 [m], normal n0
    and tangents T0 (k, 3) in the frame's coordinates.
    Out: (J_rel (3, nv), a_rel [m/s²], p_s [m], v_m [m/s], n, T (k, 3)).

    World n = R n0, T = R T0, p_s = o + R p0. With r = p − o the material point under p moves with
    v_m = v_o + ω × r, and v_rel = v − v_m = J_rel q̇ (+ the bodies' coordinates' part), J_rel = J − J_o + [r]× J_ω
    (u·(ω × r) = (r × u)·ω, so a row along u is u J − u J_o − (r × u)·J_ω). The gap g = n·(p − p_s) has
    ġ = n·v_rel (ṅ·(p − p_s) = −n·(ω × (p − p_s)) completes v_m). Differentiating u·v_rel with q̈ = 0, u̇ = ω × u
    and ṙ = v − v_o:
        d/dt (u·v_rel) = (ω × u)·v_rel + u·(a − a_o − α × r − ω × (v − v_o))
                       = u·[a − (a_o + α × r + ω × (ω × r)) − 2 ω × v_rel] = u·a_rel,
    the material point's acceleration and Coriolis' term: one vector for every u, so the rows' γ are u·a_rel plus
    Baumgarte's terms as on a fixed surface (tests/test_tilt_tray.py checks it by finite differences).
    """
    nv = J.shape[1]
    r = p - o
    n, p_s = np.zeros(3), o.copy()
    T = np.zeros((T0.shape[0], 3))
    for i in range(3):
        for j in range(3):
            n[i] += R[i, j] * n0[j]
            p_s[i] += R[i, j] * p0[j]
            for k in range(T0.shape[0]):
                T[k, i] += R[i, j] * T0[k, j]
    v_m = v_o + cross3(w, r)
    v_rel = v - v_m
    a_rel = a - (a_o + cross3(alpha, r) + cross3(w, cross3(w, r))) - 2.0 * cross3(w, v_rel)
    J_rel = np.empty((3, nv))
    for c in range(nv):
        rxJ = cross3(r, J_w[:, c])  # [r]× J_ω's column c
        for i in range(3):
            J_rel[i, c] = J[i, c] - J_o[i, c] + rxJ[i]
    return J_rel, a_rel, p_s, v_m, n, T


@dataclass
class RidingMass:
    """A chain's equivalent mass on a turning surface (a chain of ``contact``): a point mass ``mass`` [kg] on the line
    through the surface's point along the chain's direction (the normal or a tangent, ``direction`` in the carrying
    frame), its place ξ [m] along it its coordinate ``coord`` in Q, as a prismatic joint of what carries the surface
    would be (the robot, or an articulated body: ``carrier``, their coordinates' indices in Q). A chain is one line,
    carried by its surface as a fixed surface's is by the world: its masses on either side ride it. Its kinetic
    energy is that of the point, ½ m |v|²: the coupling with the carrier is in M and f (:func:`riding_terms`, at the
    last state asked)."""

    contact: Contact
    coord: int
    mass: float
    direction: np.ndarray  #: the line's unit direction in the carrying frame [-]
    carrier: np.ndarray  #: the carrier's coordinates' indices in Q (the robot's joints, or the body's)
    J: np.ndarray = field(default_factory=lambda: np.zeros((3, 0)))  #: ∂p/∂(carrier) (3, k) [m/rad or m/m]
    drift: np.ndarray = field(default_factory=lambda: np.zeros(3))  #: the point's acceleration at Q̈ = 0 [m/s²]
    n: np.ndarray = field(default_factory=lambda: np.zeros(3))  #: the line's direction in the world, ∂p/∂ξ [-]

    def velocity(self, carrier_rates: np.ndarray, xi_dot: float) -> np.ndarray:
        """The point's velocity [m/s] at the carrier's rates [rad/s or m/s] and ξ̇ [m/s] (the last terms')."""
        return self.J @ carrier_rates + xi_dot * self.n


def riding_masses(contacts: list[Contact], nv: int) -> list[RidingMass]:
    """The masses of the chains on turning surfaces (a surface carried by a robot frame, its carrier the robot's nv
    joints, or by an articulated body, its coordinates)."""
    out = []
    for c in (c for c in contacts if c.turning):
        directions = [c.spec.normal, *c.spec.tangents[:len(c.tangent_chains)]]  # each chain's, in the frame
        body = c.surface_link[0] if c.surface_link is not None else None
        carrier = np.arange(body.first, body.first + body.nb) if body is not None else np.arange(nv)
        for dc, d in zip(c.chains, directions, strict=True):
            out += [RidingMass(c, node.coord, node.mass, d, carrier) for node in dc.chain.nodes
                    if node.kind == NodeKind.MASS]
    return out


def riding_terms(rm: RidingMass, frame: FrameTerms, w: np.ndarray, xi: float, xi_dot: float) -> None:
    """Set ``rm``'s terms at a state: the carrying frame's terms ``frame`` (Jacobians over the carrier's coordinates,
    ``rm.carrier``), its angular velocity ω = ``w`` [rad/s], the mass's ξ [m] and ξ̇ [m/s].

    With r = R p0 + ξ n from the frame's origin (p0 the surface's point, n = R d0 the line's direction, in the
    frame), the point fixed in the frame at r moving along n at ξ̇: v = v_o + ω × r + ξ̇ n, and at Q̈ = 0 its
    acceleration adds Coriolis' 2 ξ̇ ω × n (:func:`riding_point`, the compiled call's too)."""
    rm.J, rm.n, rm.drift = riding_point(contiguous(frame.jacobian), contiguous(frame.angular_jacobian), frame.drift,
                                        frame.angular_drift, contiguous(frame.rotation), w, rm.direction,
                                        rm.contact.spec.point, xi, xi_dot)


@njit(cache=True)
def riding_point(J_o, J_w, a_o, alpha, R, w, d0, p0, xi, xi_dot):
    """(J (3, k), n, drift [m/s²]) of a mass riding a frame's line (the frame's J_o, J_ω over k coordinates, its
    J̇q̇ = (a_o, α), rotation R, angular velocity ω = ``w`` [rad/s]; the line through p0 [m] along d0, both in the
    frame; the mass at ξ [m] on it, moving at ξ̇ [m/s]): n = R d0, r = R p0 + ξ n, J = J_o − [r]× J_ω (the point
    fixed in the frame at r), drift = a_o + α × r + ω × (ω × r) + 2 ξ̇ ω × n (its acceleration at Q̈ = 0, Coriolis'
    term included); one source for :func:`riding_terms` and the call's :func:`.pipeline.contacts.add_riding`."""
    n, r = np.zeros(3), np.zeros(3)
    for i in range(3):
        for j in range(3):
            n[i] += R[i, j] * d0[j]
    for i in range(3):
        for j in range(3):
            r[i] += R[i, j] * p0[j]
        r[i] += xi * n[i]
    J = np.empty((3, J_o.shape[1]))
    for c in range(J_o.shape[1]):
        rxJ = cross3(r, J_w[:, c])
        for i in range(3):
            J[i, c] = J_o[i, c] - rxJ[i]
    drift = a_o + cross3(alpha, r) + cross3(w, cross3(w, r)) + 2.0 * xi_dot * cross3(w, n)
    return J, n, drift
