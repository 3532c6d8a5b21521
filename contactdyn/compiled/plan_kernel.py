"""A plan's call after Pinocchio, compiled: the controller's command through the drives, folded or not.

For a mode whose drives are a matrix L (:mod:`contactdyn.compiled.plan_drives`) and whose controller is
either a force-reading tip law read off as a matrix M (A7, A10, hybrid: :mod:`contactdyn.compiled.plan_law`)
or the affine task PD law (its tip force g_ctl among the plan's outputs), everything a call does
after φ is small dense algebra:

    y = P φ = [A, b, o]                          the KKT system and the affine outputs
    tip law:   u = time part + U_x x + tip + measured forces;  [a*, f_swap, ż] = M u
               τ_c = Σ_f J_fᵀ w_f;  τ = computed torque (contactdyn.laws.controllers.computed_torque);
               B = ∂τ/∂λ per row it reads (+ A's column of a row reaching beyond the robot), and
               ∂τ/∂Q̈_b of a reference carried by body coordinate Q_b (one more folded column)
    task law:  τ = J_tipᵀ g_ctl + F φ (its feedforward and joint damping), nothing folded
    A[:nQ, cols] −= L_τ B;   b[:nQ] += L[:nQ] [τ, x, 1];   z = A⁻¹ b;   ż += D_z z[cols]
    ẋ = [Q̇, Q̈, ẏ] with ż in its slots

:func:`call` runs it in one compiled function (numba), the law's time part (reference, force ramps) included;
:func:`call_at`, what the plan's right-hand side and output samples run, writes φ first (plan_phi.write_phi)
in the same function. The fold itself (:func:`fold_solve`) is
the one :mod:`contactdyn.compiled.plan_fold` runs for the output and the carried references. A call
where a voltage clips, or whose solve is singular or not finite, returns status 1 and goes the
plan's readable way (:mod:`contactdyn.compiled.plan_rhs`): the clip and the least-squares fallback stay
written once, there. A tip law's kernel is built when the law has read M (its first call).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse

from ..laws.controllers import computed_torque as law
from ..numerics.compile_cache import njit
from ..numerics.linalg import lu_solve, mm, mtv, mv, sparse_dot
from .plan_law import NO_REFERENCE, CompiledLaw, compiled_law, plan_inputs, write_time_part
from .plan_phi import work_terms, write_phi
from .plan_probe import affine_map

__all__ = ["fold_solve", "kernel_of", "calls", "call", "call_at", "pack", "pack_with_phi",
           "matrix_of", "vector_of", "csr_of", "kkt_of", "write_out", "KERNEL"]

OK, DECLINED = 0, 1  #: :func:`call`'s status
KERNEL = 1  #: this module's call among the compiled calls a step takes (plan_steps)
TIP_LAW, TASK_LAW = 0, 1  #: the controller's shape (INTS' kind)
#: the constants of a plan's call, packed by :func:`pack` into one float and one int buffer (two arguments: a
#: compiled function's call costs ~0.06 µs per argument): float arrays, then int arrays, by these indices
P_VAL, M_, U_VAL, U_C, L_, L_TAU, D_A, D_F, D_Z, ROTOR, D_CTL, K_NULL, F_FF = range(13)  # floats
T_MOVES, T_R, T_CIRCLE, T_TERMS, T_START, T_RAMPS = range(13, 19)  # floats: the time part's tables
#: floats: φ's time tables, its first frame, the robot's table (plan_phi.write_phi, contactdyn.robot.rigid_body)
PHI_MOVES, PHI_RAMPS, PHI_FRAME, PHI_RIGID = 19, 20, 21, 22
P_COL, P_ROW, INTS, FRAMES, FORCES, COLS, REACH = range(23, 30)  # ints (P: CSR values, columns, row starts)
U_COL, U_ROW = 30, 31  # ints: the state map's U_x by rows (U_VAL its values, U_C its constant column)
PHI_AT, PHI_MSLOTS, PHI_RSLOTS, PHI_SUPPORT = 32, 33, 34, 35  # ints: φ's layout, time slots, first frame's support
#: INTS, in this order (TIMED: the tip law's time part is computed in the call, plan_law.write_time_part, from
#: the reference's tables T_* of kind T_KIND and the ramps, F_d written from u[I_SET])
M, NQ, NV, I_H, I_J, I_DR, TIP, U_F, ZS, SWAP, N_LIM, O_Y0, O_Y1, X_Z0, X_Z1, W0, KIND, O_G, TIMED, I_SET, T_KIND = \
    range(21)


def pack(floats: list, ints: list) -> tuple[np.ndarray, np.ndarray]:
    """(fb, ib): the float arrays one after another in fb, the int arrays in ib after a table of
    (offset, rows, columns) per array, floats first (a vector has one row)."""
    floats = [np.atleast_2d(np.asarray(a, dtype=float)) for a in floats]
    ints = [np.atleast_2d(np.asarray(a, dtype=np.int64)) for a in ints]
    table, offset = [], 0
    for a in floats:
        table += [offset, *a.shape]
        offset += a.size
    offset = 3 * (len(floats) + len(ints))
    for a in ints:
        table += [offset, *a.shape]
        offset += a.size
    fb = np.concatenate([a.ravel() for a in floats]) if floats else np.zeros(0)
    ib = np.concatenate([np.array(table, dtype=np.int64)] + [a.ravel() for a in ints])
    return fb, ib


#: the packed buffers' accessors take explicit signatures: their index k is a module constant at each call site,
#: which numba would type as a literal and compile once per constant (~50 specializations, ~6 s of a first run)
_FB, _IB = "float64[::1]", "int64[::1]"


@njit([f"float64[:, ::1]({_FB}, {_IB}, int64)", f"int64[:, ::1]({_IB}, {_IB}, int64)"], cache=True)
def matrix_of(buf, ib, k):
    """Array k of :func:`pack`'s buffers (``buf``: fb for a float array, ib for an int array), as a (rows, columns)
    view."""
    o, r, c = ib[3 * k], ib[3 * k + 1], ib[3 * k + 2]
    return buf[o:o + r * c].reshape((r, c))


@njit([f"{_FB}({_FB}, {_IB}, int64)", f"{_IB}({_IB}, {_IB}, int64)"], cache=True)
def vector_of(buf, ib, k):
    """Array k of :func:`pack`'s buffers (``buf``: fb for a float array, ib for an int array), flat."""
    o, r, c = ib[3 * k], ib[3 * k + 1], ib[3 * k + 2]
    return buf[o:o + r * c]


