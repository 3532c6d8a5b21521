"""One right-hand-side call, written once over a mode's packed arrays (:mod:`.pack`): the pipeline.

    robot terms -> frames -> contacts (chains, bond rows, friction rows) -> limit rows -> stuck joints' rows
    -> controller (τ, ż, a force-reading law's fold B, a carried reference's column) -> joint damping and sliding
    friction -> drives and the KKT assembly and solve (the fold through the drives, the clips re-checked)
    -> rates ẋ = [Q̇, Q̈, ẏ] (the energy audit's last) and the event values

:func:`call` is numba-compiled once for every scene and every law (the laws enter by address: stage and friction
laws through :mod:`contactdyn.laws.abi`, a user controller through :mod:`contactdyn.laws.controllers.abi`, a drive
kind through :mod:`contactdyn.laws.drive_abi`); under ``NUMBA_DISABLE_JIT=1`` the same source runs interpreted, and
so it does in a process where numba is on for a :class:`Pipeline` given ``twins`` (:mod:`contactdyn.numerics.twins`:
a scene kind's first run, :mod:`contactdyn.first_run`).
:class:`Pipeline` packs a mode once and calls it; its ``events`` name the event values (gaps [m], normal forces
[N], slip velocities [m/s], friction or stick forces [N], limit torques [N·m or N]). A singular KKT matrix
(redundant rows, consistent or not) is solved in the call by the minimum-norm least squares
(:func:`.kkt.solve_linear`), and counted (``Pipeline.least_squares``: ``Result.stats["singular_solves"]``). A call
with no answer (:meth:`Pipeline.failed_call`) raises a law's own error where a law failed, a user's law's as its
:class:`~contactdyn.laws.failures.LawError` (its name, file and line): a declared Python stage's (one numba cannot
compile, called back through ctypes: :mod:`contactdyn.laws.abi`) exception, a compiled law's (the call run again
interpreted), the controller's words where its command was not finite (an operational task singular there); else (a
KKT system with a non-finite entry, status 0: an overflowed trial state) its rates are NaN, which the step control
rejects, and it is counted; a law that returned NaN or ±inf there is named (``Pipeline.non_finite``).
"""

from __future__ import annotations

import math
import traceback
from contextlib import contextmanager, nullcontext

import numpy as np
from numba import types

from ...errors import SimulationError
from ...laws.abi import checking_laws, raise_python_stage_error
from ...laws.drive_abi import checking_drives
from ...laws.failures import LawError, is_users, kinetic_coefficient, naming_laws, no_command_error, non_finite_error
from ...numerics.compile_cache import njit
from ...numerics.linalg import put
from ...numerics.native_call import address, call_at, declare, giving_handles
from ...numerics.twins import Twins, run_as
from ..contact import structure
from .actuation import (
    carry,
    drive_command,
    drives,
    joint_pd_terms,
    open_loop_terms,
    reference,
    set_points,
    task_force_terms,
    task_pd_terms,
)
from .contacts import add_riding, contact_terms, finish, limit_rows
from .drives import drive_values, inertias
from .energy import energy_rates
from .force_fold import carried_coordinate, controller_terms, fold_rates, solve_through_drives
from .joint_friction import joint_events, joint_rows, joint_torques
from .kkt import LEAST_SQUARES, NOT_FINITE, coulomb_split, kkt_solve
from .launch import ST_DONE, ST_HEAD, launch_settled, launch_start, launch_took
from .pack import (
    A_CALL,
    A_CONTROLLER,
    A_ENERGY,
    A_LAUNCH,
    A_LAUNCH_SETTLED,
    A_LAUNCH_START,
    A_SOLVE,
    A_SPLIT,
    ANY_MOTOR,
    CARRIER,
    CTL_ABI,
    CTL_JOINT_PD,
    CTL_KIND,
    CTL_TASK_FORCE,
    CTL_TASK_PD,
    D_CMD,
    D_FD,
    D_LAM,
    D_TAU,
    D_TC,
    D_TIP,
    D_XD,
    ENERGY,
    EV_FF,
    EV_FN,
    EV_GAP,
    EV_VT,
    EV_W,
    N_CONTACTS,
    N_DRIVES,
    N_HELD,
    N_LAUNCH,
    N_LIMITS,
    N_ROWS,
    NF,
    NQ,
    NV,
    NX,
    NY,
    R_REFLECTED,
    R_WEIGHTS,
    READS_FORCES,
    REF_DIMS,
    TIP_FRAME,
    W_DIAG,
    W_DRIVES,
    W_LEAST_SQUARES,
    W_SPLITS,
    diag_starts,
    pack,
    python_stages,
    set_slip_references,
    unsupported,
)
from .robot_terms import frame_terms, robot_part, robot_terms

