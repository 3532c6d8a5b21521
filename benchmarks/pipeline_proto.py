"""The one pipeline (contactdyn/model/pipeline/) compiled against the same call interpreted, per call; its cold compile.

    PYTHONPATH=. python3 benchmarks/pipeline_proto.py [CASE ...] [--calls 2000] [--repeats 7] [--compile]
        [--out FILE.json]

Per mode (:func:`cases`: the sims, benchmarks/hard and examples scenes, in their first mode and in modes set by
hand: touching, sticking, a joint on its limit, a later phase), the median time of one right-hand-side call [µs] of
the pipeline compiled (``Pipeline.rhs``) and interpreted (the same call run as its Python source,
``mode_runner(system, compiled=False)``: the tests' per-state reference, :func:`agreement`), timed interleaved (every
variant once per repeat, each a batch of ``--calls`` calls over 16 states near the mode's start; the interpreted
call a hundredth of them), in one process, after an untimed warm-up. Also
per call inside one compiled loop (no Python between calls: the pipeline's ``rates_at``, as a compiled DOP853 step
calls it), and the largest relative difference of ẋ against the interpreted call over the states. ``--compile``: the
compile time of the pipeline's first call from a cold cache, in a child process with a fresh NUMBA_CACHE_DIR
(import and ``prepare`` first, then the first call), and again warm (the same directory, a new process), on b1 and
impedance_press.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
import tomllib
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from timing import interleaved, write_report  # noqa: E402

from contactdyn import parse_scene  # noqa: E402
from contactdyn.hybrid.pipeline_mode import mode_runner  # noqa: E402
from contactdyn.simulate import prepare  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def _scene(path: str, edit=None):
    doc = tomllib.loads((ROOT / path).read_text())
    if edit is not None:
        edit(doc)
    return parse_scene(doc, file=str(ROOT / path))


def _stribeck(doc: dict) -> None:
    doc["contact"]["tip"]["tangent"] = {"model": "friction", "directions": [[1.0, 0.0, 0.0]], "mu_s": 0.6,
                                        "mu_k": 0.4, "law": "stribeck", "v_s": 0.01}


def _no_motors(doc: dict) -> None:
    """case1_cart with ideal torque drives (its DC motors dropped), its approach phase only (task PD)."""
    del doc["robot"]["drive"], doc["body"]["cart"]["drive"]
    doc["phase"] = doc["phase"][:1]


def _carried_pd(doc: dict) -> None:
    """case1_cart without its motors, its push (the reference carried by the cart) under task PD (x and z)."""
    del doc["robot"]["drive"], doc["body"]["cart"]["drive"]
    doc["phase"][1]["controller"] = {"kind": "task_pd", "axes": [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], "kp": 1e5,
                                     "kd": 6000.0, "feedforward": "gravity"}


def _tool_pd(doc: dict, circle: bool = False) -> None:
    """A pencil writer under task PD holding its tool axis (the deleted twin needed a compiled operational call:
    the moment is not affine), its circle made a straight trapezoid (``circle``: kept, and a straight move after it)."""
    ctl = doc["controller"]
    doc["controller"] = {"kind": "task_pd", "kp": ctl["kp"], "kd": ctl["kd"], "axes": ctl["axes"],
                         "tool_axis": ctl["tool_axis"], "tool_target": ctl["tool_target"], "ko": 5.0, "do": 0.5,
                         "kd_normal": ctl["kd_normal"], "feedforward": "gravity"}
    line = {"kind": "trapezoid", "delta": [-0.03, 0.0, 0.0], "duration": 4.0, "accel_fraction": 0.2}
    if circle:
        doc["phase"][1]["reference"]["moves"].append({**line, "delta": [0.0, 0.01, 0.0], "start": 0.005})
    else:
        doc["phase"][1]["reference"] = {"moves": [line]}


def _launch(slip, phase=1):
    """Touching in a 2-D slide launching from rest along the reference ``slip`` (the robot at rest: x0's velocities
    zeroed), in phase ``phase``."""
    def change(system, modes, ph, x0):
        ph = system.start_phase(phase, ph.t_start + 1.0, x0, ph)
        x0[system.nQ:2 * system.nQ] = 0.0
        return [mm.with_(touching=True, stuck=False, from_rest=True, slip=tuple(slip),
                         offsets=tuple(0.0 for _ in c.tangent_chains))
                for c, mm in zip(system.contacts, modes, strict=True)], ph
    return change


def _energy(doc: dict, joints: bool = True) -> None:
    """The energy audit on, viscous friction 5 N·s/m on the contact, and (``joints``) b1's joint friction."""
    doc["solver"]["record_energy"] = True
    doc["contact"][next(iter(doc["contact"]))]["tangent"]["viscous"] = 5.0
    if joints:
        _joint_friction(doc)


