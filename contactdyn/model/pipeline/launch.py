"""2-D slides launching from rest over the packed arrays (which ones: :func:`contactdyn.model.friction.launching`).

A touching 2-D slide started from rest, still inside the stick band (v_t · r ≤ v_ε), slides where it accelerates: d =
(cos θ, sin θ) with a_t(d) ∥ d ahead, found by Newton on θ (at most 4 updates; the derivative by a 1e-7 rad difference;
where it does not converge, one last trial along a_t, then the reference r), each trial the whole call with that
contact's direction set to d (its normal column re-tilted, or its known friction force re-aimed, and the KKT re-solved).
A slide already past the band keeps r (its own direction from there on, ``contacts._slip_direction``). Slip and
acceleration are the relative motion's along the state's tangents (:func:`.contacts.tangential_motion`: on a turning
surface they turn with it).

Several contacts launching at once nest (each trial of one runs the later ones' Newtons first): level k's Newton
reads, per trial, the pass in which every later level has found its direction for that trial. The levels' states are
one stack (LV_* per launching contact); a pass's rates go to the deepest level first, and a level done (converged:
its trial's pass is its result; or given up: one more round with r) hands the same rates up to the one before it. A
level that aims a new trial starts the later levels again from their references.

The call drives it (:func:`contactdyn.model.pipeline.pipeline.call`, one loop over its body): :func:`launch_start`
copies ``reals`` (the packed mode stays as packed) and aims every launching contact at its reference's angle,
:func:`launch_settled` gives each contact already past the band its r back before the first pass (its slip is the
frames', which no trial direction changes: no Newton for it, and when every one is, the first pass is the result),
:func:`launch_took` reads each pass's rates and frames and aims the next trial, until level 0 is done: that pass is
the result.
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

__all__ = ["launch_start", "launch_settled", "launch_took", "ST_DONE", "ST_HEAD"]

#: the launch state's header: ST_DONE N_LAUNCH when every launching contact is past the band (the first pass is the
#: result; 0 otherwise), ST_CHECKED 1 once launch_settled has looked; then per launching contact its level (LV_*)
ST_DONE, ST_CHECKED, ST_HEAD = 0, 1, 2
#: a level: its pending pass (its first, at θ, at θ + h; or DONE_R: given up, r aimed; PAST: past the band, r
#: aimed), updates done, θ [rad], φ = d × a_t and a_t · d [m/s²] at θ, the contact's reference r
LV_STEP, LV_UPDATES, LV_THETA, LV_PHI, LV_AHEAD, LV_R, LV_W = 0, 1, 2, 3, 4, 5, 7
FIRST, AT, AT_H, DONE_R, PAST = 0, 1, 2, 3, 4
H = 1e-7  #: [rad] the difference of the derivative dφ/dθ
MAX_UPDATES = 4
ALONG_TRIED = MAX_UPDATES + 1  #: a level's LV_UPDATES once its last trial along a_t is aimed (:func:`_try_along`)


@njit(cache=True)
def _contact(ints, j):
    return section(ints, ints[I_CONTACTS], ints[N_CONTACTS], CI_W)[ints[ints[I_LAUNCH] + j]]


@njit(cache=True)
def _level(state, j):
    """Launching contact j's level in the state (a view)."""
    return state[ST_HEAD + LV_W * j:ST_HEAD + LV_W * (j + 1)]


@njit(cache=True)
def _aim(ints, trial, j, theta):
    """The trial direction d = (cos θ, sin θ) of launching contact j into ``trial``."""
    at = _contact(ints, j)[CI_REALS] + CR_R
    trial[at], trial[at + 1] = math.cos(theta), math.sin(theta)


@njit(cache=True)
def _aim_r(ints, trial, level, j):
    """Launching contact j's reference r itself into ``trial`` (not its cos/sin round trip)."""
    at = _contact(ints, j)[CI_REALS] + CR_R
    trial[at], trial[at + 1] = level[LV_R], level[LV_R + 1]


@njit(cache=True)
def _restart(ints, trial, state, j):
    """Levels j.. begun again (a past-band one keeps r): each aimed at its reference (θ = atan2(r)), first pass."""
    for k in range(j, ints[N_LAUNCH]):
        level = _level(state, k)
        if level[LV_STEP] == PAST:
            continue
        level[LV_STEP], level[LV_UPDATES] = FIRST, 0
        level[LV_THETA] = math.atan2(level[LV_R + 1], level[LV_R])
        _aim(ints, trial, k, level[LV_THETA])


@njit(cache=True)
def launch_start(ints, reals):
    """(the reals the call's first pass reads, the launch state): ``reals`` itself without a launch, else a copy
    with every launching contact aimed at its reference's angle (its r kept in its level)."""
    n = ints[N_LAUNCH]
    state = np.zeros(ST_HEAD + LV_W * n)
    if n == 0:
        return reals, state
    trial = reals.copy()
    for j in range(n):
        at = _contact(ints, j)[CI_REALS] + CR_R
        level = _level(state, j)
        level[LV_R], level[LV_R + 1] = trial[at], trial[at + 1]
    _restart(ints, trial, state, 0)
    return trial, state