__all__ = ["call", "rates_at", "samples_at", "law_at", "stage_addresses", "call_time", "unusable_friction", "Pipeline"]


@njit(cache=True)
def call(t, x, ints, reals, work, events):
    """ẋ at (t [s], x) of the packed mode; the event values and the status (last) into ``events``. A 2-D slide
    launching from rest first finds its direction (:mod:`.launch`): the loop's trial passes on a copy of ``reals``,
    then the pass with the directions found (one pass without a launch; one body, compiled once). The controller's
    kind, the solve through a fold, a launch's Newton and the energy audit are stages reached by address
    (:func:`stage_addresses`: compiled on their own, for the scenes that have them)."""
    nv, nQ, nr, nc = ints[NV], ints[NQ], ints[N_ROWS], ints[N_CONTACTS]
    if ints[N_LAUNCH]:
        reals, state = call_at(ints[A_LAUNCH_START], "pipeline.launch_start", (ints, reals))
    else:
        state = np.zeros(ST_HEAD)
    while True:
        final = state[ST_DONE] >= ints[N_LAUNCH]
        H, h, g, Jw, W = robot_terms(x, ints, reals)  # (over the robot's and the articulated bodies' columns)
        M, Hc = inertias(H, ints[ANY_MOTOR], reals[ints[R_REFLECTED]:], nv)  # rotors reflected: true M, the law's H
        FJ, Fa, Fp, Fv, FR = frame_terms(x, ints, reals, W, Jw)
        if not final:  # (before the first pass: a contact already past the stick band gets its r back, no Newton)
            final = call_at(ints[A_LAUNCH_SETTLED], "pipeline.launch_settled", (x, ints, state, reals, FJ, Fa, Fp, Fv,
                                                                                FR))
        f = np.zeros(nQ)
        for i in range(nv):
            f[i] = -h[i]
        weights = ints[R_WEIGHTS]
        for i in range(nQ - nv):  # the bodies' weights m g·axis [N] (0 for the other coordinates)
            f[nv + i] = reals[weights + i]
        for i in range(nv, ints[NF]):  # the articulated bodies' −h_b (0 for a translating body's coordinate)
            f[i] -= h[i]
        M = add_riding(x, ints, reals, FJ, Fa, FR, M, f)  # (a chain's mass riding a turning surface: M over Q)
        ydot = np.zeros(ints[NY])
        G, C, gamma = np.zeros((nr, nQ)), np.zeros((nr, nQ)), np.zeros(nr)
        pending = np.zeros((nc, 5))
        xdot = np.empty(ints[NX])
        if not contact_terms(x, ints, reals, work, FJ, Fa, Fp, Fv, FR, f, ydot, G, C, gamma, events, pending):
            events[events.size - 1] = -1.0
            return xdot
        first_joint = nr - ints[N_HELD]
        first_limit = first_joint - ints[N_LIMITS]
        if work[ints[W_DIAG]] != 0.0:  # (diagnostics: the contacts' generalized force on the joints, f holds −h)
            at_tc = diag_starts(ints)[D_TC]
            for i in range(nv):
                work[at_tc + i] = f[i] + h[i]
        limit_rows(x, ints, reals, first_limit, G, C, gamma)
        joint_rows(x, ints, reals, first_joint, G, C, gamma)
        Hr, hr, gr, FJr = robot_part(ints, Hc, h, g, FJ)  # the controller sees the robot alone
        tau, zdot, B, D, bq, dq = call_at(ints[A_CONTROLLER], "pipeline.controller",
                                          (t, x, ints, reals, work, Hr, hr, gr, FJr, Fa, Fp, Fv, FR, f, C, events))
        joint_torques(x, ints, reals, f)
        ok, applied, qdd, lam, outcome = call_at(ints[A_SOLVE], "pipeline.solve",
                                                 (x, ints, reals, work, M, f, G, C, gamma, tau, B, bq))
        if not ok:
            events[events.size - 1] = -1.0
            return xdot
        split = False
        if outcome == LEAST_SQUARES and ints[A_SPLIT]:  # (redundant holds: split by their limits)
            lam, split = call_at(ints[A_SPLIT], "pipeline.split", (ints, reals, events, C, lam, first_limit,
                                                                   first_joint))
        fold_rates(ints, lam, zdot, D, ydot, dq, qdd, carried_coordinate(ints, bq))
        for i in range(nQ):
            xdot[i] = x[nQ + i]
        put(xdot, nQ, qdd)
        put(xdot, 2 * nQ, ydot)
        finish(ints, lam, xdot, events, pending, first_limit)
        if ints[ENERGY] >= 0:
            call_at(ints[A_ENERGY], "pipeline.energy", (x, ints, reals, work, applied, xdot, events, pending))
        joint_events(x, ints, reals, lam, first_joint, events, EV_W * nc + ints[N_LIMITS], xdot)
        if work[ints[W_DIAG]] != 0.0:  # an output sample's call (samples_at): the diagnostics too
            record(t, x, ints, reals, work, applied, tau, Fp[ints[TIP_FRAME]], lam, C, first_limit)
        events[events.size - 1] = 0.0 if outcome == NOT_FINITE else 1.0
        if final or outcome == NOT_FINITE or call_at(ints[A_LAUNCH], "pipeline.launch_took",
                                                     (x, ints, state, reals, FJ, Fa, Fp, Fv, FR, xdot)):
            if outcome == LEAST_SQUARES:  # (the result's pass only: a launch's trials are not counted)
                work[ints[W_LEAST_SQUARES]] += 1.0
                if split:
                    work[ints[W_SPLITS]] += 1.0
            return xdot


