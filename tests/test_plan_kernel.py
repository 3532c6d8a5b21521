"""The compiled kernel of a plan's call (compiled.plan_kernel) and its small linear algebra (numerics.linalg)."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from test_output_samples import _pressing_writer

from contactdyn import simulate
from contactdyn.compiled import samples
from contactdyn.compiled.plan_law import compiled_law
from contactdyn.compiled.rhsplan import _PLANS
from contactdyn.model.system import System
from contactdyn.numerics.linalg import cholesky, forward_solve, lu_solve, pinv, sparse_dot
from contactdyn.robot.robot import Robot
from contactdyn.scene.scene_file import load_scene, parse_scene
from contactdyn.simulate import run_system


@pytest.mark.parametrize("nv", [1, 2, 3, 5, 7])
def test_pinv_is_numpys_pinv_with_its_rcond(nv):
    """J⁺ of tip Jacobians (3, nv): full rank, a repeated column, a zero row, all zero; against numpy's SVD pinv."""
    rng = np.random.default_rng(nv)
    for k in range(60):
        J = rng.normal(size=(3, nv)) * 10.0 ** rng.uniform(-3, 3)
        if k % 3 == 1 and nv > 1:
            J[:, 1] = 2.0 * J[:, 0]
        if k % 4 == 2:
            J[2] = 0.0
        if k == 59:
            J[:] = 0.0
        ref = np.linalg.pinv(J, rcond=1e-10)
        assert np.allclose(pinv(J), ref, rtol=1e-12, atol=1e-12 * (1.0 + np.abs(ref).max()))


def test_pinv_near_a_singular_pose_keeps_the_small_singular_value():
    """σ₂/σ₁ = 1e-8 (above the 1e-10 cut): J⁺ has the 1e8 entries numpy's has, to 1e-7 relative."""
    u, _ = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))
    v, _ = np.linalg.qr(np.random.default_rng(4).normal(size=(2, 2)))
    J = u[:, :2] @ np.diag([1.0, 1e-8]) @ v.T
    ref = np.linalg.pinv(J, rcond=1e-10)
    assert np.abs(ref).max() > 1e7
    assert np.allclose(pinv(J), ref, rtol=1e-7, atol=0.0)


def test_lu_solve_is_a_solve_and_nan_when_singular():
    rng = np.random.default_rng(5)
    for n in (1, 3, 7, 12):
        A, b = rng.normal(size=(n, n)), rng.normal(size=n)
        assert np.allclose(A @ lu_solve(A, b), b, rtol=0.0, atol=1e-11 * np.abs(A).max() * (1 + np.abs(b).max()))
    assert np.all(np.isnan(lu_solve(np.array([[1.0, 2.0], [2.0, 4.0]]), np.ones(2))))


def test_cholesky_forward_solve_and_the_sparse_product():
    """L Lᵀ = A and L Y = B to round-off, nan for an indefinite A; P x over P's nonzeros (scipy's CSR) is P x."""
    from scipy import sparse

    rng = np.random.default_rng(6)
    for n in (1, 4, 7):
        B = rng.normal(size=(n, n))
        A = B @ B.T + 0.1 * np.eye(n)
        L = cholesky(A)
        assert np.allclose(np.tril(L), L) and np.allclose(L @ L.T, A, rtol=0, atol=1e-13 * np.abs(A).max())
        R = rng.normal(size=(n, 3))
        assert np.allclose(L @ forward_solve(L, R), R, rtol=0, atol=1e-12 * (1 + np.abs(R).max()))
    assert np.all(np.isnan(cholesky(np.array([[1.0, 2.0], [2.0, 1.0]]))))
    P = rng.normal(size=(30, 20)) * (rng.random((30, 20)) < 0.1)
    P[4] = 0.0  # an empty row
    x = rng.normal(size=20)
    S = sparse.csr_matrix(P)
    assert np.allclose(sparse_dot(S.indptr.astype(np.int64), S.indices.astype(np.int64), S.data, x), P @ x,
                       rtol=0, atol=1e-14)


