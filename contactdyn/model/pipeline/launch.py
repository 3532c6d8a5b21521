"""A 2-D slide launching from rest over the packed arrays (:func:`contactdyn.model.friction.launch_directions`).

A touching 2-D slide started from rest, still inside the stick band (v_t · r ≤ v_ε), slides where it accelerates:
d = (cos θ, sin θ) with a_t(d) ∥ d ahead, found by Newton on θ (at most 4 updates; the derivative by a 1e-7 rad
difference; the reference r where it does not converge), each trial the whole call with that contact's direction
set to d (its normal column re-tilted, or its known friction force re-aimed, and the KKT re-solved). Contacts
launch in order, each trial with the earlier ones' directions found. A slide already past the band keeps r (its
own direction from there on, ``contacts._slip_direction``). Slip and acceleration are the relative motion's along
the state's tangents (:func:`.contacts.tangential_motion`: on a turning surface they turn with it).

The call drives it (:func:`contactdyn.model.pipeline.pipeline.call`, one loop over its body): :func:`launch_start`
copies ``reals`` (the packed mode stays as packed) and aims the first launching contact, :func:`launch_took` reads
each pass's rates and frames and aims the next trial, until the direction is found. A contact past the band gets r
back before its pass (:func:`launch_settled`: its slip is the frames', which no trial direction changes, so no pass
is run for it: a slide past the band, most of a launch mode's calls, costs one pass); a Newton that converges ends on
its trial's pass, which is then the result; otherwise one more pass runs with the directions found.
"""

from __future__ import annotations

import math

import numpy as np

from ...numerics.compile_cache import njit
from .contacts import add_coordinate_rates, tangential_motion
from .pack import (
    CI_REALS,
    CI_W,
    CR_R,
    I_CONTACTS,
    I_LAUNCH,
    N_CONTACTS,
    N_LAUNCH,
    NQ,
    RH_SLIP_BAND,
    section,
)

__all__ = ["launch_start", "launch_settled", "launch_took", "ST_CONTACT"]

#: the Newton's state: the launching contact (its index among them), the pending pass (the contact's first, at θ, at
#: θ + h), updates done, θ [rad], φ = d × a_t and a_t · d [m/s²] at θ, the contact's reference r
ST_CONTACT, ST_STEP, ST_UPDATES, ST_THETA, ST_PHI, ST_AHEAD, ST_R, ST_W = 0, 1, 2, 3, 4, 5, 6, 8
FIRST, AT, AT_H = 0, 1, 2
H = 1e-7  #: [rad] the difference of the derivative dφ/dθ
MAX_UPDATES = 4


@njit(cache=True)
def _contact(ints, j):
    return section(ints, ints[I_CONTACTS], ints[N_CONTACTS], CI_W)[ints[ints[I_LAUNCH] + j]]


@njit(cache=True)
def _aim(ints, trial, j, theta):
    """The trial direction d = (cos θ, sin θ) of launching contact j into ``trial``."""
    at = _contact(ints, j)[CI_REALS] + CR_R
    trial[at], trial[at + 1] = math.cos(theta), math.sin(theta)


@njit(cache=True)
def _begin(ints, trial, state, j):
    """Launching contact j's first pass aimed at its reference r (θ = atan2(r)); r kept in ``state``."""
    state[ST_CONTACT] = j
    if j >= ints[N_LAUNCH]:
        return
    at = _contact(ints, j)[CI_REALS] + CR_R
    state[ST_STEP], state[ST_UPDATES] = FIRST, 0
    state[ST_R], state[ST_R + 1] = trial[at], trial[at + 1]
    state[ST_THETA] = math.atan2(trial[at + 1], trial[at])
    _aim(ints, trial, j, state[ST_THETA])


@njit(cache=True)
def launch_start(ints, reals):
    """(the reals the call's first pass reads, the Newton's state): ``reals`` itself without a launch, else a copy
    with the first launching contact aimed."""
    state = np.zeros(ST_W)
    if ints[N_LAUNCH] == 0:
        return reals, state
    trial = reals.copy()
    _begin(ints, trial, state, 0)
    return trial, state