@njit(cache=True)
def record(t, x, ints, reals, work, applied, tau, p_tip, lam, C, first_limit):
    """The diagnostics of a call at (t [s], x) into ``work``'s section (:func:`.pack.diag_starts`; written when its
    switch is on: an output sample's call, :func:`samples_at`): the drives' applied forces [N·m or N] (the joints',
    then the bodies' servo forces [N]), the command [N·m or N], the tip [m], x_d [m] (carried by its body, if one
    carries it), F_d [N], the rows' forces λ (normal and stick forces [N], limit and holding torques [N·m or N],
    tangential bonds' interface forces [N]), and the contacts' generalized force on the joints as a sampled law
    measures it [N·m or N]: the deformable and friction forces (written by the call after the contacts), plus the
    forces λ of the contacts' rows (before ``first_limit``) whose columns C reach beyond the robot
    (``PipelineMode.measurement``). Each chain's interface force [N] is written by every call
    (:func:`.contacts.contact_terms`), the stage states (x [m], ẋ [m/s], F [N]) are in ``work`` already."""
    at = diag_starts(ints)  # (put: no slice assignment, see numerics.linalg.put)
    put(work, at[D_TAU], applied)
    put(work, at[D_CMD], tau)
    put(work, at[D_TIP], p_tip)
    if ints[REF_DIMS]:
        x_d, v_d, _ = reference(t, ints, reals)
        carry(x, ints, reals, x_d, v_d)
        put(work, at[D_XD], x_d)
    put(work, at[D_FD], set_points(t, ints, reals)[0])
    put(work, at[D_LAM], lam)
    nv = ints[NV]
    for r in range(first_limit):
        reaches = False
        for c in range(nv, C.shape[1]):
            reaches = reaches or C[r, c] != 0.0
        for c in range(nv if reaches else 0):
            work[at[D_TC] + c] += C[r, c] * lam[r]


@njit(cache=True)
def rates_at(ts, X, ints, reals, work, events):
    """ẋ at each (ts[k], X[k]) in one compiled call (the output samples' and a compiled step's way: no Python
    between calls); the number of states done before a call's status was not 1."""
    out = np.empty(X.shape)
    for k in range(ts.size):
        put(out[k], 0, call_at(ints[A_CALL], "pipeline.call", (ts[k], X[k], ints, reals, work, events)))
        if events[events.size - 1] != 1.0:
            return out, k
    return out, ts.size


