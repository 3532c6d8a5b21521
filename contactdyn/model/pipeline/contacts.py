"""The pipeline's contact stages over the packed arrays: chains, bond rows, friction rows, limit rows, and after the
solve the contacts' forces.

Per contact, in the order of ``System.contacts``: its chains (the
normal, then the tangential ones) by :func:`contactdyn.model.chain_forces.chain_call` over the chain's packed plan
(stage laws by address), each bonded chain's row G and γ; then friction
(:func:`_friction`): a stick row per tangent, or a slide's tilt of the normal
column −μ d·G_T (μ by the friction law's address, or the constant μ_k) or its known force −μ max(F, 0) d − c v_t
on the coordinates; then the chains' tip force Jᵀ F [N].
After the solve (:func:`finish`): normal forces, friction forces, the impulse states' rates, limit torques.
A chain's mass riding a turning surface couples with what carries it (:func:`add_riding`: its M and bias terms).
A contact's two sides (:func:`contact_sides`): the touching one a packed frame (a robot frame, an articulated body's
point) or a translating body's point, the surface the ground, a body, or turning with a packed frame (a robot
frame, an articulated body's); a translating body's side moved by its coordinates, a packed frame's by the
rigid-body table's columns (the robot's joints, then the articulated bodies' coordinates: J (3, NF)).
"""

from __future__ import annotations

import math

import numpy as np

from ...laws.abi import call_friction
from ...numerics.compile_cache import njit
from ..chain_forces import H_COORDS, K_U, K_UA, ON_ANCHOR, ON_TIP, chain_call, coordinate_row, orient, relative_sides
from ..contact import riding_point, turning_surface
from .pack import (
    ANCHOR,
    CH_COEF,
    CH_CONSTS,
    CH_ENV_COORD,
    CH_ENV_KIND,
    CH_MOTION,
    CH_NCONSTS,
    CH_NNODES,
    CH_NS,
    CH_OFFSET,
    CH_PLAN,
    CH_ROBOT_COORD,
    CH_ROBOT_KIND,
    CH_ROW,
    CH_STAGES,
    CH_STATE,
    CH_W,
    CI_COORDS,
    CI_FIRST_T,
    CI_FP_AT,
    CI_FRAME,
    CI_FRICTION,
    CI_IMPULSE,
    CI_LAW,
    CI_N_FP,
    CI_N_T,
    CI_NORMAL,
    CI_NORMAL_ROW,
    CI_NT,
    CI_REALS,
    CI_STICK_ROW,
    CI_SURFACE,
    CI_TOUCHING,
    CI_W,
    CR_AXES,
    CR_MU_K,
    CR_MU_S,
    CR_N,
    CR_POINT,
    CR_R,
    CR_T,
    CR_TOUCH,
    CR_VISCOUS,
    EV_FF,
    EV_FN,
    EV_GAP,
    EV_VT,
    EV_W,
    FRICTION_SLIDE,
    FRICTION_STICK,
    I_CHAINS,
    I_CONTACTS,
    I_LIMITS,
    I_RIDING,
    LI_JOINT,
    LI_W,
    N_CHAINS,
    N_CONTACTS,
    N_LIMITS,
    N_RIDING,
    NQ,
    R_LIMITS,
    R_RIDING,
    RH_OMEGA,
    RH_SLIP_BAND,
    RI_COORD,
    RI_FRAME,
    RI_W,
    RR_DIR,
    RR_MASS,
    RR_POINT,
    RR_W,
    TIP,
    W_DIAG,
    section,
)

__all__ = ["contact_terms", "limit_rows", "finish", "contact_sides", "turning_sides", "surface_point",
           "tangential_motion", "frame_omega", "add_coordinates", "add_coordinate_rates", "add_riding"]

#: per contact, what finishes a slide once its normal force is solved: μ [-], d (2), the viscous force (2) [N]
P_MU, P_D, P_VISC, P_W = 0, 1, 3, 5

# ---- a contact's two sides: the touching one (a packed frame: a robot frame or an articulated body's point; or a
# translating body's point) and the surface (the ground, a translating body, or turning with a packed frame:
# turning_sides). A translating body's point is its place at the coordinates 0 plus Σ axis Q [m], its velocity
# Σ axis Q̇, its acceleration Σ axis Q̈ (no drift).