def _massless(doc: dict) -> None:
    """b1's surface a massless stage k, b (model c): the normal force known from the stage, no normal row."""
    tip = doc["contact"]["tip"]
    tip["normal"] = {"direction": [0.0, 1.0, 0.0], "model": "c", "k": 1e5, "b": 100.0}
    del tip["bonded"]
    _energy(doc)


def _joint_friction(doc: dict) -> None:
    """b1 with joint damping and Coulomb joint friction (static above kinetic) on both joints."""
    doc["robot"]["joint"] = {"q1": {"damping": 0.5, "friction_static": 3.0, "friction_kinetic": 2.0},
                             "q2": {"damping": 0.2, "friction": 1.5}}


def _joint_modes(modes_of_joints, limits=()):
    """The joints' friction modes set (0 stuck, ±1 sliding), and joints pressing on their limits."""
    def change(system, modes, ph, x0):
        return modes, replace(ph, joint_modes=tuple(modes_of_joints), limits=tuple(limits))
    return change


def _sampled(doc: dict) -> None:
    """b1's task PD run sampled at 1 kHz with a zero-order hold (the held command in the state)."""
    doc["controller"]["sample_rate"] = 1000.0


def _holding(tau, joint_modes=None):
    """x0's held command set to ``tau`` [N·m] (a sampled law's slots, as a sample writes them), the joints' modes."""
    def change(system, modes, ph, x0):
        x0[2 * system.nQ + ph.z_slice.start + ph.controller.held.start:][:system.nv] = tau
        return modes, ph if joint_modes is None else replace(ph, joint_modes=tuple(joint_modes))
    return change


def _real_cell_drives(kp: float):
    """force_loop_real_cell's motors (24 V limit) under task PD (its sampled force law and joint friction dropped:
    another helper's kinds), its reference 1 cm off along x so that kp [N/m] sets how far the voltages clip."""
    def edit(doc: dict) -> None:
        doc["controller"] = {"kind": "task_pd", "axes": [[1.0, 0.0, 0.0]], "kp": kp, "kd": 100.0}
        del doc["robot"]["joint"]
        doc["phase"][0]["reference"]["start"] = [0.46, -0.15, 0.0]
    return edit


def _voltages(doc: dict) -> None:
    """case2_writer_motors under open-loop voltages (30, −2) V against a 28 V limit (the shoulder clips), its first
    phase only."""
    doc["robot"]["drive"]["u_max"] = 28.0
    doc["controller"] = {"kind": "voltage", "u": [30.0, -2.0]}
    doc["phase"] = [{k: v for k, v in doc["phase"][0].items() if k != "controller"}]


def _straight(doc: dict) -> None:
    """A writer with its own controller (operational_space), its circle made a straight trapezoid."""
    doc["phase"][1]["reference"] = {"moves": [{"kind": "trapezoid", "delta": [-0.03, 0.0, 0.0], "duration": 4.0,
                                               "accel_fraction": 0.2}]}


def _force_dynamic(doc: dict) -> None:
    """b1_force_loop under A10 as written (F* swapped into τ) on the exact nominal (model b: k, b, m), no reference."""
    doc["controller"] = {"kind": "force_dynamic", "kv": 40.0, "kf": 50.0, "cancel": "target",
                         "nominal": {"k": 1e5, "b": 1.0, "m": 10.0}}
    del doc["phase"][0]["reference"]