def csr_of(plan) -> sparse.csr_matrix:
    """The plan's map P by rows (its ~1 % nonzeros), made once per plan for the kernels' constants."""
    P = plan.__dict__.get("_P_csr")
    if P is None:
        P = plan._P_csr = sparse.csr_matrix(plan.P)
    return P


@njit(f"Tuple(({_FB}, float64[:, ::1], {_FB}, {_FB}))({_FB}, {_FB}, {_IB}, int64, int64, int64, int64)", cache=True)
def kkt_of(phi, fb, ib, k_val, k_col, k_row, m):
    """(y, A, b, o) of y = P φ = [A, b, o] with P by rows in the packed arrays k_val, k_col, k_row (:func:`csr_of`);
    A (m, m) and b: copies, for the caller to fold into; o: the affine outputs, a view of y."""
    y = sparse_dot(vector_of(ib, ib, k_row), vector_of(ib, ib, k_col), vector_of(fb, ib, k_val), phi)
    return y, y[:m * m].copy().reshape((m, m)), y[m * m:m * m + m].copy(), y[m * m + m:]


@njit(cache=True, inline="always")
def write_out(out, x, z, y, o, tau, nQ, o_y0, o_y1):
    """[ẋ, z, o, τ] into ``out`` with ẋ = [Q̇, Q̈, ẏ] (ẏ = y[o_y0:o_y1]); returns ẋ (a view) for the caller's
    own slots (a law's ż, impulse rates)."""
    n, m = x.size, z.size
    xd = out[:n]
    xd[:nQ] = x[nQ:2 * nQ]
    xd[nQ:2 * nQ] = z[:nQ]
    xd[2 * nQ:] = y[o_y0:o_y1]
    out[n:n + m] = z
    out[n + m:n + m + o.size] = o
    out[n + m + o.size:] = tau
    return xd