TOUCHING, SURFACE = 0, 1  #: the sides


@njit(cache=True)
def _span(ints, row, side):
    """(where the side's coordinates are in ``ints``, the first one's number among the contact's, how many)."""
    at = row[CI_COORDS]
    n_touch = ints[at]
    if side == TOUCHING:
        return at + 2, 0, n_touch
    return at + 2 + n_touch, n_touch, ints[at + 1]


@njit(cache=True)
def _carry(x, ints, row, cr, side, p, v):
    """p [m] and v [m/s] moved by the side's coordinates (in place)."""
    nQ = ints[NQ]
    at, first, n = _span(ints, row, side)
    for k in range(n):
        i, a = ints[at + k], CR_AXES + 3 * (first + k)
        for r in range(3):
            p[r] = p[r] + cr[a + r] * x[i]
            v[r] = v[r] + cr[a + r] * x[nQ + i]


@njit(cache=True)
def surface_point(x, ints, row, cr):
    """(p_env [m], v_env [m/s]): the contact's surface point, carried by its body if any."""
    p, v = cr[CR_POINT:CR_POINT + 3].copy(), np.zeros(3)
    _carry(x, ints, row, cr, SURFACE, p, v)
    return p, v


@njit(cache=True)
def _touching_point(x, ints, row, cr, Fp, Fv):
    """(p_tip [m], v_tip [m/s]): its packed frame's, or a translating body's touching point carried by its
    coordinates."""
    fi = row[CI_FRAME]
    p_tip, v_tip = Fp[fi], Fv[fi]
    if ints[row[CI_COORDS]]:  # a body's point touches
        p_tip, v_tip = cr[CR_TOUCH:CR_TOUCH + 3].copy(), np.zeros(3)
        _carry(x, ints, row, cr, TOUCHING, p_tip, v_tip)
    return p_tip, v_tip


@njit(cache=True)
def contact_sides(x, ints, row, cr, FJ, Fa, Fp, Fv):
    """(J (3, NF) of its packed frame, p_tip [m], v_tip [m/s], J̇q̇ [m/s²], p_env [m], v_env [m/s]); a translating
    body's touching point has the zero frame's J and J̇q̇ (the frames' last row)."""
    fi = row[CI_FRAME]
    p_tip, v_tip = _touching_point(x, ints, row, cr, Fp, Fv)
    p_env, v_env = surface_point(x, ints, row, cr)
    return FJ[fi, :3], p_tip, v_tip, Fa[fi, :3], p_env, v_env


@njit(cache=True)
def frame_omega(x, ints, FJ, s):
    """ω [rad/s] (world) of packed frame s at the state x: its J_ω q̇ over the rigid-body table's columns."""
    nQ = ints[NQ]
    w = np.zeros(3)
    for r in range(3):
        for c in range(FJ.shape[2]):
            w[r] += FJ[s, 3 + r, c] * x[nQ + c]
    return w


@njit(cache=True)
def turning_sides(x, ints, row, cr, J, p_tip, v_tip, drift, FJ, Fa, Fp, Fv, FR):
    """On a surface carried by a robot frame or an articulated body's (the packed frame ``row[CI_SURFACE]``):
    (J_rel (3, NF), a_rel [m/s²], p_env [m], v_env [m/s], n, T (nt, 3)) of the relative motion at this state
    (model.contact.turning_surface), the touching side's J, p, v, J̇q̇ from :func:`contact_sides`; T the tangents
    of its friction or its tangential chains."""
    nt, s = max(row[CI_NT], row[CI_N_T]), row[CI_SURFACE]
    w = frame_omega(x, ints, FJ, s)
    return turning_surface(p_tip, v_tip, J, drift, Fp[s], Fv[s], FJ[s, :3], Fa[s, :3], FR[s], w, FJ[s, 3:], Fa[s, 3:],
                           cr[CR_POINT:CR_POINT + 3], cr[CR_N:CR_N + 3], cr[CR_T:CR_T + 3 * nt].reshape((nt, 3)))


