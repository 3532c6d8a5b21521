"""A circle move of the reference packed (``kind = "circle"``, :class:`~contactdyn.laws.trajectory.Move`).

Its rows come from the trajectory's own compiled profile, :func:`contactdyn.laws.trajectory.circle_reference` (the
point turning about the move's normal on a trapezoidal angle). Packed per move (``pack._reference``): a flag (1 a
circle), the turns' angle [rad] and the move's (c, u, w, p) terms (3 × 4, ``Move._circle_terms``).
"""

from __future__ import annotations

import numpy as np

from ...laws.trajectory import circle_reference
from ...numerics.compile_cache import njit

__all__ = ["CIRCLE_W", "add_circle"]

CIRCLE_W = 14  #: a move's reals in the circle section: flag, span [rad], terms (3 × 4 by rows)


@njit(cache=True)
def add_circle(t, move, circle, x_d, v_d, a_d):
    """The circle's displacement [m], velocity [m/s] and acceleration [m/s²] at t [s] added to (x_d, v_d, a_d);
    ``move`` its row of the move table (code, start [s], duration [s], accel fraction)."""
    out = circle_reference(t, move[1], move[2], move[3], circle[1], circle[2:CIRCLE_W].reshape((3, 4)),
                           np.zeros(0))
    for i in range(3):
        x_d[i] += out[i]
        v_d[i] += out[3 + i]
        a_d[i] += out[6 + i]