@njit(cache=True)
def fold_solve(A, b, L, L_tau, tau, x, B, cols, nQ):
    """(z, y₀, Y): z of A z = b with the drives' forces at the command τ + B z[cols] [N·m or N] folded into
    rows :nQ (A, b changed in place; L: [forces; u/u_max] = L [τ, x, 1]; z nan where A is singular), and
    the drive values y₀ = L [τ, x, 1], Y = L_τ B: y₀ + Y z[cols] at the solved command (the voltages' clip
    test reads its rows nQ:)."""
    nv, n = tau.size, x.size
    txo = np.empty(nv + n + 1)
    txo[:nv] = tau
    txo[nv:nv + n] = x
    txo[-1] = 1.0
    y0 = mv(L, txo)
    Y = mm(L_tau, B)
    for k in range(cols.size):
        for i in range(nQ):
            A[i, cols[k]] -= Y[i, k]
    for i in range(nQ):
        b[i] += y0[i]
    return lu_solve(A, b), y0, Y


#: inline="always" (here and below): a helper compiled into its compiled callers, not as a level of its own
#: (numba compiles each function with all it calls: ~10 s of case1_cart's first run over these helpers)
@njit(cache=True, inline="always")
def _tip_law(phi, x, u, A, b, o, fb, ib, c):
    """(τ, B, [a*, f_swap, ż]) of the force-reading tip law: u the inputs' time part, the state part U_x x + u_c
    (U_x by rows: a few nonzeros); c: INTS."""
    nQ, nv = c[NQ], c[NV]
    uu = u + sparse_dot(vector_of(ib, ib, U_ROW), vector_of(ib, ib, U_COL), vector_of(fb, ib, U_VAL), x) + \
        vector_of(fb, ib, U_C)
    uu[:6] = phi[c[TIP]:c[TIP] + 6]  # p_tip [m], ṗ_tip [m/s]
    forces = vector_of(ib, ib, FORCES)
    for k in range(forces.size):
        uu[c[U_F] + k] = o[forces[k]]  # the measured forces [N]
    targets = mv(matrix_of(fb, ib, M_), uu)
    H = phi[:nv * nv].reshape((nv, nv)).T + matrix_of(fb, ib, D_CTL)  # φ holds H column by column
    J = phi[c[I_J]:c[I_J] + 3 * nv].reshape((3, nv))
    tau_c = np.zeros(nv)  # the contacts' torque [N·m or N]
    frames = vector_of(ib, ib, FRAMES)
    for f in range(frames.size):
        tau_c += mtv(phi[frames[f]:frames[f] + 3 * nv].reshape((3, nv)), b[c[W0] + 3 * f:c[W0] + 3 * f + 3])
    Jp = law.pinv(J)
    rotor = vector_of(fb, ib, ROTOR)
    f_swap = targets[3:6] if c[SWAP] else targets[0:0]
    tau = law.torque(H, rotor, phi[c[I_H]:c[I_H] + nv], tau_c, J, Jp, phi[c[I_DR]:c[I_DR] + 3], x[nQ:nQ + nv],
                     targets[:3], f_swap, vector_of(fb, ib, K_NULL)[0])
    B = law.increments(H, rotor, J, Jp, matrix_of(fb, ib, D_A), matrix_of(fb, ib, D_F))
    reach = vector_of(ib, ib, REACH)
    for k in range(reach.size):
        for i in range(nv):
            B[i, reach[k]] += A[i, nQ + reach[k]]
    return tau, B, targets