@njit(cache=True)
def add_coordinates(ints, row, cr, U, out):
    """Add to ``out`` (k, nQ) the bodies' part of the relative motion (touching side − surface) along the unit
    directions U (k, 3) [m/m]: + U·axis on the touching body's coordinates, − on the surface body's."""
    for side, sign in ((TOUCHING, 1.0), (SURFACE, -1.0)):
        at, first, n = _span(ints, row, side)
        for k in range(n):
            i, a = ints[at + k], CR_AXES + 3 * (first + k)
            for j in range(U.shape[0]):
                out[j, i] += sign * (U[j, 0] * cr[a] + U[j, 1] * cr[a + 1] + U[j, 2] * cr[a + 2])


@njit(cache=True)
def tangential_motion(x, ints, row, cr, FJ, Fa, Fp, Fv, FR):
    """(J (3, NF), J̇q̇ [m/s²], v_tip − v_env [m/s], T (nt, 3)) of a contact's relative motion: its touching side's
    (:func:`contact_sides`), or on a turning surface the relative motion along this state's tangents
    (:func:`turning_sides`). The velocity includes the translating bodies' coordinates; their part of the
    acceleration, axis · Q̈, is the caller's (:func:`add_coordinate_rates`)."""
    J, p_tip, v_tip, drift, p_env, v_env = contact_sides(x, ints, row, cr, FJ, Fa, Fp, Fv)
    T = cr[CR_T:CR_T + 3 * row[CI_NT]].reshape((row[CI_NT], 3))
    if row[CI_SURFACE] >= 0:
        J, drift, p_env, v_env, _, T = turning_sides(x, ints, row, cr, J, p_tip, v_tip, drift, FJ, Fa, Fp, Fv, FR)
    return J, drift, v_tip - v_env, T


@njit(cache=True)
def add_coordinate_rates(ints, row, cr, rates, acc):
    """acc [m/s²] (3) plus the touching body's Σ axis Q̈ minus the surface body's, Q̈ = ``rates`` (nQ)."""
    for side, sign in ((TOUCHING, 1.0), (SURFACE, -1.0)):
        at, first, n = _span(ints, row, side)
        for k in range(n):
            i, a = ints[at + k], CR_AXES + 3 * (first + k)
            for r in range(3):
                acc[r] += sign * (cr[a + r] * rates[i])

# ---- the contacts' stages ----------------------------------------------------------------------------------------


@njit(cache=True)
def _chain(x, ints, reals, work, ch, p_tip, v_tip, p_env, v_env, drift, f, ydot):
    """The call of the chain whose ints are ``ch`` over its packed plan: (tip F along u [N], γ [m/s²], interface
    F [N], gap [m], finite)."""
    ns, nn = ch[CH_NS], ch[CH_NNODES]
    plan = ints[ch[CH_PLAN]:ch[CH_STAGES]]
    stages = section(ints, ch[CH_STAGES], ns, 7)
    coef = section(reals, ch[CH_COEF], ns, 4)
    consts = reals[ch[CH_CONSTS]:ch[CH_CONSTS] + ch[CH_NCONSTS]]
    motion = section(work, ch[CH_MOTION], 2, nn)
    state = section(work, ch[CH_STATE], ns, 4)
    return chain_call(plan, stages, coef, consts, x, p_tip, v_tip, p_env, v_env, drift, reals[ch[CH_OFFSET]], f,
                      ydot, motion, state)


@njit(cache=True)
def _bond_row(ints, reals, ch, J, G, C):
    """The bond row of the chain whose ints are ``ch`` (model.chain_forces._bond_row): the two surfaces' relative
    motion along u (the tip's and the anchor's body coordinates: the plan's H_COORDS, their u·axis in its
    constants)."""
    r = ch[CH_ROW]
    consts = reals[ch[CH_CONSTS]:ch[CH_CONSTS] + ch[CH_NCONSTS]]
    plan = ints[ch[CH_PLAN]:ch[CH_STAGES]]
    for kind, coord, sign in ((ch[CH_ROBOT_KIND], ch[CH_ROBOT_COORD], 1.0), (ch[CH_ENV_KIND], ch[CH_ENV_COORD], -1.0)):
        if kind == TIP:
            for c in range(J.shape[1]):
                G[r, c] += sign * (consts[K_U] * J[0, c] + consts[K_U + 1] * J[1, c] + consts[K_U + 2] * J[2, c])
        elif kind != ANCHOR:
            G[r, coord] += sign
        if kind == TIP or kind == ANCHOR:  # the body coordinates that carry this node
            for k in range(plan[plan[H_COORDS]]):
                i, on, slot = coordinate_row(plan, k)
                if on == (ON_TIP if kind == TIP else ON_ANCHOR):
                    G[r, i] += sign * consts[K_UA + slot]
    for c in range(G.shape[1]):  # (element by element: a slice assignment compiles numba's shape check and message)
        C[r, c] = G[r, c]


