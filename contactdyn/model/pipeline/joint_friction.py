"""The pipeline's joint friction over the packed arrays (:mod:`contactdyn.model.joint_friction`, issue 31).

Per joint its damping −b q̇ [N·m or N]; per joint with dry friction, in the phase's joint mode: stuck (a row
eᵢ Q̈ + ω q̇ᵢ = 0 after the limits' rows, its force the holding torque; a joint pressing on a limit has none) or
sliding with sign s (the known torque −s τ_k). The event values after the limits': the held joints' torques
[N·m or N], then the sliding joints' speeds [rad/s or m/s]; per such joint the rate of its impulse state ∫τ_f dt
(the step follows the holding torque the ``joint_slip`` event watches). The packed layout: ``pack._joint_friction``.
"""

from __future__ import annotations

from ...numerics.compile_cache import njit
from .pack import I_JOINTS, JOINT_FRICTION, N_HELD, N_SLIDING, NQ, NV, R_JOINTS, RH_OMEGA

__all__ = ["joint_rows", "joint_torques", "joint_events", "joint_dissipation"]


@njit(cache=True)
def joint_rows(x, ints, reals, first_row, G, C, gamma):
    """A row per held joint from ``first_row`` (JointFriction.add_rows): eᵢ, γ = ω q̇ᵢ [rad/s² or m/s²]."""
    nQ, w = ints[NQ], reals[RH_OMEGA]
    for k in range(ints[N_HELD]):
        i, r = ints[ints[I_JOINTS] + k], first_row + k
        G[r, i] = C[r, i] = 1.0
        gamma[r] = w * x[nQ + i]


@njit(cache=True)
def joint_torques(x, ints, reals, f):
    """The damping and sliding friction −b q̇ − s τ_k [N·m or N] added to f (JointFriction.torques)."""
    if not ints[JOINT_FRICTION]:
        return
    nv, nQ, at = ints[NV], ints[NQ], ints[R_JOINTS]
    tau = -reals[at:at + nv] * x[nQ:nQ + nv]
    sliding = ints[I_JOINTS] + ints[N_HELD]
    for k in range(ints[N_SLIDING]):
        i = ints[sliding + k]
        tau[i] -= reals[at + nv + 2 * k] * reals[at + nv + 2 * k + 1]
    for c in range(nv):
        f[c] += tau[c]


@njit(cache=True)
def joint_events(x, ints, reals, lam, first_row, events, base, xdot):
    """From ``events[base]``: the held joints' holding torques λ [N·m or N], the sliding joints' speeds; into
    ``xdot`` the rates of their impulse states ∫τ_f dt: λ, −s τ_k (a joint on a limit: 0, set before)."""
    nv, nQ, n_held, n_sliding = ints[NV], ints[NQ], ints[N_HELD], ints[N_SLIDING]
    at, slots = ints[R_JOINTS] + nv, ints[I_JOINTS] + n_held + n_sliding
    for k in range(n_held):
        events[base + k] = lam[first_row + k]
        xdot[ints[slots + k]] = lam[first_row + k]
    for k in range(n_sliding):
        events[base + n_held + k] = x[nQ + ints[ints[I_JOINTS] + n_held + k]]
        xdot[ints[slots + n_held + k]] = -reals[at + 2 * k] * reals[at + 2 * k + 1]


@njit(cache=True)
def joint_dissipation(x, ints, reals):
    """[W] b q̇² + Σ τ_k s q̇ᵢ ≥ 0 (the power the joints' damping and sliding take)."""
    if not ints[JOINT_FRICTION]:
        return 0.0
    nv, nQ, at = ints[NV], ints[NQ], ints[R_JOINTS]
    damped = 0.0
    for c in range(nv):
        v = x[nQ + c]
        damped += reals[at + c] * (v * v)
    sliding = ints[I_JOINTS] + ints[N_HELD]
    dry = 0.0
    for k in range(ints[N_SLIDING]):
        dry += reals[at + nv + 2 * k + 1] * reals[at + nv + 2 * k] * x[nQ + ints[sliding + k]]
    return damped + dry