@njit(cache=True)
def samples_at(ts, X, ints, reals, work, events):
    """(ẋ, event values, work) at each (ts[k], X[k]) with the diagnostics on (:func:`record`: the output
    samples' way), and the number of states done before a call's status was not 1."""
    n = ts.size
    Xd, E, W = np.empty(X.shape), np.zeros((n, events.size)), np.zeros((n, work.size))
    work[ints[W_DIAG]] = 1.0
    done = n
    for k in range(n):
        put(Xd[k], 0, call_at(ints[A_CALL], "pipeline.call", (ts[k], X[k], ints, reals, work, events)))
        if events[events.size - 1] != 1.0:
            done = k
            break
        put(E[k], 0, events)
        put(W[k], 0, work)
    work[ints[W_DIAG]] = 0.0
    return Xd, E, W, done


@njit(cache=True)
def law_at(t, x, ints, reals, work, events, tau_contact):
    """A sampled law's command at a sample instant: (τ [N·m or N; V], ż, b, d) of the phase's controller stage (the
    mode packed with the sampled law itself, as if continuous) at (t [s], x), on measured forces instead of the
    fold: ``events`` holds each contact's measured normal force [N] (EV_FN), ``work`` each tangential chain's
    interface force [N], ``tau_contact`` the contacts' generalized force on the joints [N·m or N] (empty: not
    read). b and d per unit acceleration of a body carrying the reference (τ += b Q̈_b: what the law measures); and
    whether τ is finite (not: the law failed there)."""
    own = ints.copy()  # (measured, not folded: the command is held, not a function of the solve's forces)
    own[READS_FORCES] = 0
    H, h, g, Jw, W = robot_terms(x, own, reals)
    _, Hc = inertias(H, ints[ANY_MOTOR], reals[ints[R_REFLECTED]:], ints[NV])
    FJ, Fa, Fp, Fv, FR = frame_terms(x, own, reals, W, Jw)
    Hr, hr, gr, FJr = robot_part(own, Hc, h, g, FJ)
    f = np.zeros(ints[NQ])
    for i in range(tau_contact.size):  # (the stage reads τ_c as f + h: f holds −h and the contacts' forces)
        f[i] = tau_contact[i] - hr[i]
    C = np.zeros((0, ints[NQ]))
    tau, zdot, _, _, bq, dq = call_at(own[A_CONTROLLER], "pipeline.controller",
                                      (t, x, own, reals, work, Hr, hr, gr, FJr, Fa, Fp, Fv, FR, f, C, events))
    finite = True
    for v in tau:
        finite = finite and np.isfinite(v)
    return tau, zdot, bq, dq, finite


# ---- the stages reached by address (numerics.native_call): compiled on their own, for the modes that have them -----
# The controller's kinds (.actuation: task PD, joint PD, task force, open loop; a law of the ABI:
# .force_fold.controller_terms), each a stage of one signature and result (τ, ż, B, D, b, d): a scene compiles its
# own kind only.
@njit(cache=True)
def solve_direct(x, ints, reals, work, M, f, G, C, gamma, tau, B, bq):
    """force_fold.solve_through_drives where nothing folds (no force-reading law, no carried column): the command
    through the drives into f, then one KKT solve."""
    cmd = drive_command(x, ints, reals, tau)
    ok, applied = drives(x, ints, reals, work, cmd, cmd, f)
    qdd, lam, outcome = kkt_solve(ints, reals, M, f, G, C, gamma, B, bq, np.int64(-1))  # (-1: compiled again)
    return ok, applied, qdd, lam, outcome


_F1, _F2, _F3, _I1, _F = types.float64[::1], types.float64[:, ::1], types.float64[:, :, ::1], types.int64[::1], \
    types.float64
_CONTROLLER = types.Tuple((_F1, _F1, _F2, _F2, _F1, _F1))(_F, _F1, _I1, _F1, _F1, _F2, _F1, _F1, _F3, _F2, _F2, _F2,
                                                          _F3, _F1, _F2, _F1)
_SOLVE = types.Tuple((types.boolean, _F1, _F1, _F1, types.int64))(_F1, _I1, _F1, _F1, _F2, _F1, _F2, _F2, _F1, _F1,
                                                                    _F2, _F1)