@njit(cache=True)
def contact_terms(x, ints, reals, work, FJ, Fa, Fp, Fv, FR, f, ydot, G, C, gamma, events, pending):
    """Every contact's chains, rows and friction into f, ydot, G, C, γ, events; False if a stage or friction law
    gave no force (NaN: it raised)."""
    cs = section(ints, ints[I_CONTACTS], ints[N_CONTACTS], CI_W)
    chains = section(ints, ints[I_CHAINS], ints[N_CHAINS], CH_W)
    for ci in range(cs.shape[0]):
        row = cs[ci]
        cr = reals[row[CI_REALS]:]
        J, p_tip, v_tip, drift, p_env, v_env = contact_sides(x, ints, row, cr, FJ, Fa, Fp, Fv)
        n, T = cr[CR_N:CR_N + 3], cr[CR_T:CR_T + 3 * row[CI_NT]].reshape((row[CI_NT], 3))
        turning = row[CI_SURFACE] >= 0
        # a chain's sides: as they are, or on a turning surface measured from it (model.chain_forces.chain_sides)
        sides = (p_tip, v_tip, p_env, v_env)
        if turning:  # the surface turns with a packed frame: the relative motion, along this state's n and T
            J, drift, p_env, v_env, n, T = turning_sides(x, ints, row, cr, J, p_tip, v_tip, drift, FJ, Fa, Fp, Fv,
                                                         FR)
            sides = relative_sides(p_tip, v_tip, p_env, v_env)
            n_touch = ints[row[CI_COORDS]]
            touch_axes = cr[CR_AXES:CR_AXES + 3 * n_touch].reshape((n_touch, 3))
        tip_force = np.zeros(3)
        F_n = 0.0
        for k in range(row[CI_NORMAL], row[CI_FIRST_T] + row[CI_N_T]):
            ch = chains[k]
            s_tip, s_vtip, s_env, s_venv = p_tip, v_tip, p_env, v_env
            if turning:  # along this state's n (the normal) or T's row (a tangential chain)
                u = n if k == row[CI_NORMAL] else T[k - row[CI_FIRST_T]]
                orient(ints[ch[CH_PLAN]:ch[CH_STAGES]], reals[ch[CH_CONSTS]:ch[CH_CONSTS] + ch[CH_NCONSTS]], u,
                       touch_axes)
                if ch[CH_NS] > 0:  # stages: from the surface (a rigid bond's gap is the same either way)
                    s_tip, s_vtip, s_env, s_venv = sides
            tip_F, gam, interface_F, gap, finite = _chain(x, ints, reals, work, ch, s_tip, s_vtip, s_env, s_venv,
                                                          drift, f, ydot)
            if not finite:
                return False
            work[ints[W_DIAG] + 1 + k] = interface_F  # (diagnostics: a tangential chain's interface force)
            for i in range(3):  # along the chain's u (its constants' first three)
                tip_force[i] += tip_F * reals[ch[CH_CONSTS] + i]
            if k == row[CI_NORMAL]:
                F_n = interface_F
                events[EV_W * ci + EV_GAP] = 0.0 if row[CI_TOUCHING] else gap
            if ch[CH_ROW] >= 0:
                _bond_row(ints, reals, ch, J, G, C)
                gamma[ch[CH_ROW]] = gam
        events[EV_W * ci + EV_FN] = F_n
        if row[CI_NT] and not _friction(x, ints, reals, ci, row, cr, J, drift, v_tip, v_env, T, F_n, f, G, C,
                                        gamma, events, pending):
            return False
        if tip_force[0] != 0.0 or tip_force[1] != 0.0 or tip_force[2] != 0.0:
            for c in range(J.shape[1]):
                f[c] += J[0, c] * tip_force[0] + J[1, c] * tip_force[1] + J[2, c] * tip_force[2]
    return True