def _position_dynamic(doc: dict) -> None:
    """b1_force_loop under A7 in task space, its reference pressed F_d / k into the surface (force_reference)."""
    doc["controller"] = {"kind": "position_dynamic", "kp": 400.0, "kv": 40.0, "force_reference": True,
                         "nominal": {"k": 1e5}}


def _joint_pd(doc: dict) -> None:
    """b1 under joint PD (bias feedforward) tracking a joint-space trapezoid."""
    doc["controller"] = {"kind": "joint_pd", "kp": [300.0, 200.0], "kd": 20.0, "feedforward": "bias"}
    doc["phase"][0]["reference"] = {"space": "joint", "start": [0.33, -1.3],
                                    "moves": [{"kind": "trapezoid", "delta": [0.2, -0.1], "duration": 1.0}]}


def _task_force(doc: dict) -> None:
    """b1 under an open-loop task force: a ramp and a sinusoid (gravity feedforward: none asked in the plane)."""
    doc["controller"] = {"kind": "task_force", "force": [0.0, -50.0, 0.0], "rate": [20.0, 0.0, 0.0],
                         "amplitude": [5.0, 3.0, 0.0], "frequency": 2.0, "phase": [0.0, 0.5, 0.0],
                         "feedforward": "gravity"}


def _clip_at(u_max: float):
    """The joints' motors limited to ``u_max`` [V] (case1_cart's push asks ~320 and ~290 V at its start, apart
    ~313 and ~275 V; case3_b's press ~0.2 V before its fold, ~28 V after: the clips' re-check)."""
    def edit(doc: dict) -> None:
        doc["robot"]["drive"]["u_max"] = u_max
    return edit


def _pushing(touching: bool):
    """case1_cart's push phase (its reference carried by the cart), the tip touching or apart."""
    def change(system, modes, ph, x0):
        ph = system.start_phase(1, ph.t_start + 1.0, x0, ph)
        return [mm.with_(touching=touching) for mm in modes], ph
    return change


def _apart(system, modes, ph, x0):
    """The first mode with every contact apart (the dynamic laws' free directions, their integrals frozen)."""
    return [mm.with_(touching=False) for mm in modes], ph


#: case -> (scene file, an edit of its TOML or None, what to change from its first mode: None, or a function of
#: (system, modes, phase, x0) giving (modes, phase))
def _touch(stuck=False, limits=(), phase=None):
    def change(system, modes, ph, x0):
        if phase is not None:
            ph = system.start_phase(phase, ph.t_start + 1.0, x0, ph)
        m = [mm.with_(touching=True, stuck=stuck, offsets=tuple(0.0 for _ in c.tangent_chains))
             for c, mm in zip(system.contacts, modes, strict=True)]
        return m, replace(ph, limits=tuple(limits))
    return change