@njit(cache=True, inline="always")
def call(t, phi, x, u, fb, ib, out):
    """The status of the module docstring's call at t [s], its [ẋ, z, o, τ] written into ``out`` (τ: the joint
    command [N·m or N; V] at the solution, what the drives make of it); fb, ib: the plan's constants
    (:func:`pack`); u: a tip law's inputs' time part (plan_law.plan_inputs), written here where INTS' TIMED
    says. INTS: sizes and offsets (ZS the ż rows of [a*, f_swap, ż], −1 none; X_Z0:X_Z1 the law's states in
    x and ẋ; TIP the tip's p, ṗ in φ; U_F the forces in u; W0 the frame forces in z; O_G a task law's g_ctl
    in o); FRAMES: each frame's J offset in φ; FORCES: o's measured forces in u's order; COLS: the folded
    columns of A (the rows' λ, then a carrying body's Q̈_b), with D_A, D_F, D_Z per column; REACH: the rows
    whose A column beyond the robot joins B."""
    c = vector_of(ib, ib, INTS)
    nQ, nv = c[NQ], c[NV]
    if c[TIMED]:
        write_time_part(t, c[T_KIND], matrix_of(fb, ib, T_MOVES), matrix_of(fb, ib, T_R), vector_of(fb, ib, T_CIRCLE),
                        matrix_of(fb, ib, T_TERMS), vector_of(fb, ib, T_START), matrix_of(fb, ib, T_RAMPS), u,
                        c[I_SET])
    y, A, b, o = kkt_of(phi, fb, ib, P_VAL, P_COL, P_ROW, c[M])
    if c[KIND] == TIP_LAW:
        tau, B, targets = _tip_law(phi, x, u, A, b, o, fb, ib, c)
    else:  # τ = J_tipᵀ g_ctl + F φ
        tau = mtv(phi[c[I_J]:c[I_J] + 3 * nv].reshape((3, nv)), o[c[O_G]:c[O_G] + 3]) + mv(matrix_of(fb, ib, F_FF), phi)
        B, targets = np.zeros((nv, 0)), np.zeros(0)
    cols = vector_of(ib, ib, COLS)
    z, y0, Y = fold_solve(A, b, matrix_of(fb, ib, L_), matrix_of(fb, ib, L_TAU), tau, x, B, cols, nQ)
    if not np.isfinite(z.dot(z)):
        return DECLINED
    folded = z[cols]
    if c[N_LIM] and np.abs(y0[nQ:] + mv(Y[nQ:], folded)).max() > 1.0:
        return DECLINED
    xd = write_out(out, x, z, y, o, tau + mv(B, folded), nQ, c[O_Y0], c[O_Y1])
    if c[ZS] >= 0:
        xd[c[X_Z0]:c[X_Z1]] = targets[c[ZS]:] + mv(matrix_of(fb, ib, D_Z), folded)
    return OK


@njit(cache=True)
def call_at(t, x, work, phi, u, fb, ib, out):
    """:func:`call` at (t, x) after computing the robot's terms into ``work`` and φ from them (plan_phi.write_phi,
    plan_phi.work_terms; φ's layout, time tables, frame and the robot's table packed in fb, ib): one compiled call
    per right-hand side."""
    at = vector_of(ib, ib, PHI_AT)
    write_phi(t, x, *work_terms(work, at[7], at[8]), phi, at, matrix_of(fb, ib, PHI_MOVES),
              vector_of(ib, ib, PHI_MSLOTS), matrix_of(fb, ib, PHI_RAMPS), vector_of(ib, ib, PHI_RSLOTS),
              vector_of(fb, ib, PHI_FRAME), vector_of(ib, ib, PHI_SUPPORT), matrix_of(fb, ib, PHI_RIGID))
    return call(t, phi, x, u, fb, ib, out)