declare("pipeline.call", call, _F1(_F, _F1, _I1, _F1, _F1, _F1))
declare("pipeline.controller", controller_terms, _CONTROLLER)  # (the declared name of every controller stage)
CONTROLLER_STAGES = {CTL_ABI: controller_terms, CTL_TASK_PD: task_pd_terms, CTL_JOINT_PD: joint_pd_terms,
                     CTL_TASK_FORCE: task_force_terms}  #: the controller's kind -> its stage (else open_loop_terms)
declare("pipeline.solve", solve_through_drives, _SOLVE)
declare("pipeline.launch_start", launch_start, types.Tuple((_F1, _F1))(_I1, _F1))
declare("pipeline.launch_took", launch_took, types.boolean(_F1, _I1, _F1, _F1, _F3, _F2, _F2, _F2, _F3, _F1))
declare("pipeline.launch_settled", launch_settled, types.boolean(_F1, _I1, _F1, _F1, _F3, _F2, _F2, _F2, _F3))
declare("pipeline.energy", energy_rates, types.none(_F1, _I1, _F1, _F1, _F1, _F1, _F1, _F2))
declare("pipeline.split", coulomb_split, types.Tuple((_F1, types.boolean))(_I1, _F1, _F1, _F2, _F1, types.int64,
                                                                             types.int64))


def stage_addresses(ints: np.ndarray, law_only: bool = False) -> None:
    """The addresses of the call and of the stages the packed mode ``ints`` needs, into its A_* slots (each stage
    compiled, or loaded from the cache, at its first use in the process). ``law_only``: the controller's stage alone
    (a sampled law's pipeline: :func:`law_at` calls nothing else)."""
    kind = int(ints[CTL_KIND])
    ints[A_CONTROLLER] = _address_of("pipeline.controller", CONTROLLER_STAGES.get(kind, open_loop_terms), _CONTROLLER)
    if law_only:
        return
    ints[A_CALL] = address("pipeline.call")
    folds = kind == CTL_ABI and (ints[READS_FORCES] != 0 or ints[CARRIER] >= 0)
    ints[A_SOLVE] = _address_of("pipeline.solve", solve_through_drives if folds else solve_direct, _SOLVE)
    if ints[N_LAUNCH]:
        ints[A_LAUNCH_START], ints[A_LAUNCH] = address("pipeline.launch_start"), address("pipeline.launch_took")
        ints[A_LAUNCH_SETTLED] = address("pipeline.launch_settled")
    if ints[ENERGY] >= 0:
        ints[A_ENERGY] = address("pipeline.energy")
    if ints[N_ROWS] > 1 and not ints[READS_FORCES]:  # (a fold's τ reads λ: its split would move the robot)
        ints[A_SPLIT] = address("pipeline.split")


def _address_of(name: str, function, signature) -> int:
    """The address of one of the functions a call site ``name`` may reach (they share its declared signature)."""
    own = f"{name}.{getattr(function, 'py_func', function).__name__}"
    declare(own, function, signature)
    return address(own)


def call_time(exc: BaseException) -> float | None:
    """t [s] of the innermost :func:`call` in ``exc``'s traceback (an interpreted call, where a law raised), or None."""
    code = getattr(call, "py_func", call).__code__
    times = [frame.f_locals.get("t") for frame, _ in traceback.walk_tb(exc.__traceback__) if frame.f_code is code]
    return float(times[-1]) if times and times[-1] is not None else None


def unusable_friction(system, modes, events, t: float) -> None:
    """The LawError of a sliding contact's friction law that gives μ < 0, NaN or ±inf at the slip speed the call with
    no answer at t [s] wrote into ``events`` (its :func:`.contacts._friction` stops there, compiled or interpreted: the
    law is called again in Python, :func:`~contactdyn.laws.failures.kinetic_coefficient`); nothing where none does."""
    for ci, (c, m) in enumerate(zip(system.contacts, modes, strict=True)):
        fr, nt = c.friction, len(c.tangents)
        if fr is None or fr.constant or not nt or not m.touching or m.stuck:
            continue
        at = EV_W * ci + EV_VT
        kinetic_coefficient(fr, c.name, math.sqrt(sum(float(v) * float(v) for v in events[at:at + nt])), t)