@njit(cache=True)
def _friction(x, ints, reals, ci, row, cr, J, drift, v_tip, v_env, T, F_n, f, G, C, gamma, events, pending):
    """A friction contact's slip velocity along its tangents T (nt, 3), and its stick rows, or its slide (the tilt
    of its normal column or its known force on the coordinates); False where its law gave no μ (NaN: it
    raised) or a negative one."""
    nQ, nt = ints[NQ], row[CI_NT]
    ev = events[EV_W * ci:EV_W * (ci + 1)]
    vt = np.zeros(nt)
    for i in range(nt):
        vt[i] = T[i, 0] * (v_tip[0] - v_env[0]) + T[i, 1] * (v_tip[1] - v_env[1]) + T[i, 2] * (v_tip[2] - v_env[2])
        ev[EV_VT + i] = vt[i]
        ev[EV_FF + i] = 0.0
    if row[CI_FRICTION] != FRICTION_STICK and row[CI_FRICTION] != FRICTION_SLIDE:
        return True
    R_T = np.zeros((nt, nQ))  # generalized rows of the tangential slip
    for i in range(nt):
        for c in range(J.shape[1]):  # (the robot's joints, then the articulated bodies' coordinates)
            R_T[i, c] = T[i, 0] * J[0, c] + T[i, 1] * J[1, c] + T[i, 2] * J[2, c]
    add_coordinates(ints, row, cr, T, R_T)
    if row[CI_FRICTION] == FRICTION_STICK:
        w = reals[RH_OMEGA]
        for i in range(nt):
            r = row[CI_STICK_ROW] + i
            for c in range(nQ):
                G[r, c] = C[r, c] = R_T[i, c]
            gamma[r] = T[i, 0] * drift[0] + T[i, 1] * drift[1] + T[i, 2] * drift[2] + w * vt[i]
        return True
    d = _slip_direction(reals, cr, vt)
    speed = math.sqrt(vt[0] * vt[0] + vt[1] * vt[1]) if nt == 2 else math.sqrt(vt[0] * vt[0])
    mu = cr[CR_MU_K] if row[CI_LAW] == 0 else \
        call_friction(row[CI_LAW], cr[CR_MU_S], cr[CR_MU_K], reals, row[CI_FP_AT], row[CI_N_FP], speed)
    if not (math.isfinite(mu) and mu >= 0.0):  # (the law's error, which Pipeline.failed_call names)
        return False
    visc = -cr[CR_VISCOUS] * vt
    p = pending[ci]
    p[P_MU] = mu
    for i in range(nt):
        p[P_D + i], p[P_VISC + i] = d[i], visc[i]
    nr = row[CI_NORMAL_ROW]
    force = np.zeros(nt)  # on the coordinates: the viscous force with a normal row, else the whole known force
    for i in range(nt):
        force[i] = visc[i] if nr >= 0 else -mu * max(F_n, 0.0) * d[i] + visc[i]
        if nr < 0:
            ev[EV_FF + i] = force[i]
    for c in range(nQ):
        s = 0.0
        for i in range(nt):
            s += d[i] * R_T[i, c]
        if nr >= 0:
            C[nr, c] = G[nr, c] - mu * s
        if nr < 0 or cr[CR_VISCOUS] != 0.0:
            s = 0.0
            for i in range(nt):
                s += force[i] * R_T[i, c]
            f[c] += s
    return True


@njit(cache=True)
def _slip_direction(reals, cr, vt):
    """A slide's direction d: 2-D, the slip's own direction once ahead of the reference r by the stick band,
    else r; 1-D, r (±1)."""
    d = cr[CR_R:CR_R + vt.size].copy()
    if vt.size == 2 and vt[0] * d[0] + vt[1] * d[1] > reals[RH_SLIP_BAND]:
        return vt / math.sqrt(vt[0] * vt[0] + vt[1] * vt[1])
    return d