def kernel_of(plan, meta: list, reach: list[int] | None):
    """kernel(t, x, φ) -> (ẋ, z, o), or None for a call that goes the readable way (a clip, a singular solve,
    a tip law's M not read yet); ``kernel.samples(ts, X)`` -> (Φ, O, Z, τ) of the output's samples, or None
    where one declines. None where the plan's mode is not one :func:`call` covers: compiled drives, no
    sliding friction, no slide launching from rest, and either a force-reading tip law by its matrix whose
    rows' reach beyond the robot is constant (``reach``, plan_fold's; ``meta``: the rows as the law's
    ``row_columns`` reads them) or the affine task law through the motors."""
    ctl = compiled_law(plan)
    tip_law = isinstance(ctl, CompiledLaw) and ctl.reason is None and (reach is not None or not plan.nr)
    if plan.compiled_drives is None or plan.friction_terms is not None or plan.launch is not None or not (
            tip_law or plan.law_via_drives):
        return None
    fb = ib = time_part = None  # the packed constants (:func:`pack`); a time part the call does not compute
    u = np.zeros(0)  # a tip law's inputs' buffer
    modes = plan.modes  # the modes this call is made for (a later ModePlan.use binds new ones)

    def ready() -> bool:
        nonlocal fb, ib, time_part, u
        if not tip_law:
            fb, ib = _task_law_constants(plan)
        elif ctl.M is not None:
            inputs = plan_inputs(plan, ctl, modes)
            fb, ib = _tip_law_constants(plan, ctl, meta, reach or [], inputs)
            u, time_part = inputs.u, None if inputs.time_tables else inputs.time_part
        return fb is not None

    def one(t, x, phi, out):
        if fb is None and not ready():
            return DECLINED
        if time_part is not None:  # a circle among other moves: the reference in Python, into u
            time_part(t)
        return call(t, phi, x, u, fb, ib, out)

    phi_of = plan.phi
    work, phi_buffer, refresh, load = phi_of.work, phi_of.buffer, phi_of.refresh, phi_of.load

    def one_at(t, x, out):  # one, with the robot's terms and φ in the same compiled call (a decline leaves φ written)
        if fb is None and not ready():
            phi_of(t, x)
            return DECLINED
        if time_part is not None:
            time_part(t)
        if load is not None:
            load(x)  # the robot's terms by Pinocchio (a robot contactdyn.robot.rigid_body does not compute)
        if call_at(t, x, work, phi_buffer, u, fb, ib, out):
            if load is None:
                refresh(x)  # Pinocchio's data at x for the readable way
            return DECLINED
        return OK

    def step_inputs():  # the compiled call's arguments for a step taken in one compiled call (plan_steps)
        if (fb is None and not ready()) or time_part is not None:
            return None
        return work, phi_buffer, u, fb, ib

    kernel = calls(plan, one, one_at)
    kernel.step_inputs, kernel.kind = (step_inputs if load is None else None), KERNEL
    return kernel


def calls(plan, one, one_at=None, rates: bool = False):
    """kernel(t, x, φ) -> (ẋ, z, o), None where ``one`` declines, and ``kernel.samples(ts, X)`` -> (Φ, O, Z, τ) of
    the output's samples, None where one declines: both by one(t, x, φ, out) -> status, a compiled call writing
    [ẋ, z, o, τ] into ``out`` (this module's :func:`call`, :func:`contactdyn.compiled.plan_operational.call`);
    ``kernel.at(t, x)`` -> (ẋ, z, o) or None by one_at(t, x, out), the same writing φ itself (None: no such; a
    decline leaves φ written at (t, x), in ``plan.phi.buffer``)."""
    s, m = plan.system, plan.m
    n, no = s.n, plan.P.shape[0] - m * (m + 1)
    size = n + m + no + s.nv
    phi_at, buffer = plan.phi_at, plan.phi.buffer  # this make_rhs's (a later ModePlan.use makes new ones)

    def kernel(t, x, phi):
        out = np.empty(size)
        if one(t, x, phi, out):
            return None
        return out[:n], out[n:n + m], out[n + m:n + m + no]

    def samples(ts, X):
        N = len(ts)
        Phi, out = np.empty((N, plan.P.shape[1])), np.empty((N, size))
        for k in range(N):
            if one_at is not None:  # φ written by the call itself
                if one_at(ts[k], X[k], out[k]):
                    return None
                Phi[k] = buffer
                continue
            Phi[k] = phi = phi_at(ts[k], X[k])
            if one(ts[k], X[k], phi, out[k]):
                return None
        return Phi, out[:, n + m:n + m + no], out[:, n:n + m], out[:, n + m + no:]

    def at(t, x):
        out = np.empty(size)
        if one_at(t, x, out):
            return None
        return out[:n], out[n:n + m], out[n + m:n + m + no]

    kernel.samples = samples
    kernel.at = at if one_at is not None else None
    kernel.one_at, kernel.layout = one_at, (size, n, m, no)  # for a caller that slices ``out`` itself
    kernel.rates = rates  # the call writes the impulse states' rates itself
    return kernel