def _mode_at(scene, at: float):
    """(system, the plan of the mode the run is in at time ``at``, t, x there)."""
    system = System(scene)
    run_system(system)
    plan = max(_PLANS[system].values(), key=lambda p: -1.0 if p.ring[3][0] is None else p.ring[3][0])
    t, x = plan.ring[3][0], plan.ring[3][1].copy()
    return system, plan, t, x


def _assert_kernel_is_the_readable_model(system, plan, t0, x0, span=0.01):
    """On states of a short stretch of the mode: the kernel answers (does not decline) and its ẋ (with the
    impulse states' rates) is System.evaluate's to 1e-10 relative."""
    assert plan.kernel is not None
    sol = solve_ivp(plan.rhs, (t0, t0 + span), x0, method="DOP853", rtol=1e-8, atol=1e-10)
    for t, x in zip(sol.t[:40], sol.y.T[:40], strict=True):
        got = plan.kernel(t, x, plan.phi_at(t, x))
        assert got is not None
        if not plan.kernel.rates:  # as the plan's call does after a kernel that leaves them
            plan.impulse_rates(*got, plan.modes, None)
        ref = system.evaluate(t, x, plan.modes, plan.phase).xdot
        assert np.allclose(got[0], ref, rtol=1e-10, atol=1e-10 * (1.0 + np.abs(ref).max()))


@pytest.mark.parametrize("name", ["case3_b_force", "case3_a_position"])
def test_kernel_is_the_readable_model_on_case3_presses(name):
    """A10 folded with its bonded row (model b), A7 with no row (model a), both through the elastic transmission."""
    system, plan, t, x = _mode_at(load_scene(name, {"duration": 2.0}), 2.0)
    assert plan.nr == (1 if name.endswith("b_force") else 0)
    _assert_kernel_is_the_readable_model(system, plan, t, x)


@pytest.mark.parametrize("force_reference", [True, False])
def test_kernel_is_the_readable_model_with_a_reference_carried_by_the_cart(force_reference):
    """Case 1's push: A7 tracking a reference carried by the cart, through DC motors. Without force_reference the
    command depends on the cart's acceleration along x (one more folded column, D_a = x); with it (the scene's)
    the reference along the touching normal is the force's depth instead, and that column is zero."""
    from contactdyn.scene.reader import read_toml
    from contactdyn.scene.scene_file import find_scene

    doc = read_toml(find_scene("case1_cart"))
    doc["phase"][1]["controller"]["force_reference"] = force_reference
    system, plan, t, x = _mode_at(parse_scene(doc, {"duration": 2.5}), 2.5)
    assert plan.phase.carrier is not None
    _assert_kernel_is_the_readable_model(system, plan, t, x)
    d_a = compiled_law(plan).M[:3, 12:15].dot(plan.phase.carrier[1])  # a* [m/s²] per unit ẍ_d along the axis
    assert np.array_equal(d_a, [0.0, 0.0, 0.0] if force_reference else [1.0, 0.0, 0.0])


def test_kernel_declines_a_clipping_voltage_and_the_call_stays_the_readable_models():
    """With a 4 V limit the A7 press clips at its start: there the kernel declines (the clip is the readable
    law's), the plan's call still equals System.evaluate; without the limit the kernel answers."""
    system, plan, _, _ = _mode_at(parse_scene(_pressing_writer(u_max=4.0)), 0.3)
    x0 = plan.system.initial_state()[0]
    t = plan.phase.t_start
    tried = [(t, x0 + dx) for dx in np.random.default_rng(1).normal(scale=1e-3, size=(20, len(x0)))]
    declined = [(t, x) for t, x in tried if plan.kernel(t, x, plan.phi_at(t, x)) is None]
    assert declined, "expected calls whose voltage clips"
    for t, x in declined:
        ref = system.evaluate(t, x, plan.modes, plan.phase).xdot
        assert np.allclose(plan.rhs(t, x), ref, rtol=1e-10, atol=1e-10 * (1.0 + np.abs(ref).max()))
    system, plan, t, x = _mode_at(parse_scene(_pressing_writer(u_max=None)), 0.3)
    _assert_kernel_is_the_readable_model(system, plan, t, x)