@njit(cache=True)
def launch_settled(x, ints, state, trial, FJ, Fa, Fp, Fv, FR):
    """Before the first pass, from its frames (the same under any trial direction): each contact whose slip is
    already past the band gets its r back for good (launched: no Newton). True when every one is: the pass about to
    run is the result. (Later passes: False at once.)"""
    if state[ST_CHECKED] != 0.0:
        return False
    state[ST_CHECKED] = 1.0
    n = ints[N_LAUNCH]
    past = 0
    for j in range(n):
        level = _level(state, j)
        if _past_band(x, ints, trial, level, j, FJ, Fa, Fp, Fv, FR):
            level[LV_STEP] = PAST
            _aim_r(ints, trial, level, j)
            past += 1
    if past == n:
        state[ST_DONE] = n
    return past == n


@njit(cache=True)
def _past_band(x, ints, trial, level, j, FJ, Fa, Fp, Fv, FR):
    """Contact j's slip already ahead of its reference r by more than the stick band: v_t · r > v_ε [m/s] (v_t
    along this state's tangents: a turning surface's turn with it)."""
    row = _contact(ints, j)
    cr = trial[row[CI_REALS]:]
    _, _, v, T = tangential_motion(x, ints, row, cr, FJ, Fa, Fp, Fv, FR)
    ahead = 0.0
    for k in range(2):
        ahead += (T[k, 0] * v[0] + T[k, 1] * v[1] + T[k, 2] * v[2]) * level[LV_R + k]
    return ahead > trial[RH_SLIP_BAND]


@njit(cache=True)
def _cross(x, ints, trial, j, xdot, FJ, Fa, Fp, Fv, FR):
    """(d × a_t, a_t · d) [m/s²] of launching contact j under its trial d: a_t = T (J Q̈ + J̇q̇ ± axis Q̈ of the
    bodies' coordinates), the relative motion's along this state's tangents."""
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
    """A pass's rates ``xdot`` and frames, read level by level from the deepest: a level done with them (its trial's
    d where φ ≈ 0 ahead; given up or past the band: r) hands them up, a level that needs another trial aims it (the
    next θ or θ + h; where dφ/dθ ≥ 0 or after MAX_UPDATES one along a_t, :func:`_try_along`, then r), begins the later
    levels again and asks for a pass (False). True when level 0 is done: this pass is the result."""
    for j in range(ints[N_LAUNCH] - 1, -1, -1):
        level = _level(state, j)
        if level[LV_STEP] == DONE_R or level[LV_STEP] == PAST:
            continue
        phi, ahead = _cross(x, ints, trial, j, xdot, FJ, Fa, Fp, Fv, FR)
        if level[LV_STEP] != AT_H:
            if ahead >= 0.0 and abs(phi) <= 1e-9 * (abs(ahead) + abs(phi)):  # the trial's d stays
                continue
            if level[LV_UPDATES] < ALONG_TRIED:
                level[LV_PHI], level[LV_AHEAD], level[LV_STEP] = phi, ahead, AT_H
                _aim(ints, trial, j, level[LV_THETA] + H)
                _restart(ints, trial, state, j + 1)
                return False
        else:
            dphi, along = (phi - level[LV_PHI]) / H, level[LV_THETA] + H + math.atan2(phi, ahead)  # (a_t's angle)
            if dphi < 0.0:
                level[LV_THETA] -= min(max(level[LV_PHI] / dphi, -0.5), 0.5)
                level[LV_UPDATES] += 1
                if level[LV_UPDATES] < MAX_UPDATES:
                    level[LV_STEP] = AT
                    _aim(ints, trial, j, level[LV_THETA])
                    _restart(ints, trial, state, j + 1)
                    return False
            _try_along(ints, trial, state, level, j, along)  # (once: after it no θ + h is aimed)
            return False
        level[LV_STEP] = DONE_R  # no convergence: the reference r, the later levels found again under it
        _aim_r(ints, trial, level, j)
        _restart(ints, trial, state, j + 1)
        return False
    return True


@njit(cache=True)
def _try_along(ints, trial, state, level, j, along):
    """Newton given up: one last trial along a_t of the trial at θ + h (``along``: a_t's angle [rad]), where the slip
    goes under it: where the joints let the contact move along one direction only (the others stuck), a_t points along
    it whatever d is, and there d = a_t settles at once, where Newton from a reference off it converges only linearly
    at the cone's edge (φ ~ δ³). Once per launch: with LV_UPDATES = ALONG_TRIED no θ + h is aimed again, so a trial
    along a_t that does not settle ends at r (:func:`launch_took`)."""
    level[LV_UPDATES] = ALONG_TRIED
    level[LV_THETA] = along
    level[LV_STEP] = AT
    _aim(ints, trial, j, along)
    _restart(ints, trial, state, j + 1)
    return True