def _ints(plan, given: dict) -> list[int]:
    """INTS of a plan: its sizes and offsets, then ``given`` by index (e.g. {KIND: TASK_LAW}), the rest 0."""
    s, m = plan.system, plan.m
    off = m * m + m  # o's start in y
    ints = [0] * (T_KIND + 1)
    ints[M], ints[NQ], ints[NV], ints[I_H] = m, s.nQ, s.nv, plan.i_h
    ints[I_J], ints[I_DR] = plan.i_J[plan.tip_frame], plan.i_dr[plan.tip_frame]
    ints[ZS], ints[N_LIM] = -1, len(plan.compiled_drives.limited)
    ints[O_Y0], ints[O_Y1] = off + plan.o_y.start, off + plan.o_y.stop
    ints[X_Z0], ints[X_Z1], ints[W0] = plan.z_slice.start, plan.z_slice.stop, s.nQ + plan.nr
    for k, value in given.items():
        ints[k] = int(value)
    return ints


def _task_law_constants(plan) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pack`'s buffers for the affine task law: g_ctl's place in o, the feedforward's map F (τ_ff = F φ)."""
    nv, width = plan.system.nv, plan.P.shape[1]
    F = affine_map(lambda e: plan._feedforward_torque(e[:width], e[plan.i_e:width]), width + 1)[:, :width]
    empty = np.zeros((0, 0))
    P = csr_of(plan)
    floats = [P.data, empty, np.zeros(0), np.zeros(0), plan.compiled_drives.L, plan.compiled_drives.L_tau,
              np.zeros((3, 0)), empty, empty, np.zeros(0), np.zeros((nv, nv)), [0.0], F, *NO_REFERENCE[1:6],
              np.zeros((0, 5))]
    ints = _ints(plan, {KIND: TASK_LAW, O_G: plan.o_gctl.start})
    return pack_with_phi(plan, floats, [P.indices, P.indptr, ints, plan.i_J, [], [], [], [], [0]])


def _tip_law_constants(plan, ctl, meta, reach, inputs) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pack`'s buffers for a force-reading tip law whose law has read M."""
    s, drives, readable = plan.system, plan.compiled_drives, ctl.ctl  # (the readable law: its rotor and k_null)
    nQ, nv, nr = s.nQ, s.nv, plan.nr
    D_a, D_f, D_z = ctl.row_columns(meta)
    cols = list(range(nQ, nQ + nr))
    if plan.phase.carrier is not None:  # a reference carried by body coordinate i_b: ∂/∂Q̈_b, one more column
        i_b, axis = plan.phase.carrier
        d = ctl.per_reference_acceleration(axis)
        D_a = np.column_stack((D_a, d[:3]))
        D_f = None if D_f is None else np.column_stack((D_f, d[3:6]))
        D_z = None if D_z is None else np.column_stack((D_z, d[ctl.zs]))
        cols.append(i_b)
    none = np.empty((0, len(cols)))
    P = csr_of(plan)
    timed = inputs.time_tables
    kind, moves, R, circle, terms, start, ramps, i_set = timed or (*NO_REFERENCE, np.zeros((0, 5)), 0)
    ints = _ints(plan, {TIP: inputs.tip, U_F: ctl.i_forces, ZS: ctl.zs.start if ctl.zs is not None else -1,
                        SWAP: ctl.swap, KIND: TIP_LAW, TIMED: timed is not None, I_SET: i_set, T_KIND: kind})
    U = inputs.state_map()  # [U_x, u_c]
    U_x = sparse.csr_matrix(U[:, :s.n])
    floats = [P.data, ctl.M, U_x.data, U[:, s.n], drives.L, drives.L_tau, D_a, none if D_f is None else D_f,
              none if D_z is None else D_z, readable._rotor, s._D_ctl, [readable.config.k_null], np.zeros((nv, 0)),
              moves, R, circle, terms, start, ramps]
    return pack_with_phi(plan, floats, [P.indices, P.indptr, ints, plan.i_J, inputs.forces, cols, reach,
                                         U_x.indices, U_x.indptr])


def pack_with_phi(plan, floats: list, ints: list) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pack` of a call's constants followed by φ's layout and time tables (:func:`call_at`)."""
    at, moves, move_slots, ramps, ramp_slots, frame, support, rigid = plan.phi.tables
    return pack([*floats, moves, ramps, frame, rigid], [*ints, at, move_slots, ramp_slots, support])
