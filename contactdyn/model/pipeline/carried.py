"""A reference carried by a body over the packed arrays (``[phase.reference] body = "..."``, model.phases).

The reference rides on body coordinate Q_b along its unit axis: x_d = axis · Q_b + reference, v_d likewise with
Q̇_b (:func:`contactdyn.model.phases.reference_at`). Its acceleration axis · Q̈_b is an unknown of the solve: the
readable model folds the command's part proportional to it (``dynamics.carried_command``); the pipeline packs a
carried reference only for laws that do not read a_d (task PD, a held command), where that part is zero.
"""

from __future__ import annotations

from ...numerics.compile_cache import njit
from .pack import CARRIER, NQ, R_CARRIER

__all__ = ["carry"]


@njit(cache=True)
def carry(x, ints, reals, x_d, v_d):
    """x_d += axis · Q_b [m], v_d += axis · Q̇_b [m/s] when a body carries the reference (in place)."""
    i = ints[CARRIER]
    if i < 0 or x_d.size == 0:
        return
    axis = reals[ints[R_CARRIER]:ints[R_CARRIER] + 3]
    for k in range(3):
        x_d[k] = x_d[k] + axis[k] * x[i]
        v_d[k] = v_d[k] + axis[k] * x[ints[NQ] + i]