@pytest.mark.parametrize("cancel", ["target", "measured"])
def test_kernel_is_the_readable_model_on_the_hybrid_law(cancel):
    """The hybrid law on the 2-DOF writer pressing case 2's (b) surface through DC motors: with cancel = "target"
    its tip force f_swap = (F − F*) n goes into τ by Jᵀ (the kernel's swap), with "measured" it does not."""
    from test_controllers import hybrid_doc

    system, plan, t, x = _mode_at(parse_scene(hybrid_doc(cancel=cancel), {"duration": 0.3}), 0.3)
    assert compiled_law(plan).swap == (cancel == "target")
    _assert_kernel_is_the_readable_model(system, plan, t, x)


@pytest.mark.parametrize("name, at", [("case3_b_force", 0.1), ("case1_cart", 1.0)])
def test_kernel_is_the_readable_model_with_the_task_law_through_motors(name, at):
    """The affine task PD law through the drives: case 3's approach (elastic transmission), case 1's first push
    (DC motors on the robot, the cart's servo)."""
    system, plan, t, x = _mode_at(load_scene(name, {"duration": at}), at)
    assert plan.law_via_drives
    _assert_kernel_is_the_readable_model(system, plan, t, x, span=0.005)


def test_a_mode_without_drives_has_no_kernel():
    """B1: the task PD law without motors (its command is in the plan's map P: nothing left to compile)."""
    system, plan, _, _ = _mode_at(load_scene("b1", {"duration": 0.1}), 0.1)
    assert plan.kernel is None


@pytest.mark.parametrize("name", ["case2_writer5dof", "case2_writer_ur5"])
def test_operational_kernel_is_the_readable_model_on_the_writers(name):
    """The operational_space law with the pencil stuck (press), launched from rest and sliding in 2-D (circle):
    every mode of the run has a compiled call, and it equals System.evaluate along a stretch of the mode."""
    system = System(load_scene(name, {"duration": 1.6}))
    run_system(system)
    plans = list(_PLANS[system].values())
    kinds = {(m.stuck, m.from_rest) for p in plans for m in p.modes}
    assert kinds == {(True, False), (False, True), (False, False)}  # stuck, launching, sliding
    for plan in plans:
        t, x = plan.ring[3][0], plan.ring[3][1].copy()
        _assert_kernel_is_the_readable_model(system, plan, t, x)


def test_operational_kernel_declines_a_slide_from_rest_inside_the_stick_band():
    """At rest (|v_t| = 0 ≤ v_ε) the launch direction is the readable rule's (launch_directions' Newton): the kernel
    declines, and the plan's call (that rule on its own KKT system) still equals System.evaluate."""
    system = System(load_scene("case2_writer5dof", {"duration": 0.8}))
    run_system(system)
    plan = next(p for p in _PLANS[system].values() if any(m.from_rest and not m.stuck for m in p.modes))
    t, x = plan.ring[3][0], plan.ring[3][1].copy()
    x[system.nQ:2 * system.nQ] = 0.0  # robot and surface at rest: no slip
    assert plan.kernel is not None and plan.kernel(t, x, plan.phi_at(t, x)) is None
    ref = system.evaluate(t, x, plan.modes, plan.phase).xdot
    elsewhere = x.copy()
    elsewhere[:system.nv] += 0.1
    system.evaluate(t, elsewhere, plan.modes, plan.phase)  # Pinocchio's data left at another state
    # the fused call computes the robot's terms itself and declines; the readable way then reads Pinocchio's data,
    # which the call brings to x first
    assert np.allclose(plan.rhs(t, x), ref, rtol=1e-10, atol=1e-10 * (1.0 + np.abs(ref).max()))