@njit(cache=True)
def launch_settled(x, ints, state, trial, FJ, Fa, Fp, Fv, FR):
    """Before a pass, from its frames (the same under any trial direction): each pending
    contact about to take its first pass whose slip is already past the band gets its r back and the next contact
    begins (as :func:`launch_took` would have done after that pass, whose rates it would not have read). True when
    no contact is left to launch: the pass about to run is the result."""
    while state[ST_CONTACT] < ints[N_LAUNCH] and state[ST_STEP] == FIRST:
        j = int(state[ST_CONTACT])
        if not _past_band(x, ints, trial, state, j, FJ, Fa, Fp, Fv, FR):
            break
        at = _contact(ints, j)[CI_REALS] + CR_R
        trial[at], trial[at + 1] = state[ST_R], state[ST_R + 1]  # launched: r, its own direction from here on
        _begin(ints, trial, state, j + 1)
    return state[ST_CONTACT] >= ints[N_LAUNCH]


@njit(cache=True)
def _past_band(x, ints, trial, state, j, FJ, Fa, Fp, Fv, FR):
    """Contact j's slip already ahead of its reference r by more than the stick band: v_t · r > v_ε [m/s] (v_t
    along this state's tangents: a turning surface's turn with it)."""
    row = _contact(ints, j)
    cr = trial[row[CI_REALS]:]
    _, _, v, T = tangential_motion(x, ints, row, cr, FJ, Fa, Fp, Fv, FR)
    ahead = 0.0
    for k in range(2):
        ahead += (T[k, 0] * v[0] + T[k, 1] * v[1] + T[k, 2] * v[2]) * state[ST_R + k]
    return ahead > trial[RH_SLIP_BAND]


@njit(cache=True)
def _cross(x, ints, trial, j, xdot, FJ, Fa, Fp, Fv, FR):
    """(d × a_t, a_t · d) [m/s²] of launching contact j under its trial d: a_t = T (J Q̈ + J̇q̇ ± axis Q̈ of the
    bodies' coordinates), the relative motion's along this state's tangents (friction.slip_acceleration)."""
    nQ = ints[NQ]
    row = _contact(ints, j)
    cr = trial[row[CI_REALS]:]
    J, drift, _, T = tangential_motion(x, ints, row, cr, FJ, Fa, Fp, Fv, FR)
    acc = drift.copy()
    for r in range(3):
        for c in range(J.shape[1]):  # (the rigid-body table's columns)
            acc[r] += J[r, c] * xdot[nQ + c]
    add_coordinate_rates(ints, row, cr, xdot[nQ:2 * nQ], acc)
    a = np.zeros(2)
    for k in range(2):
        a[k] = T[k, 0] * acc[0] + T[k, 1] * acc[1] + T[k, 2] * acc[2]
    d0, d1 = cr[CR_R], cr[CR_R + 1]
    return d0 * a[1] - d1 * a[0], a[0] * d0 + a[1] * d1


@njit(cache=True)
def launch_took(x, ints, state, trial, FJ, Fa, Fp, Fv, FR, xdot):
    """A pass's rates ``xdot`` and frames read for the pending contact: its next trial aimed, or its direction
    found (d where φ ≈ 0 ahead; r where dφ/dθ ≥ 0 or after MAX_UPDATES) and the next contact begun. True when this
    pass is the result (the last contact's Newton converged on it). (A contact past the stick band never gets here:
    :func:`launch_settled` gave it r before the pass, from the same frames.)"""
    j = int(state[ST_CONTACT])
    at = _contact(ints, j)[CI_REALS] + CR_R
    phi, ahead = _cross(x, ints, trial, j, xdot, FJ, Fa, Fp, Fv, FR)
    if state[ST_STEP] != AT_H:
        if ahead >= 0.0 and abs(phi) <= 1e-9 * (abs(ahead) + abs(phi)):  # the trial's d stays
            _begin(ints, trial, state, j + 1)
            return j + 1 >= ints[N_LAUNCH]
        state[ST_PHI], state[ST_AHEAD], state[ST_STEP] = phi, ahead, AT_H
        _aim(ints, trial, j, state[ST_THETA] + H)
        return False
    dphi = (phi - state[ST_PHI]) / H
    if dphi < 0.0:
        state[ST_THETA] -= min(max(state[ST_PHI] / dphi, -0.5), 0.5)
        state[ST_UPDATES] += 1
        if state[ST_UPDATES] < MAX_UPDATES:
            state[ST_STEP] = AT
            _aim(ints, trial, j, state[ST_THETA])
            return False
    trial[at], trial[at + 1] = state[ST_R], state[ST_R + 1]  # no convergence: the reference r
    _begin(ints, trial, state, j + 1)
    return False
