"""A deformation chain's forces at one state: stages, junctions, the bond row and the gap.

Part I's contact-zone models (a), (b), (c) and their generalisations are chains of
Kelvin–Voigt stages and equivalent masses along one direction u (:mod:`contactdyn.model.chain`).
At a state x, with the chain's touching plan (:class:`~contactdyn.model.contact.ChainPlan`):

1. node motion: the tip and the anchor move with the robot and the environment body
   (s = u·p [m], ṡ = u·ṗ [m/s]); masses are coordinates of Q; a damped junction j is a
   first-order state whose rate balances its stages,
   Σ_below (k (s_lower − s_j) + b (ṡ_lower − ṡ_j)) = Σ_above (k (s_j − s_upper) + b (ṡ_j − ṡ_upper)),
   an undamped one, or one whose stages share a time constant b/k (:func:`~contactdyn.model.chain.balanced`),
   sits where its springs balance; a damped free end is a state only while it relaxes after a
   separation, else it follows its stage's other node;
2. stage forces F = k x + b ẋ [N] at compression x = s_lower − s_upper (or the
   Hunt–Crossley law) push the upper node along +u and the lower one back; their sums act
   on the tip (a Cartesian force along u), the masses and the environment body;
3. with both surface nodes solid and touching, the chain is *bonded*: a constraint row
   G Q̈ + γ = 0 on the two surfaces' relative motion, stabilised by Baumgarte,
   ë + 2ω ė + ω² e = 0 on the violation e (ω = ``solver.stabilization`` [1/s]).

The readable right-hand side (:mod:`contactdyn.model.dynamics`) and the compiled plan's probes
(:mod:`contactdyn.compiled.plan_probe`) both call :func:`chain_forces`: one description of the law.
"""

from __future__ import annotations

import numpy as np

from .chain import NodeKind
from .contact import ChainPlan, Contact, DirectionalChain, Kinematics

__all__ = ["chain_forces"]


def chain_forces(system, c: Contact, dc: DirectionalChain, touching: bool, offset: float, kin: Kinematics,
                 x: np.ndarray, f: np.ndarray, ydot: np.ndarray, ev, full: bool, relaxing: bool = False):
    """Apply a chain's stage forces; return (tip force along u [N], bond row or None, γ, interface F, gap).

    Adds the stages' forces on masses and the body to ``f`` [N], junction rates and the
    energy audit's damper power to ``ydot``; with ``full`` records every stage's (x, ẋ, F)
    in ``ev.stages``. ``offset`` [m] shifts the anchor (tangential chains anchored at touch);
    ``relaxing``: the damped surface ends relax after a separation (``ContactMode.relaxing``).
    """
    plan = dc.plan(touching, relaxing)
    pos, vel = _node_motion(system.nQ, dc, plan, kin, x, offset, ydot)
    dc.last_positions = pos
    tip_F, anchor_F, interface_F = _stage_forces(system, c, dc, plan, pos, vel, f, ydot, ev, full)
    if c.body_index >= 0 and anchor_F != 0.0:
        f[c.body_index] += anchor_F * float(dc.u @ c.body_axis)
    chain = dc.chain
    row, gamma = _bond_row(system, c, dc, kin) if plan.bond else (None, 0.0)
    gap = pos[chain.robot_surface] - pos[chain.env_surface]
    if plan.bond:  # Baumgarte: the violation e obeys ë + 2ω ė + ω² e = 0, zero on the exact manifold
        w = system.stabilization
        gamma += 2.0 * w * (vel[chain.robot_surface] - vel[chain.env_surface]) + w * w * gap
    return tip_F, row, gamma, interface_F, (0.0 if touching else gap)