class Pipeline:
    """One mode packed and its call: ``rhs(t, x)`` the integrator's function, ``values()`` the last call's events.
    ``twins`` (:class:`~contactdyn.numerics.twins.Twins`): the call runs interpreted, as its twins (the mode packed
    with handles, nothing of it compiled but the twins' leaves); :meth:`of` gives a function of the package as this
    pipeline runs it. ``law_only``: only the controller's stage gets an address (a sampled law's pipeline, which
    runs :func:`law_at` alone: nothing else is compiled for it)."""

    def __init__(self, system, modes, phase, twins=None, law_only: bool = False):
        self.twins = twins
        self.system, self.modes, self.phase = system, list(modes), phase
        with giving_handles() if twins is not None else nullcontext():
            reason = self.of(unsupported)(system, modes, phase)
            if reason:
                raise ValueError(f"the compiled call does not run this mode: {reason}")
            self.packed = self.of(pack)(system, modes, phase)
            self.of(stage_addresses)(self.packed.ints, law_only)
            #: the laws run as declared Python stages (numba cannot compile them), with numba's reasons
            self.python_stages = [] if twins is not None else python_stages(system, modes, phase)
        self.failed_calls = 0  #: calls with no answer (a KKT system that is not finite): NaN rates, steps rejected
        #: (t [s], x) of the last call with no answer from a finite state in which a law gave NaN (status -1), or None:
        #: a run that fails names the law there (:meth:`non_finite`)
        self.last_failed: tuple[float, np.ndarray] | None = None
        self._twin: Pipeline | None = None  #: this mode packed for the call interpreted (:meth:`_probe`), once made
        self._call = self.of(call)

    def of(self, function):
        """``function`` (of the package) as this pipeline runs it: itself, or interpreted its twin."""
        return run_as(self.twins, function)

    @property
    def least_squares(self) -> int:
        """The calls whose KKT matrix was singular, solved in the call by the minimum-norm least squares (the
        ``Evaluation.regular = False``; every call since the packing, compiled steps' too)."""
        return int(self.packed.work[self.packed.ints[W_LEAST_SQUARES]])

    @property
    def holds_split(self) -> int:
        """Of those, the calls whose redundant holds were split by their limits (:func:`.kkt.coulomb_split`)."""
        return int(self.packed.work[self.packed.ints[W_SPLITS]])

    def use(self, modes) -> None:
        """Run with these modes from now on: the same :func:`~contactdyn.model.contact.structure`, their own 2-D
        reference directions r (written into ``reals``)."""
        if structure(modes) != structure(self.modes):
            raise ValueError(f"a pipeline runs modes of its own structure only; packed for {self.modes}, given {modes}")
        set_slip_references(self.packed.ints, self.packed.reals, modes)
        self.modes = list(modes)

    def rhs(self, t: float, x: np.ndarray) -> np.ndarray:
        """ẋ at (t [s], x)."""
        p = self.packed
        xdot = self._call(float(t), x, p.ints, p.reals, p.work, p.events)
        return xdot if p.events[-1] == 1.0 else self.failed_call(t, x)

    def failed_call(self, t: float, x: np.ndarray, final: bool = False) -> np.ndarray:
        """ẋ where the call at (t [s], x) gave no answer (its status not 1). A law's own error is raised there (a user's
        law's as its LawError): a Python stage's; a friction law's μ < 0, NaN or ±inf (:func:`unusable_friction`); a
        compiled law's, which its C function cannot carry out (status -1; a user's controller with no finite command):
        the same call run once interpreted at (t, x) raises it from the law's source (:meth:`_probe`); the controller's
        words where its command was not finite (:meth:`controller_error`). Else the contact system was not finite (an
        overflowed trial state, a law's NaN): NaN rates, which the step control rejects; a law that returned NaN or ±inf
        there is named where the caller cannot go on (``final``), else the state is kept (``last_failed``: a run that
        fails names it)."""
        raise_python_stage_error(t)
        status = self.packed.events[-1]
        if status < 0.0:  # (a friction law's μ < 0, NaN or ±inf stopped the call: .contacts._friction)
            unusable_friction(self.system, self.modes, self.packed.events, t)
        failed = self.controller_error(t, x)
        if status < 0.0 and np.all(np.isfinite(x)):
            self.last_failed = (float(t), np.array(x, float))
        users = failed is not None and is_users(type(self.phase.controller))
        if ((status < 0.0 or users) and self.twins is None) or (status < 0.0 and final):  # (run again interpreted)
            found = self._probe(t, x, final)
            if found is not None and failed is None:
                raise found
        if failed is not None:
            raise failed
        self.failed_calls += 1
        return np.full(np.size(x), np.nan)

    def non_finite(self) -> LawError | None:
        """The LawError of a law that returned NaN or ±inf in the last call with no answer from a finite state
        (``last_failed``, run again interpreted: :meth:`_probe`), else None."""
        return None if self.last_failed is None else self._probe(*self.last_failed, check=True)

    def _probe(self, t: float, x: np.ndarray, check: bool = False) -> LawError | None:
        """The call at (t [s], x) once more interpreted: a law's exception raised as its LawError; ``check``: the
        laws' and drive kinds' results checked, the LawError of the first that returned NaN or ±inf from finite
        inputs (else None)."""
        if self._twin is None:
            self._twin = Pipeline(self.system, self.modes, self.phase, Twins())
        probe = self._twin
        probe.use(self.modes)  # (a turn's reference directions)
        p = probe.packed
        with _checking(check) as notes, naming_laws(t):
            probe._call(float(t), np.array(x, float), p.ints, p.reals, p.work, p.events)
        raise_python_stage_error(t)  # (its controller a Python stage there: its exception kept)
        return non_finite_error(*notes[0], t) if notes else None

    def controller_error(self, t: float, x: np.ndarray) -> SimulationError | None:
        """The phase's controller's own words where its command at (t [s], x) is not finite (the call with its
        diagnostics on: an operational task singular there; a user's law: its τ and the joints' q, v), else None."""
        p = self.packed
        p.work[p.ints[W_DIAG]] = 1.0
        try:
            self._call(float(t), np.array(x, float), p.ints, p.reals, p.work, p.events)
        finally:
            p.work[p.ints[W_DIAG]] = 0.0
        at, nv, nQ = self.of(diag_starts)(p.ints)[D_CMD], self.system.nv, p.ints[NQ]
        tau = p.work[at:at + nv]
        return None if np.all(np.isfinite(tau)) else no_command_error(self.phase.controller, tau, x[:nv],
                                                                       x[nQ:nQ + nv], t)

    def values(self) -> dict[str, object]:
        """The last call's event values by name: per contact gap [m], F_n [N], v_t [m/s], F_f [N]; limit torques,
        the stuck joints' holding torques [N·m or N] and the sliding joints' speeds [rad/s or m/s], by joint; with
        motors, the drives' outputs (``.drives.drive_values``)."""
        p, out = self.packed, {}
        for ci, name in enumerate(p.contacts):
            ev = p.events[EV_W * ci:EV_W * (ci + 1)]
            out[name] = {"gap": ev[EV_GAP], "F_n": ev[EV_FN], "v_t": ev[EV_VT:EV_VT + 2].copy(),
                         "F_f": ev[EV_FF:EV_FF + 2].copy()}
        at_limit, at_held, at_sliding = p.joint_event_starts()
        out["limit"] = {i: p.events[at_limit + k] for k, i in enumerate(p.limits)}
        out["joint_hold"] = {i: p.events[at_held + k] for k, i in enumerate(p.held)}
        out["joint_speed"] = {i: p.events[at_sliding + k] for k, i in enumerate(p.sliding)}
        if p.ints[ANY_MOTOR]:
            out["drives"] = drive_values(p.work[p.ints[W_DRIVES]:], p.ints[N_DRIVES])
        return out


@contextmanager
def _checking(check: bool):
    """Inside: (``check``) the stage and friction laws' and the drive kinds' plain-Python calls checked, the first
    non-finite result from finite inputs noted in the list given (:func:`~contactdyn.laws.abi.checking_laws`,
    :func:`~contactdyn.laws.drive_abi.checking_drives`); else nothing checked, the list empty."""
    if not check:
        yield []
        return
    with checking_laws() as notes, checking_drives(notes):
        yield notes