CASES = {
    "b1": ("sims/b1.toml", None, None),
    "b1_stick": ("sims/b1.toml", None, _touch(stuck=True)),
    "b1_limit": ("sims/b1.toml", None, _touch(limits=((1, -1),))),
    "b1_stribeck": ("sims/b1.toml", _stribeck, None),
    "b1_sampled": ("sims/b1.toml", _sampled, _holding((40.0, -25.0))),
    "b1_sampled_joints": ("sims/b1.toml", lambda d: (_sampled(d), _joint_friction(d)),
                          _holding((40.0, -25.0), ((0, 0), (1, 1)))),
    "b1_energy": ("sims/b1.toml", _energy, None),
    "b1_energy_stuck": ("sims/b1.toml", _energy, _joint_modes(((0, 0), (1, 0)))),
    "b1_energy_stick": ("sims/b1.toml", _energy, _touch(stuck=True)),
    "b1_energy_massless": ("sims/b1.toml", _massless, _touch()),
    "writer_b_energy": ("sims/case2_writer_b.toml", lambda d: _energy(d, joints=False), _touch(phase=1)),
    "b1_joints_slide": ("sims/b1.toml", _joint_friction, None),
    "b1_joints_stuck": ("sims/b1.toml", _joint_friction, _joint_modes(((0, 0), (1, 0)))),
    "b1_joints_mixed": ("sims/b1.toml", _joint_friction, _joint_modes(((0, -1), (1, 0)))),
    "b1_joints_limit": ("sims/b1.toml", _joint_friction, _joint_modes(((0, 0), (1, 0)), limits=((1, -1),))),
    "writer_b_approach": ("sims/case2_writer_b.toml", None, None),
    "writer_b_write": ("sims/case2_writer_b.toml", None, _touch(phase=1)),
    "writer_rigid_approach": ("sims/case2_writer_rigid.toml", None, None),
    "writer_rigid_write": ("sims/case2_writer_rigid.toml", None, _touch(phase=1)),
    "writer_rigid_stick": ("sims/case2_writer_rigid.toml", None, _touch(stuck=True, phase=1)),
    "hard_bounce": ("benchmarks/hard/bounce.toml", None, None),
    "hard_bounce_touch": ("benchmarks/hard/bounce.toml", None, _touch()),
    "hard_fast_mass": ("benchmarks/hard/fast_mass.toml", None, None),
    "hard_grazing": ("benchmarks/hard/grazing.toml", None, None),
    "hard_mass_ratio": ("benchmarks/hard/mass_ratio.toml", None, None),
    "hard_singular": ("benchmarks/hard/singular.toml", None, None),
    "hard_stickslip": ("benchmarks/hard/stickslip.toml", None, None),
    "hard_stiff": ("benchmarks/hard/stiff.toml", None, None),
    "hard_undamped": ("benchmarks/hard/undamped.toml", None, None),
    "cart_chains_touch": ("sims/case1_cart.toml", _no_motors, _touch()),
    "cart_push_carried": ("sims/case1_cart.toml", _carried_pd, _touch(phase=1)),
    "writer5dof_tool": ("sims/case2_writer5dof.toml", _tool_pd, None),
    "writer5dof_tool_slide": ("sims/case2_writer5dof.toml", _tool_pd, _touch(phase=1)),
    "writer5dof_circle": ("sims/case2_writer5dof.toml", lambda d: _tool_pd(d, circle=True), _touch(phase=1)),
    "ur5_circle": ("sims/case2_writer_ur5.toml", lambda d: _tool_pd(d, circle=True), _touch(phase=1)),
    "writer5dof_launch": ("sims/case2_writer5dof.toml", _tool_pd, _launch((0.6, 0.8))),
    "ur5_launch": ("sims/case2_writer_ur5.toml", _tool_pd, _launch((-1.0, 0.0))),
    "ur5_tool": ("sims/case2_writer_ur5.toml", _tool_pd, None),
    "writer5dof_ops": ("sims/case2_writer5dof.toml", None, None),
    "writer5dof_ops_write": ("sims/case2_writer5dof.toml", _straight, _touch(phase=1)),
    "ur5_ops": ("sims/case2_writer_ur5.toml", None, None),
    "ur5_ops_write": ("sims/case2_writer_ur5.toml", _straight, _touch(phase=1)),
    "cubic_press": ("examples/cubic_press.toml", None, None),
    "impedance_press": ("examples/impedance_press.toml", None, None),
    "cart_motors": ("sims/case1_cart.toml", None, None),
    "cart_motors_touch": ("sims/case1_cart.toml", None, _touch()),
    "writer_motors_approach": ("sims/case2_writer_motors.toml", None, None),
    "writer_motors_write": ("sims/case2_writer_motors.toml", None, _touch(phase=1)),
    "writer_motors_stick": ("sims/case2_writer_motors.toml", None, _touch(stuck=True, phase=1)),
    "writer_motors_voltage": ("sims/case2_writer_motors.toml", _voltages, None),
    "case3a_approach": ("sims/case3_a_position.toml", None, None),
    "case3a_touch": ("sims/case3_a_position.toml", None, _touch()),
    "case3b_approach": ("sims/case3_b_position.toml", None, None),
    "case3b_touch": ("sims/case3_b_position.toml", None, _touch()),
    "real_cell_drives": ("sims/force_loop_real_cell.toml", _real_cell_drives(2000.0), None),
    "real_cell_clip": ("sims/force_loop_real_cell.toml", _real_cell_drives(2e4), None),
    "force_pi_press": ("examples/force_pi_press.toml", None, None),
    "force_loop_hybrid": ("sims/b1_force_loop.toml", None, None),
    "force_loop_hybrid_stick": ("sims/b1_force_loop.toml", None, _touch(stuck=True)),
    "force_loop_hybrid_apart": ("sims/b1_force_loop.toml", None, _apart),
    "b1_force_dynamic": ("sims/b1_force_loop.toml", _force_dynamic, None),
    "b1_position_dynamic": ("sims/b1_force_loop.toml", _position_dynamic, None),
    "case3a_force_press": ("sims/case3_a_force.toml", None, _touch(phase=1)),
    "case3b_force_press": ("sims/case3_b_force.toml", None, _touch(phase=1)),
    "case3b_position_press": ("sims/case3_b_position.toml", None, _touch(phase=1)),
    "case3a_position_press": ("sims/case3_a_position.toml", None, _touch(phase=1)),
    "cart_push": ("sims/case1_cart.toml", None, _touch(phase=1)),
    "cart_push_clip": ("sims/case1_cart.toml", _clip_at(300.0), _touch(phase=1)),
    "cart_push_apart": ("sims/case1_cart.toml", None, _pushing(False)),
    "cart_push_apart_clip": ("sims/case1_cart.toml", _clip_at(312.9), _pushing(False)),
    "case3b_force_press_clip": ("sims/case3_b_force.toml", _clip_at(10.0), _touch(phase=1)),
    "b1_joint_pd": ("sims/b1.toml", _joint_pd, None),
    "b1_task_force": ("sims/b1.toml", _task_force, None),
}


