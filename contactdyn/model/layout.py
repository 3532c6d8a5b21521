"""The state layout: which part of the scene owns which slot of the state x.

    x = [Q, Q̇, y]

Q [m, rad] holds the second-order coordinates, in this order:

1. the robot's active joints (nv of them);
2. one coordinate per active environment body (a cart), along its axis [m];
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
   following the contact forces the ``slip`` event watches (:mod:`contactdyn.hybrid.events`).

A part the scene does not name has no slot and costs nothing. The functions here assign
the slots; :class:`~contactdyn.model.system.System` keeps the resulting sizes (``nv``, ``nQ``,
``ny``, ``n = 2 nQ + ny``).
"""

from __future__ import annotations

from .chain import NodeKind
from .contact import Contact

__all__ = ["assign_chain_slots", "assign_first_order_slots"]


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
                             contacts: list[Contact]) -> tuple[list[slice], int, dict[str, int], int]:
    """Slots of y after the junctions: (controller slices, energy slot or −1, impulse slots, ny)."""
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
    return z_slices, energy_slot, impulse_slots, n_first