@njit(cache=True)
def limit_rows(x, ints, reals, first_row, G, C, gamma):
    """A row per joint pressing on its limit (model.limits.JointLimits.add_rows): e_i Q̈ + 2ω q̇_i + ω² (q_i − limit)."""
    nQ, w = ints[NQ], reals[RH_OMEGA]
    lims = section(ints, ints[I_LIMITS], ints[N_LIMITS], LI_W)
    for k in range(lims.shape[0]):
        i, r = lims[k, LI_JOINT], first_row + k
        G[r, i] = C[r, i] = 1.0
        gamma[r] = 2.0 * w * x[nQ + i] + w * w * (x[i] - reals[ints[R_LIMITS] + k])


@njit(cache=True)
def finish(ints, lam, xdot, events, pending, first_limit_row):
    """After the solve: normal forces of the rows, stick forces, a slide's friction −μ max(F, 0) d + visc, the
    impulse states' rates [N], the limits' torques (into ``events``)."""
    nQ = ints[NQ]
    cs = section(ints, ints[I_CONTACTS], ints[N_CONTACTS], CI_W)
    for ci in range(cs.shape[0]):
        row = cs[ci]
        ev = events[EV_W * ci:EV_W * (ci + 1)]
        nt = row[CI_NT]
        if row[CI_NORMAL_ROW] >= 0:
            ev[EV_FN] = lam[row[CI_NORMAL_ROW]]
        if row[CI_FRICTION] == FRICTION_STICK:
            for i in range(nt):
                ev[EV_FF + i] = lam[row[CI_STICK_ROW] + i]
        elif row[CI_FRICTION] == FRICTION_SLIDE and row[CI_NORMAL_ROW] >= 0:
            p = pending[ci]
            for i in range(nt):
                ev[EV_FF + i] = -p[P_MU] * max(ev[EV_FN], 0.0) * p[P_D + i] + p[P_VISC + i]
        slot = row[CI_IMPULSE]
        if slot >= 0:
            xdot[2 * nQ + slot] = ev[EV_FN]
            for i in range(nt):
                xdot[2 * nQ + slot + 1 + i] = ev[EV_FF + i]
    base = EV_W * cs.shape[0]
    for k in range(ints[N_LIMITS]):
        events[base + k] = lam[first_limit_row + k]


@njit(cache=True)
def add_riding(x, ints, reals, FJ, Fa, FR, M, f):
    """M (nQ, nQ) with each chain mass riding a turning surface coupled to what carries it, m [J | n]ᵀ [J | n] beyond
    its own m (M_rest's diagonal), and its bias −m [J | n]ᵀ a in f (J, n, a: :func:`contactdyn.model.contact.
    riding_point` at its carrying frame, over the table's NF columns; M as
    ``constraints.mass_matrix`` builds it); M itself (NF × NF) when no mass rides."""
    n_r = ints[N_RIDING]
    if n_r == 0:
        return M
    nQ, ncol = ints[NQ], M.shape[0]  # (ncol: the rigid-body table's NF columns)
    Mx = np.zeros((nQ, nQ))
    for r in range(ncol):
        for c in range(ncol):
            Mx[r, c] = M[r, c]
    rows, consts = section(ints, ints[I_RIDING], n_r, RI_W), section(reals, ints[R_RIDING], n_r, RR_W)
    for k in range(n_r):
        fi, i, m = rows[k, RI_FRAME], rows[k, RI_COORD], consts[k, RR_MASS]
        J, n, drift = riding_point(FJ[fi, :3], FJ[fi, 3:], Fa[fi, :3], Fa[fi, 3:], FR[fi], frame_omega(x, ints, FJ, fi),
                                   consts[k, RR_DIR:RR_DIR + 3], consts[k, RR_POINT:RR_POINT + 3], x[i], x[nQ + i])
        for a in range(ncol):
            Jn = Ja = 0.0
            for r in range(3):
                Jn += J[r, a] * n[r]
                Ja += J[r, a] * drift[r]
            Mx[a, i] += m * Jn
            Mx[i, a] += m * Jn
            f[a] -= m * Ja
            for c in range(ncol):
                Mx[a, c] += m * (J[0, a] * J[0, c] + J[1, a] * J[1, c] + J[2, a] * J[2, c])
        f[i] -= m * (n[0] * drift[0] + n[1] * drift[1] + n[2] * drift[2])
    return Mx