def case(name: str, cases: dict | None = None):
    """(system, modes, phase, t, x0) of a case of ``cases`` (CASES unless given): its scene's first mode at its
    start, changed as the case says."""
    path, edit, change = (CASES if cases is None else cases)[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        system, modes, phase, x0 = prepare(_scene(path, edit))
    if change is not None:
        modes, phase = change(system, modes, phase, x0)
    return system, modes, phase, phase.t_start + 0.0123, x0


def states(x0: np.ndarray, count: int, seed: int = 7) -> list[np.ndarray]:
    """x0 and count − 1 random states near it (x0 + 1e-3 (1 + |x0|) N(0, 1))."""
    rng = np.random.default_rng(seed)
    return [x0.copy()] + [x0 + 1e-3 * (1.0 + np.abs(x0)) * rng.normal(size=x0.size) for _ in range(count - 1)]


def interpreted(system, modes, phase):
    """The mode on the same call interpreted (its Python source, the pipeline's twins): the reference a compiled call
    is held to state by state (one interpreted runner per system, kept on it: run_agreement's)."""
    runner = getattr(system, "_interpreted_runner", None)
    if runner is None:
        runner = system._interpreted_runner = mode_runner(system, compiled=False)
    return runner(modes, phase)


def agreement(pipeline, system, modes, phase, t: float, xs: list[np.ndarray]) -> tuple[float, int]:
    """(largest ‖ẋ − ẋ_interpreted‖∞ / ‖ẋ_interpreted‖∞ over the states, how many agree bit for bit): the compiled
    call ``pipeline`` against the same call interpreted (:func:`interpreted`)."""
    mode, worst, bitwise = interpreted(system, modes, phase), 0.0, 0
    for x in xs:
        ref = mode.rhs(t, np.array(x, float))
        got = pipeline.rhs(t, x)
        worst = max(worst, float(np.abs(got - ref).max() / np.abs(ref).max()))
        bitwise += int(np.array_equal(got, ref))
    return worst, bitwise


def _batch(fn, t: float, xs: list[np.ndarray], calls: int):
    def run():
        for k in range(calls):
            fn(t, xs[k % len(xs)])
    return run


def _many(rates, ts: np.ndarray, X: np.ndarray):
    def run():
        rates(ts, X)
    return run


def measure(name: str, calls: int, repeats: int) -> dict:
    """One case's row: per-call medians [µs] of the pipeline compiled and interpreted; the agreement."""
    from contactdyn.model.pipeline.pipeline import Pipeline, rates_at

    system, modes, phase, t, x0 = case(name)
    xs = states(x0, 16)
    pipe = Pipeline(system, modes, phase)
    variants = {"pipeline": _batch(pipe.rhs, t, xs, calls)}
    slow = interpreted(system, modes, phase)
    variants["interpreted"] = _batch(slow.rhs, t, xs, max(calls // 100, 1))
    # inside compiled code (no Python per call): the pipeline's rates_at
    ts, X = np.full(calls, t), np.array([xs[k % len(xs)] for k in range(calls)])
    pk = pipe.packed
    variants["pipeline_compiled"] = _many(lambda ts_, X_: rates_at(ts_, X_, pk.ints, pk.reals, pk.work, pk.events),
                                          ts, X)
    for run in variants.values():
        run()  # untimed
    times = interleaved(variants, repeats)
    worst, bitwise = agreement(pipe, system, modes, phase, t, xs)
    per = {"pipeline": calls, "interpreted": max(calls // 100, 1), "pipeline_compiled": calls}
    us = {k: v.cpu / per[k] * 1e6 for k, v in times.items()}
    return {"case": name, "pipeline_us": us["pipeline"], "interpreted_us": us["interpreted"],
            "pipeline_compiled_us": us["pipeline_compiled"], "max_rel_diff": worst,
            "bitwise_states": f"{bitwise}/{len(xs)}", "failed_calls": pipe.failed_calls}


_CHILD = """
import time, warnings
w0, c0 = time.perf_counter(), time.process_time()
import sys; sys.path.insert(0, {bench!r})
from pipeline_proto import case
system, modes, phase, t, x0 = case({name!r})
w1, c1 = time.perf_counter(), time.process_time()
from contactdyn.model.pipeline.pipeline import Pipeline
Pipeline(system, modes, phase).rhs(t, x0)
w2, c2 = time.perf_counter(), time.process_time()
print(w1 - w0, c1 - c0, w2 - w1, c2 - c1)
"""


def compile_times(name: str = "b1") -> dict:
    """[s] wall and CPU of import + prepare, then of the first call (pack + call), in a child with a fresh
    NUMBA_CACHE_DIR (cold), then again in a second child on its directory (warm)."""
    out = {}
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": str(ROOT)}
        for label in ("cold", "warm"):
            code = _CHILD.format(bench=str(ROOT / "benchmarks"), name=name)
            got = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                 check=True).stdout.split()[-4:]
            out[f"pipeline_{label}"] = {"prepare_wall_s": float(got[0]), "prepare_cpu_s": float(got[1]),
                                        "first_call_wall_s": float(got[2]), "first_call_cpu_s": float(got[3])}
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("cases", nargs="*", default=list(CASES))
    p.add_argument("--calls", type=int, default=2000)
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--compile", action="store_true")
    p.add_argument("--out")
    args = p.parse_args(argv)
    rows = []
    for name in args.cases:
        t0 = time.perf_counter()
        rows.append(measure(name, args.calls, args.repeats))
        r = rows[-1]
        print(f"{name:22s} pipeline {r['pipeline_us']:6.2f} us  interpreted {r['interpreted_us']:8.1f} us  "
              f"compiled loop {r['pipeline_compiled_us']:5.2f} us  rel diff {r['max_rel_diff']:.1e}  "
              f"bitwise {r['bitwise_states']}  ({time.perf_counter() - t0:.0f} s)", flush=True)
    head = {"benchmark": "pipeline_proto", "calls": args.calls, "repeats": args.repeats}
    if args.compile:
        head["compile"] = {name: compile_times(name) for name in ("b1", "impedance_press")}
        print("compile [s]:", json.dumps(head["compile"]))
    if args.out:
        write_report(Path(args.out), head, rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