@pytest.mark.parametrize("name", ["case3_b_force", "case3_a_position", "case2_writer5dof", "case2_writer_ur5"])
def test_output_by_the_kernel_equals_the_batched_output(name, monkeypatch):
    """The output's samples by the compiled call per sample equal those of the batched NumPy paths (taken where
    the kernel declines) on every channel, to 1e-10 of each channel's largest value; the kernel's did run."""
    ran = []
    by_kernel = samples._kernel_samples
    monkeypatch.setattr(samples, "_kernel_samples", lambda plan, ts, X: ran.append(1) or by_kernel(plan, ts, X))
    got = simulate(load_scene(name, {"duration": 2.5}))
    assert ran
    monkeypatch.setattr(samples, "_kernel_samples", lambda plan, ts, X: None)
    want = simulate(load_scene(name, {"duration": 2.5}))
    for key, w in want.channels.items():
        g = np.asarray(got.channels[key], float)
        w = np.asarray(w, float)
        scale = max(float(np.nanmax(np.abs(w), initial=0.0)), 1e-300)
        np.testing.assert_allclose(g, w, rtol=0.0, atol=1e-10 * scale, err_msg=key)


def test_kernel_is_the_readable_model_on_a_redundant_arm():
    """A7 on the 5-DOF writer (J⁺ of a 3×5 Jacobian, the null-space damping k_null) pressing a bonded wall
    under DC motors with the rotors taken out of H (``inertia = "link"``)."""
    q0 = [0.3, 0.678629948129, 1.834747110377, 0.428215595084, 0.0]  # [rad] sims/case2_writer5dof's pose
    p0 = Robot.load("writer5dof").frame_position(np.array(q0), "tip")
    drive = {"kind": "dc_motor", "R": 0.272, "C_M": 0.061, "J": 0.000452, "N": 160.0, "N_star": 65.12}
    doc = {"duration": 0.2, "robot": {"urdf": "writer5dof", "tip": "tip", "q0": q0, "drive": drive},
           "controller": {"kind": "position_dynamic", "kp": 400.0, "kv": 40.0, "k_null": 5.0, "inertia": "link"},
           "phase": [{"name": "main", "reference": {"space": "task", "start": (p0 + [0.005, 0.0, -0.01]).tolist(),
                                                    "moves": []}}],
           "contact": {"c": {"point": p0.tolist(), "bonded": True,
                             "normal": {"direction": [-1, 0, 0], "model": "b", "k": 1e4, "b": 10.0, "m": 2.0}}}}
    system, plan, t, x = _mode_at(parse_scene(doc), 0.2)
    assert plan.nr == 1 and system.nv == 5
    _assert_kernel_is_the_readable_model(system, plan, t, x, span=0.005)


def test_operational_kernel_is_the_readable_model_on_a_1d_slide():
    """The 5-DOF writer with 1-D friction along x drawing a line: the pencil stuck, then sliding along its one
    tangent (the kernel's 1-D impulse rate −μ F d + the viscous force, d the mode's fixed direction)."""
    from contactdyn.scene.reader import read_toml
    from contactdyn.scene.scene_file import find_scene

    doc = read_toml(find_scene("case2_writer5dof"))
    doc["duration"] = 1.0
    doc["contact"]["pencil"]["tangent"]["directions"] = [[1.0, 0.0, 0.0]]
    doc["phase"][1]["reference"]["moves"] = [{"kind": "trapezoid", "delta": [0.02, 0.0, 0.0], "duration": 0.4}]
    system = System(parse_scene(doc))
    run_system(system)
    plans = list(_PLANS[system].values())
    assert {m.stuck for p in plans for m in p.modes} == {True, False}
    for plan in plans:
        t, x = plan.ring[3][0], plan.ring[3][1].copy()
        _assert_kernel_is_the_readable_model(system, plan, t, x)
