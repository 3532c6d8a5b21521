"""A contact's two sides over the packed arrays: the touching one (a robot frame, or a body's point) and the surface
(the ground, or a body), each carried by its body's coordinates (:class:`contactdyn.model.contact.Contact`).

A body translates: a point of it is its place at the coordinates 0 plus Σ axis Q [m], its velocity Σ axis Q̇, and its
acceleration Σ axis Q̈ (the axes are fixed, so no drift term).
"""

from __future__ import annotations

import numpy as np

from ...numerics.compile_cache import njit
from .pack import CI_COORDS, CI_FRAME, CR_AXES, CR_POINT, CR_TOUCH, NQ

__all__ = ["contact_sides", "surface_point", "relative_velocity", "add_coordinates", "add_coordinate_rates"]

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
def contact_sides(x, ints, row, cr, FJ, Fa, Fp, Fv):
    """(J (3, nv) of the robot's frame, p_tip [m], v_tip [m/s], J̇q̇ [m/s²], p_env [m], v_env [m/s]); a body's
    touching point has the zero frame's J and J̇q̇ (the frames' last row)."""
    fi = row[CI_FRAME]
    p_tip, v_tip = Fp[fi], Fv[fi]
    if ints[row[CI_COORDS]]:  # a body's point touches
        p_tip, v_tip = cr[CR_TOUCH:CR_TOUCH + 3].copy(), np.zeros(3)
        _carry(x, ints, row, cr, TOUCHING, p_tip, v_tip)
    p_env, v_env = surface_point(x, ints, row, cr)
    return FJ[fi, :3], p_tip, v_tip, Fa[fi, :3], p_env, v_env


@njit(cache=True)
def add_coordinates(ints, row, cr, U, out):
    """Add to ``out`` (k, nQ) the bodies' part of the relative motion (touching side − surface) along the unit
    directions U (k, 3) [m/m]: + U·axis on the touching body's coordinates, − on the surface body's."""
    for side in (TOUCHING, SURFACE):
        at, first, n = _span(ints, row, side)
        for k in range(n):
            i, a = ints[at + k], CR_AXES + 3 * (first + k)
            for j in range(U.shape[0]):
                ua = U[j, 0] * cr[a] + U[j, 1] * cr[a + 1] + U[j, 2] * cr[a + 2]
                if side == TOUCHING:
                    out[j, i] += ua
                else:
                    out[j, i] -= ua


@njit(cache=True)
def relative_velocity(x, ints, row, cr, Fv):
    """v_tip − v_env [m/s] of the contact (the robot frame's velocity from ``Fv``)."""
    v_tip = Fv[row[CI_FRAME]]
    if ints[row[CI_COORDS]]:  # a body's point touches
        p, v_tip = cr[CR_TOUCH:CR_TOUCH + 3].copy(), np.zeros(3)
        _carry(x, ints, row, cr, TOUCHING, p, v_tip)
    return v_tip - surface_point(x, ints, row, cr)[1]


@njit(cache=True)
def add_coordinate_rates(ints, row, cr, rates, acc):
    """acc [m/s²] (3) plus the touching body's Σ axis Q̈ minus the surface body's, Q̈ = ``rates`` (nQ)."""
    for side in (TOUCHING, SURFACE):
        at, first, n = _span(ints, row, side)
        for k in range(n):
            i, a = ints[at + k], CR_AXES + 3 * (first + k)
            for r in range(3):
                if side == TOUCHING:
                    acc[r] += cr[a + r] * rates[i]
                else:
                    acc[r] -= cr[a + r] * rates[i]