def _node_motion(nQ: int, dc: DirectionalChain, plan: ChainPlan, kin: Kinematics, x: np.ndarray, offset: float,
                 ydot: np.ndarray) -> tuple[list[float], list[float]]:
    """Positions [m] and velocities [m/s] of the chain's nodes along u; junction rates into ``ydot``."""
    chain, u = dc.chain, dc.u
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
    junction_nodes = plan.junction_nodes
    for a, b in plan.aliases:
        if b not in junction_nodes:
            pos[a], vel[a] = pos[b], vel[b]
    y = x[2 * nQ:]
    for j, active, slot, group, algebraic in plan.junctions:
        num = den = kk = ks = 0.0
        for k in active:
            s = stages[k]
            K, B = s.kelvin_voigt  # a junction joins affine stages only (chain._check)
            if s.upper in group:  # stage below pushes j up
                num += K * (pos[s.lower] - (y[slot] if slot >= 0 else 0.0)) + B * vel[s.lower]
                ks += K * pos[s.lower]
            else:  # stage above pushes j down
                num -= K * ((y[slot] if slot >= 0 else 0.0) - pos[s.upper]) - B * vel[s.upper]
                ks += K * pos[s.upper]
            den += B
            kk += K
        if den > 0.0 and not algebraic:
            pos[j], vel[j] = y[slot], num / den
            ydot[slot] = vel[j]
        else:  # undamped or balanced junction: algebraic force balance
            pos[j] = ks / kk if kk > 0 else 0.0
            vel[j] = sum(stages[k].kelvin_voigt[0] * vel[stages[k].lower if stages[k].upper in group
                                                         else stages[k].upper]
                         for k in active) / kk if kk > 0 else 0.0
            if den > 0.0:
                _follow(slot, vel[j], ydot)
    for a, b in plan.aliases:
        if b in junction_nodes:
            pos[a], vel[a] = pos[b], vel[b]
    for a, b in plan.free_ends:
        pos[a], vel[a] = pos[b], vel[b]
        _follow(nodes[a].state, vel[a], ydot)
    return pos, vel


def _follow(slot: int, vel: float, ydot: np.ndarray) -> None:
    """An algebraic node's slot of y (if it has one) moves with it: its position stays ready for the
    mode that needs it as a state (relaxing after a separation) without a stiff term to integrate."""
    if slot >= 0:
        ydot[slot] = vel


def _stage_forces(system, c: Contact, dc: DirectionalChain, plan: ChainPlan, pos: list[float], vel: list[float],
                  f: np.ndarray, ydot: np.ndarray, ev, full: bool) -> tuple[float, float, float]:
    """Sum the active stages' forces on tip, anchor and masses: (tip F, anchor F, interface F) [N]."""
    chain = dc.chain
    nodes, stages = chain.nodes, chain.stages
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
        if system.energy_slot >= 0:
            ydot[system.energy_slot + 1] += (F - s.force(xs, 0.0)) * xd  # damper power [W]
        if full and ev is not None:
            ev.stages[f"{c.name}.{dc.label}.{s.label}"] = (xs, xd, F)
    if full and ev is not None:
        for k in range(len(stages)):
            label = f"{c.name}.{dc.label}.{stages[k].label}"
            if label not in ev.stages:
                ev.stages[label] = (0.0, 0.0, 0.0)
    return tip_F, anchor_F, interface_F


def _bond_row(system, c: Contact, dc: DirectionalChain, kin: Kinematics) -> tuple[np.ndarray, float]:
    """Row of the two surfaces' relative motion along u, and its velocity-product term γ (J̇q̇ part)."""
    nQ, chain, u = system.nQ, dc.chain, dc.u
    nodes = chain.nodes
    row = np.zeros(nQ)
    gamma = 0.0
    for node, sign in ((chain.robot_surface, 1.0), (chain.env_surface, -1.0)):
        kind = nodes[node].kind
        if kind == NodeKind.TIP:
            row[: system.nv] += sign * (u @ kin.J)
            gamma += sign * float(u @ kin.drift)
        elif kind == NodeKind.ANCHOR:
            if c.body_index >= 0:
                row[c.body_index] += sign * float(u @ c.body_axis)
        else:
            row[nodes[node].coord] += sign
    return row, gamma
