"""A 2-D slide launching from rest over the packed arrays (:func:`contactdyn.model.friction.launch_directions`).

A touching 2-D slide started from rest, still inside the stick band (v_t · r ≤ v_ε), slides where it accelerates:
d = (cos θ, sin θ) with a_t(d) ∥ d ahead, found by Newton on θ (at most 4 updates; the derivative by a 1e-7 rad
difference; the reference r where it does not converge), each trial the whole call with that contact's direction
set to d (its normal column re-tilted, or its known friction force re-aimed, and the KKT re-solved). Contacts
launch in order, each trial with the earlier ones' directions found. A slide already past the band keeps r (its
own direction from there on, ``contacts._slip_direction``).

The call drives it (:func:`contactdyn.model.pipeline.pipeline.call`): :func:`launch_start` copies ``reals`` (the
packed mode stays as packed) and sets the first trial, :func:`launch_took` reads each trial's rates and sets the
next, until ``state[ST_CONTACT]`` passes the last launching contact; the call then runs on the copy.
"""

from __future__ import annotations

import math

import numpy as np

from ...numerics.compile_cache import njit
from .pack import (
    CI_BODY,
    CI_FRAME,
    CI_REALS,
    CI_W,
    CR_AXIS,
    CR_R,
    CR_T,
    I_CONTACTS,
    I_LAUNCH,
    N_CONTACTS,
    N_LAUNCH,
    NQ,
    NV,
    RH_SLIP_BAND,
    section,
)
from .robot_terms import frame_terms, robot_terms

__all__ = ["launch_start", "launch_took", "ST_CONTACT"]

#: the Newton's state: the launching contact (its index among them), the pending trial (at θ, at θ + h), updates
#: done, θ [rad], φ = d × a_t and a_t · d [m/s²] at θ
ST_CONTACT, ST_STEP, ST_UPDATES, ST_THETA, ST_PHI, ST_AHEAD, ST_W = range(7)
AT, AT_H = 0, 1
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
def _next_contact(x, ints, reals, trial, state, FJ, Fv):
    """From ``state[ST_CONTACT]`` on, the first launching contact still inside the stick band: its first trial set
    (θ from its reference r); those past the band keep r."""
    nQ = ints[NQ]
    j = int(state[ST_CONTACT])
    while j < ints[N_LAUNCH]:
        row = _contact(ints, j)
        cr = reals[row[CI_REALS]:]
        body = row[CI_BODY]
        v = Fv[row[CI_FRAME]].copy()
        if body >= 0:
            for i in range(3):
                v[i] -= cr[CR_AXIS + i] * x[nQ + body]
        T = cr[CR_T:CR_T + 6].reshape((2, 3))
        ahead = 0.0  # v_t · r [m/s]
        for k in range(2):
            ahead += (T[k, 0] * v[0] + T[k, 1] * v[1] + T[k, 2] * v[2]) * cr[CR_R + k]
        if not ahead > reals[RH_SLIP_BAND]:
            state[ST_STEP], state[ST_UPDATES] = AT, 0
            state[ST_THETA] = math.atan2(cr[CR_R + 1], cr[CR_R])
            _aim(ints, trial, j, state[ST_THETA])
            break
        j += 1
    state[ST_CONTACT] = j


@njit(cache=True)
def launch_start(x, ints, reals):
    """(trial reals, Newton state, frames' J (nf, 6, nv), J̇q̇ (nf, 6)) with the first trial set."""
    H_, h, g, Jw, W = robot_terms(x, ints, reals)
    FJ, Fa, Fp, Fv, FR = frame_terms(x, ints, reals, W, Jw)
    trial = reals.copy()
    state = np.zeros(ST_W)
    _next_contact(x, ints, reals, trial, state, FJ, Fv)
    return trial, state, FJ, Fa, Fv


@njit(cache=True)
def _cross(ints, trial, j, xdot, FJ, Fa):
    """(d × a_t, a_t · d) [m/s²] of launching contact j under its trial d: a_t = T (J Q̈ + J̇q̇ − axis Q̈_body)
    (friction.slip_acceleration)."""
    nv, nQ = ints[NV], ints[NQ]
    row = _contact(ints, j)
    cr = trial[row[CI_REALS]:]
    fi, body = row[CI_FRAME], row[CI_BODY]
    acc = Fa[fi, :3].copy()
    for r in range(3):
        for c in range(nv):
            acc[r] += FJ[fi, r, c] * xdot[nQ + c]
        if body >= 0:
            acc[r] -= cr[CR_AXIS + r] * xdot[nQ + body]
    a = np.zeros(2)
    for k in range(2):
        a[k] = cr[CR_T + 3 * k] * acc[0] + cr[CR_T + 3 * k + 1] * acc[1] + cr[CR_T + 3 * k + 2] * acc[2]
    d0, d1 = cr[CR_R], cr[CR_R + 1]
    return d0 * a[1] - d1 * a[0], a[0] * d0 + a[1] * d1


@njit(cache=True)
def launch_took(x, ints, reals, trial, state, FJ, Fa, Fv, xdot):
    """The rates ``xdot`` of the pending trial read: the Newton's next trial set, or the contact's direction found
    (d where φ ≈ 0 ahead; r where dφ/dθ ≥ 0 or after MAX_UPDATES) and the next contact's first trial."""
    j = int(state[ST_CONTACT])
    phi, ahead = _cross(ints, trial, j, xdot, FJ, Fa)
    at = _contact(ints, j)[CI_REALS] + CR_R
    found = False
    if state[ST_STEP] == AT:
        if ahead >= 0.0 and abs(phi) <= 1e-9 * (abs(ahead) + abs(phi)):
            found = True  # the trial's d stays
        else:
            state[ST_PHI], state[ST_AHEAD], state[ST_STEP] = phi, ahead, AT_H
            _aim(ints, trial, j, state[ST_THETA] + H)
            return
    else:
        dphi = (phi - state[ST_PHI]) / H
        if dphi < 0.0:
            state[ST_THETA] -= min(max(state[ST_PHI] / dphi, -0.5), 0.5)
            state[ST_UPDATES] += 1
            if state[ST_UPDATES] < MAX_UPDATES:
                state[ST_STEP] = AT
                _aim(ints, trial, j, state[ST_THETA])
                return
    if not found:  # no convergence: the reference r
        trial[at], trial[at + 1] = reals[at], reals[at + 1]
    state[ST_CONTACT] = j + 1
    _next_contact(x, ints, reals, trial, state, FJ, Fv)
