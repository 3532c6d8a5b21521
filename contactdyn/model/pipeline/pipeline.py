"""One right-hand-side call, written once over a mode's packed arrays (:mod:`.pack`): the pipeline.

    robot terms -> frames -> contacts (chains, bond rows, friction rows) -> limit rows -> controller (τ, ż and a
    force-reading law's fold B) -> drives -> KKT assembly and solve -> rates ẋ = [Q̇, Q̈, ẏ] and the event values

:func:`call` is numba-compiled once for every scene and every law (the laws enter by address: stage and friction
laws through :mod:`contactdyn.laws.abi`, a user controller through :mod:`contactdyn.laws.controllers.abi`); under
``NUMBA_DISABLE_JIT=1`` the same source runs interpreted. :class:`Pipeline` packs a mode once and calls it; its
``events`` name the event values (gaps [m], normal forces [N], slip velocities [m/s], friction or stick forces
[N], limit torques [N·m or N]). A call whose KKT matrix is singular (status 0), or whose compiled stage law gave no
force (status -1), is answered by the readable model (:meth:`System.evaluate`), and counted.
"""

from __future__ import annotations

import numpy as np

from ...numerics.compile_cache import njit
from .actuation import drives
from .contacts import contact_terms, finish, limit_rows
from .force_fold import controller_terms, fold_rates
from .kkt import kkt_solve
from .pack import EV_FF, EV_FN, EV_GAP, EV_VT, EV_W, N_CONTACTS, N_LIMITS, N_ROWS, NQ, NV, NX, NY, pack, unsupported
from .robot_terms import frame_terms, robot_terms

__all__ = ["call", "rates_at", "Pipeline"]


@njit(cache=True)
def call(t, x, ints, reals, work, events):
    """ẋ at (t [s], x) of the packed mode; the event values and the status (last) into ``events``."""
    nv, nQ, nr, nc = ints[NV], ints[NQ], ints[N_ROWS], ints[N_CONTACTS]
    H, h, g, Jw, W = robot_terms(x, ints, reals)
    FJ, Fa, Fp, Fv, FR = frame_terms(x, ints, reals, W, Jw)
    f = np.zeros(nQ)
    f[:nv] = -h
    ydot = np.zeros(ints[NY])
    G, C, gamma = np.zeros((nr, nQ)), np.zeros((nr, nQ)), np.zeros(nr)
    pending = np.zeros((nc, 5))
    xdot = np.empty(ints[NX])
    if not contact_terms(x, ints, reals, work, FJ, Fa, Fp, Fv, f, ydot, G, C, gamma, events, pending):
        events[events.size - 1] = -1.0
        return xdot
    first_limit = nr - ints[N_LIMITS]
    limit_rows(x, ints, reals, first_limit, G, C, gamma)
    tau, zdot, B, D = controller_terms(t, x, ints, reals, H, h, g, FJ, Fa, Fp, Fv, FR, f, C, events)
    drives(x, ints, reals, tau, f)
    qdd, lam, regular = kkt_solve(ints, reals, H, f, G, C, gamma, B)
    fold_rates(ints, lam, zdot, D, ydot)
    xdot[:nQ] = x[nQ:2 * nQ]
    xdot[nQ:2 * nQ] = qdd
    xdot[2 * nQ:] = ydot
    finish(ints, lam, xdot, events, pending, first_limit)
    events[events.size - 1] = 1.0 if regular else 0.0
    return xdot


@njit(cache=True)
def rates_at(ts, X, ints, reals, work, events):
    """ẋ at each (ts[k], X[k]) in one compiled call (the output samples' and a compiled step's way: no Python
    between calls); the number of states done before a call's status was not 1."""
    out = np.empty(X.shape)
    for k in range(ts.size):
        out[k] = call(ts[k], X[k], ints, reals, work, events)
        if events[events.size - 1] != 1.0:
            return out, k
    return out, ts.size


class Pipeline:
    """One mode packed and its call: ``rhs(t, x)`` the integrator's function, ``values()`` the last call's events."""

    def __init__(self, system, modes, phase):
        reason = unsupported(system, modes, phase)
        if reason:
            raise ValueError(f"the pipeline prototype does not run this mode: {reason}")
        self.system, self.modes, self.phase = system, list(modes), phase
        self.packed = pack(system, modes, phase)
        self.fallbacks = 0  #: calls answered by the readable model (singular KKT matrix, a law that failed)

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        """ẋ at (t [s], x)."""
        p = self.packed
        xdot = call(float(t), x, p.ints, p.reals, p.work, p.events)
        if p.events[-1] != 1.0:
            self.fallbacks += 1
            return self.system.evaluate(t, x, self.modes, self.phase).xdot
        return xdot

    def values(self) -> dict[str, object]:
        """The last call's event values by name: per contact gap [m], F_n [N], v_t [m/s], F_f [N]; limit torques."""
        p, out = self.packed, {}
        for ci, name in enumerate(p.contacts):
            ev = p.events[EV_W * ci:EV_W * (ci + 1)]
            out[name] = {"gap": ev[EV_GAP], "F_n": ev[EV_FN], "v_t": ev[EV_VT:EV_VT + 2].copy(),
                         "F_f": ev[EV_FF:EV_FF + 2].copy()}
        out["limit"] = {i: p.events[EV_W * len(p.contacts) + k] for k, i in enumerate(p.limits)}
        return out
