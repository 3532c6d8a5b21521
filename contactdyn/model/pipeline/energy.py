"""The energy audit's rates over the packed arrays (``solver.record_energy``, ``System.energy_slot``).

Two states from the slot e of y (``System.energy_slot``): the drives' work, ẏ_e = the power they deliver [W] (ideal
torque sources: Σ cmd_i q̇_i; with motors, each kind's own power as :func:`.drives.apply_drives` wrote it), and the
energy dissipated, ẏ_{e+1} [W]: the motors' losses (a tube's damper), the chains' dampers (written by the chains,
``chain_forces``), the sliding contacts' viscous friction c |v_t|² and Coulomb friction μ max(F, 0) d · v_t (μ and d
as :func:`.contacts.contact_terms` kept them, F the solved normal force: :func:`.contacts.finish`), the joints'
damping and sliding friction (:func:`.joint_friction.joint_dissipation`).
"""

from __future__ import annotations

from ...numerics.compile_cache import njit
from .contacts import P_D, P_MU
from .drives import DW_W
from .joint_friction import joint_dissipation
from .pack import (
    ANY_MOTOR,
    CI_FRICTION,
    CI_NT,
    CI_REALS,
    CI_W,
    CR_VISCOUS,
    ENERGY,
    EV_FN,
    EV_VT,
    EV_W,
    FRICTION_SLIDE,
    I_CONTACTS,
    N_CONTACTS,
    N_DRIVES,
    NQ,
    W_DRIVES,
    section,
)

__all__ = ["energy_rates"]


@njit(cache=True)
def energy_rates(x, ints, reals, work, cmd, xdot, events, pending):
    """The audit's two rates into ``xdot`` (after the solve: the normal forces are known); nothing without one."""
    e = ints[ENERGY]
    if e < 0:
        return
    nQ, n = ints[NQ], ints[N_DRIVES]
    lost = xdot[2 * nQ + e + 1]  # the chains' dampers
    power = 0.0
    if ints[ANY_MOTOR]:  # the drives' laws wrote their power and losses after the forces
        at = ints[W_DRIVES] + DW_W * n
        power, lost = work[at], lost + work[at + 1]
    else:
        for i in range(n):
            power += cmd[i] * x[nQ + i]
    cs = section(ints, ints[I_CONTACTS], ints[N_CONTACTS], CI_W)
    for ci in range(cs.shape[0]):
        if cs[ci, CI_FRICTION] == FRICTION_SLIDE:
            vt = events[EV_W * ci + EV_VT:EV_W * ci + EV_VT + cs[ci, CI_NT]]
            c = reals[cs[ci, CI_REALS] + CR_VISCOUS]
            for i in range(vt.size):
                lost += c * vt[i] * vt[i]
    lost += joint_dissipation(x, ints, reals)
    for ci in range(cs.shape[0]):
        if cs[ci, CI_FRICTION] == FRICTION_SLIDE:
            p, ev = pending[ci], events[EV_W * ci:EV_W * (ci + 1)]
            slip = 0.0
            for i in range(cs[ci, CI_NT]):
                slip += p[P_D + i] * ev[EV_VT + i]
            lost += p[P_MU] * max(ev[EV_FN], 0.0) * slip
    xdot[2 * nQ + e] = power
    xdot[2 * nQ + e + 1] = lost
