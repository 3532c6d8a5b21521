"""Sampled-data control: a law run at sample instants with a zero-order hold, delayed, through sensor models.

The scenes are short pieces of B1 (sims/b1.toml: a planar 2R pressing and sliding on a model (b) surface, no
gravity, continuous task PD) with the controller sampled; a few test laws of the measured input alone make the
hold and the delay line exact to compare.
"""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from run_agreement import interpreted_evaluate

from contactdyn import parse_scene, simulate
from contactdyn.errors import SceneError
from contactdyn.hybrid.loop import HybridRun
from contactdyn.laws import DRIVE_KINDS, register_drive_kind
from contactdyn.laws.controllers import CONTROLLERS, Controller, register
from contactdyn.laws.controllers.sampled import SampledController
from contactdyn.laws.drive_kinds import DcMotor
from contactdyn.laws.failures import LawError
from contactdyn.laws.sensors import HOLDS, ForceSensor, SensorSpec
from contactdyn.model.paths import PIPELINE
from contactdyn.model.system import System
from contactdyn.numerics.held_steps import PiecewiseDense

ROOT = Path(__file__).resolve().parents[1]
B1 = tomllib.loads((ROOT / "sims" / "b1.toml").read_text())
RATE = 1000.0  #: [Hz]


class _Clock(Controller):
    """τ = (sin 50 t, cos 30 t) [N·m] of the measured time alone: a delay shifts it exactly."""

    name = "_test_clock"

    def command(self, inp):
        return np.array([math.sin(50.0 * inp.t), math.cos(30.0 * inp.t)]), None


class _Probe(Controller):
    """A small force-reading law that keeps what it was given (inputs: (t, q, forces))."""

    name = "_test_probe"
    uses_forces = True
    seen: list = []

    def command(self, inp):
        _Probe.seen.append((inp.t, inp.q.copy(), dict(inp.forces)))
        return -1e-3 * inp.forces["tip"] * np.ones(2), None


class _Integrator(Controller):
    """One state z with ż = 2 − t [1/s]; τ = (z, 0)."""

    name = "_test_integrator"
    n_states = 1

    def command(self, inp):
        return np.array([inp.z[0], 0.0]), np.array([2.0 - inp.t])


class _Ramp(Controller):
    """τ = (20 t, 0) [N·m] of the measured time alone: a held staircase that grows by 20 N·m/s."""

    name = "_test_ramp"

    def command(self, inp):
        return np.array([20.0 * inp.t, 0.0]), None


class _Runaway(Controller):
    """One state z whose rate overflows in the law's own arithmetic (ż = 1e308 · 10 = inf); τ = 0."""

    name = "_test_runaway"
    n_states = 1

    def command(self, inp):
        return np.zeros(2), np.array([1e308]) * 10.0


LAWS = (_Clock, _Probe, _Integrator, _Ramp, _Runaway)


@pytest.fixture(autouse=True)
def _test_laws():
    """The test laws registered while a test runs (the key reference lists the registered ones)."""
    for law in LAWS:
        register(law)
    yield
    for law in LAWS:
        CONTROLLERS.pop(law.name, None)


def b1(duration: float = 0.02, output_rate: float = 20_000.0, **controller) -> dict:
    doc = copy.deepcopy(B1)
    doc["duration"] = duration
    doc["solver"]["output_rate"] = output_rate
    if "kind" in controller:  # another law: its own table
        doc["controller"] = {}
    doc["controller"].update(controller)
    return doc


def run_of(doc: dict) -> tuple[HybridRun, object]:
    run = HybridRun(System(parse_scene(doc)))
    return run, run.run(0.0)


def compiled_mode(run: HybridRun):
    """(the run's one compiled mode, the indices of its state's held command)."""
    (mode,) = run.pipelines.pipes.values()
    ctl, z0 = mode.phase.controller, 2 * run.system.nQ + mode.phase.z_slice.start
    return mode, np.arange(z0 + ctl.held.start, z0 + ctl.held.stop)


def starts(run: HybridRun) -> list[tuple[float, object]]:
    """(t [s], segment) of each segment's start and each sample instant a segment's steps carried inside
    (numerics.held_steps: a piece of steps starts there)."""
    return [(float(t0), seg) for seg in run.segments
            for t0 in (seg.sol.starts if isinstance(seg.sol, PiecewiseDense) else [seg.t0])]


def held_commands(run: HybridRun) -> np.ndarray:
    """The held command at each segment's and each carried sample's start (each sample's, in a run without
    events)."""
    s = run.system
    z0 = 2 * s.nQ + s.z_slices[0].start
    return np.array([np.asarray(seg.sol(t0))[z0:z0 + s.nv] for t0, seg in starts(run)])


# ---- the hold ------------------------------------------------------------------------------
def test_the_command_is_piecewise_constant_with_jumps_exactly_at_the_samples():
    run, r = run_of(b1(sample_rate=RATE))
    assert isinstance(run.system.controllers[0], SampledController)
    assert len(run.segments) == 1  # one segment: the compiled DOP853 takes the samples as step boundaries
    begun = np.array([t0 for t0, _ in starts(run)])
    np.testing.assert_array_equal(begun, np.arange(20) / RATE)  # a piece of steps per period, starting at k/rate
    assert r.stats["samples"] == 20
    k = np.floor(r.t * RATE + 1e-9).astype(int)  # the sample in force at each output time
    tau = r["tau_cmd"]
    np.testing.assert_array_equal(tau, r["tau"])  # (ideal drives: the applied torque is the command)
    for j in range(20):
        block = tau[k == j]
        assert len(block) >= 19 and np.array_equal(block, np.repeat(block[:1], len(block), axis=0))
    firsts = np.array([tau[k == j][0] for j in range(20)])
    assert np.all(np.abs(np.diff(firsts, axis=0)).max(axis=1) > 1e-6)  # it jumps at every sample


def test_the_held_command_is_the_continuous_law_at_the_sample():
    run, _ = run_of(b1(sample_rate=RATE))
    held = held_commands(run)
    continuous = System(parse_scene(b1()))
    phase = continuous.start_phase(0, 0.0, run.segments[0].sol(0.0)[:continuous.n], None)
    for (t0, seg), tau in zip(starts(run)[:5], held[:5], strict=True):
        x = np.asarray(seg.sol(t0))
        xc = np.concatenate([x[:2 * run.system.nQ], x[2 * run.system.nQ + 2:]])  # without the held slots
        modes = seg.modes
        ref = interpreted_evaluate(continuous, t0, xc, modes, phase).tau_cmd
        np.testing.assert_allclose(tau, ref, rtol=1e-13, atol=1e-12)


def test_a_delay_of_d_samples_shifts_the_command_by_exactly_d_samples():
    d = 3
    run0, _ = run_of(b1(kind="_test_clock", sample_rate=RATE))
    run3, _ = run_of(b1(kind="_test_clock", sample_rate=RATE, delay=d))
    h0, h3 = held_commands(run0), held_commands(run3)
    np.testing.assert_array_equal(h3[d:], h0[:-d])
    np.testing.assert_array_equal(h3[:d], np.repeat(h0[:1], d, axis=0))  # the line starts full of the first
    assert not np.array_equal(h3, h0)


def test_the_laws_own_states_advance_by_forward_euler_once_per_sample():
    run, _ = run_of(b1(kind="_test_integrator", sample_rate=RATE))
    z = held_commands(run)[:, 0]  # τ_k = z_k, z_{k+1} = z_k + T (2 − t_k), z_0 = 0
    T = 1.0 / RATE
    expected = np.concatenate([[0.0], np.cumsum([T * (2.0 - k * T) for k in range(19)])])
    np.testing.assert_allclose(z, expected, rtol=1e-14, atol=1e-17)


def test_a_phase_begun_off_the_grid_integrates_its_laws_states_over_the_time_that_passed():
    """The first hold of a phase begun between sample instants is shorter than the period: the law's states advance
    by that hold, not by T (z = ∫ż dt at the samples, as the continuous law integrates it)."""
    doc = b1(duration=0.02, kind="_test_integrator")
    start = 0.0125  # [s] half a period off the 1 kHz grid
    second = copy.deepcopy(doc["phase"][0])
    doc["phase"][0]["until"] = start
    second.update(name="sampled", controller={"sample_rate": RATE})
    doc["phase"].append(second)
    run, _ = run_of(doc)
    s = run.system
    z0 = 2 * s.nQ + s.z_slices[1].start
    begun = [(t0, seg) for t0, seg in starts(run) if seg.phase.index == 1]
    times = np.array([t0 for t0, _ in begun])
    np.testing.assert_allclose(times, [start, *np.arange(13, 20) / RATE], rtol=0, atol=1e-15)
    z = np.array([np.asarray(seg.sol(t0))[z0] for t0, seg in begun])  # τ_k = z_k
    holds = np.diff(np.append(times, 0.02))[:-1]  # the first 0.5 ms, then T
    expected = np.concatenate([[0.0], np.cumsum(holds * (2.0 - times[:-1]))])
    np.testing.assert_allclose(z, expected, rtol=1e-13, atol=1e-17)
    assert z[1] == pytest.approx(0.5e-3 * (2.0 - start), rel=1e-13)  # (T (2 − t_s): twice that)


def test_held_voltages_run_through_the_motors_on_the_compiled_call():
    drive = {"kind": "dc_motor", "C_M": 0.05, "C_E": 0.05, "R": 1.0, "J": 1e-5, "N": 20.0}
    docs = [b1(kind="voltage", u=[1.0, -0.5], **rate) for rate in ({"sample_rate": RATE}, {})]
    for doc in docs:
        doc["robot"]["drive"] = drive
    sampled, continuous = (simulate(parse_scene(doc)) for doc in docs)
    assert {row["path"] for row in sampled.stats["paths"].values()} == {PIPELINE}
    np.testing.assert_array_equal(sampled["tau_cmd"], np.tile([1.0, -0.5], (len(sampled.t), 1)))  # [V]
    np.testing.assert_allclose(sampled["q"], continuous["q"], rtol=0, atol=1e-7)  # a constant law: the same run


MOTOR = {"kind": "dc_motor", "C_M": 0.05, "C_E": 0.04, "R": 1.5, "J": 1e-5, "N": 20.0, "N_star": 16.0}


def test_a_voltage_hold_keeps_the_motors_voltages_that_the_command_asks_at_the_sample():
    """hold = "voltage": u_k = R (τ_k / N*) / C_M + C_E N q̇(t_k) (eq. 51 inverted at the speed measured at the
    sample), held until the next, so the motors' torque N* C_M (u_k − C_E N q̇) / R falls with their speed between
    samples; hold = "command" holds the torque τ_k, the voltage following the speed."""
    docs = {hold: b1(kind="_test_clock", sample_rate=RATE, hold=hold) for hold in HOLDS}
    for doc in docs.values():
        doc["robot"]["drive"] = MOTOR
    runs = {hold: simulate(parse_scene(doc)) for hold, doc in docs.items()}
    m, r, c = MOTOR, runs["voltage"], runs["command"]
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    interpreted = simulate(parse_scene(docs["voltage"]), interpreted=True)
    np.testing.assert_array_equal(interpreted["u"], r["u"])  # (the same source)
    k = np.floor(r.t * RATE + 1e-9).astype(int)
    for j in range(20):
        at = np.flatnonzero(k == j)
        t_k = j / RATE
        assert r.t[at[0]] == pytest.approx(t_k, abs=1e-15)
        tau_k = np.array([math.sin(50.0 * t_k), math.cos(30.0 * t_k)])  # [N·m] the clock law's command
        u_k = m["R"] * (tau_k / m["N_star"]) / m["C_M"] + m["C_E"] * (m["N"] * r["v"][at[0]])
        np.testing.assert_allclose(r["u"][at], np.tile(u_k, (len(at), 1)), rtol=1e-13)
        torque = m["N_star"] * m["C_M"] / m["R"] * (u_k - m["C_E"] * m["N"] * r["v"][at])  # [N·m] eq. 51
        np.testing.assert_allclose(r["tau"][at], torque, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(c["tau"][at], np.tile(tau_k, (len(at), 1)), rtol=1e-13)
        assert np.abs(np.diff(r["tau"][at], axis=0)).max() > 0.0 and np.abs(np.diff(c["u"][at], axis=0)).max() > 0.0


def test_a_voltage_hold_is_dropped_with_the_rest_of_the_sampling_when_a_scene_is_made_continuous():
    from contactdyn.analysis.sampled_stability import continuous_scene

    doc = b1(sample_rate=RATE, hold="voltage")
    doc["robot"]["drive"] = MOTOR
    scene = continuous_scene(parse_scene(doc))
    assert not {"sample_rate", "hold"} & set(scene.document["controller"])
    assert not any(isinstance(c, SampledController) for c in System(scene).controllers)


class _FussyMotor(DcMotor):
    """A DC motor whose voltage law (Python only: it reads a dict) refuses a torque above a limit."""

    name = "_test_fussy_motor"
    meaning = "a DC motor refusing large torques (the test's)"
    limit = {"tau": 0.05}  #: [N·m]

    @staticmethod
    def voltage(spec, tau, qd, omega):
        if abs(tau) > _FussyMotor.limit["tau"]:
            raise ValueError(f"no voltage for {tau:.3g} N·m")
        return spec.R * (tau / spec.n_torque) / spec.C_M + spec.C_E * (spec.n_speed * qd)


def test_a_voltage_laws_own_error_at_a_sample_ends_the_run_as_it_does_a_continuous_run():
    register_drive_kind(_FussyMotor)
    try:
        for sampling in ({"sample_rate": RATE, "hold": "voltage"}, {}):
            doc = b1(**sampling)
            doc["robot"]["drive"] = {**MOTOR, "kind": "_test_fussy_motor"}
            with pytest.raises(LawError, match=r"drive kind '_test_fussy_motor' \(test_sampled_control\.py, line "
                                               r"\d+\) raised ValueError: no voltage for"):
                simulate(parse_scene(doc))
    finally:
        DRIVE_KINDS.pop("_test_fussy_motor")


def test_a_voltage_hold_needs_a_motor_on_every_joint(tmp_path):
    doc = b1(sample_rate=RATE, hold="voltage")
    with pytest.raises(SceneError) as err:
        System(parse_scene(doc, file=str(tmp_path / "s.toml")))
    assert all(w in str(err.value) for w in ("controller.hold", "a motor on every joint", "dc_motor", "s.toml"))


@pytest.mark.parametrize("holds", [("command", "voltage"), ("voltage", "command")])
def test_a_sampled_phase_starts_from_what_acts_in_the_units_it_holds(monkeypatch, holds):
    """Case 1's cart (a DC motor on every joint), its second phase sampled from an instant off the grid: the held slots
    its first sample measures with are what acts just before, in what the phase holds: the motors' voltages [V] for a
    voltage hold after a torque law, the drives' torques for a torque hold after a voltage hold (before: the previous
    law's command as it was, torques read as volts or volts as torques; on the real cell split in two phases, the
    first measured force 59.0 N where 50.4 N acted)."""
    from contactdyn.hybrid.sampling import SampledPhases

    first: dict[int, tuple[float, np.ndarray]] = {}
    take = SampledPhases.take

    def spy(self, t, x, phase, runner):
        if phase.index not in first:
            first[phase.index] = (t, x[self.slots[phase.index][0]].copy())
        return take(self, t, x, phase, runner)

    monkeypatch.setattr(SampledPhases, "take", spy)
    before, after = holds
    ov = {"duration": 0.2016, "phase.0.until": 0.2015, "solver.output_rate": 2e5,
          "phase.1.controller.sample_rate": 1000.0, "phase.1.controller.hold": after}
    if before == "voltage":
        ov.update({"phase.0.controller.sample_rate": 1000.0, "phase.0.controller.hold": "voltage"})
    r = simulate("case1_cart", ov)
    t1, held = first[1]
    assert t1 == 0.2015
    at = np.flatnonzero(r.t < t1)[-1]  # the output 5 µs before the phase's start: the phase before acts
    acting = r["u"][at] if after == "voltage" else r["tau"][at]
    np.testing.assert_allclose(held, acting, rtol=2e-3)  # (5 µs later)
    assert not np.allclose(held, r["tau_cmd"][at], rtol=0.05)  # the command as it was, in the other units


# ---- sensors -------------------------------------------------------------------------------
def test_the_low_pass_ramp_response_is_the_closed_form_at_the_samples():
    """A force ramping at c [N/s] from 0: the filter's readings are the continuous low-pass's response c (t − τ (1 −
    e^(−t/τ))) at the samples (exact for an input linear between them)."""
    fc, period, c = 30.0, 1e-3, 7e3
    tau = 1.0 / (2.0 * math.pi * fc)
    sensor = ForceSensor(SensorSpec(force_cutoff=fc), period)
    t = period * np.arange(60)
    readings = [sensor.read({"c": c * tk})["c"] for tk in t]
    np.testing.assert_allclose(readings, c * (t - tau * (1.0 - np.exp(-t / tau))), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("fc", [1e3, 1e5, 1.19e5, 1e9])
def test_a_fast_low_pass_reads_the_force_with_no_lag(fc):
    """As the cut-off grows the reading tends to the force at the sample (its lag τ on a ramp, ~1/(2π f_c)), smoothly
    (before: a whole sample of lag, until exp(−2π f_c T) underflowed at 119 kHz and the lag vanished at once)."""
    period, c = 1e-3, 1e3  # [s], [N/s]
    tau = 1.0 / (2.0 * math.pi * fc)
    sensor = ForceSensor(SensorSpec(force_cutoff=fc), period)
    readings = np.array([sensor.read({"c": c * k * period})["c"] for k in range(8)])
    lag = c * period * np.arange(8) - readings  # [N] behind the force
    np.testing.assert_allclose(lag[1:], c * tau * (1.0 - np.exp(-period * np.arange(1, 8) / tau)), rtol=1e-9,
                               atol=1e-12)
    assert np.all(lag <= c * tau + 1e-12)  # [N] never more than the continuous filter's lag


def test_noise_and_bias_are_the_seeded_draws():
    spec = SensorSpec(force_noise=2.0, force_bias=0.5, seed=11)
    sensor = ForceSensor(spec, 1e-3, stream=0)
    got = [sensor.read({"b": 10.0, "a": 1.0}) for _ in range(3)]
    draws = np.random.default_rng([11, 0]).normal(0.0, 2.0, 6).reshape(3, 2)  # keys in sorted order: a, b
    np.testing.assert_array_equal([[g["a"], g["b"]] for g in got], np.array([1.5, 10.5]) + draws)


def test_the_encoders_quantise_q_to_their_resolution():
    res = 1e-3
    system = System(parse_scene(b1(kind="_test_probe", sample_rate=RATE, sensor={"encoder_resolution": res})))
    _Probe.seen.clear()  # (building the system tries the law at a sample input: affine in the forces it reads)
    run = HybridRun(system)
    run.run(0.0)
    assert len(_Probe.seen) == len(starts(run))
    for (t, q, _), (t0, seg) in zip(_Probe.seen, starts(run), strict=True):
        assert t == t0
        np.testing.assert_allclose(q / res, np.round(q / res), rtol=0, atol=1e-9)
        assert np.all(np.abs(q - np.asarray(seg.sol(t))[:2]) <= 0.5 * res + 1e-15)
    assert {round(float(qi / res)) for _, q, _ in _Probe.seen for qi in q} != set()


def test_the_same_seed_gives_a_bit_identical_run_and_another_seed_another():
    def run(seed):
        return simulate(parse_scene(b1(kind="_test_probe", sample_rate=RATE, sensor={"force_noise": 5.0,
                                                                                       "seed": seed})))

    a, b, c = run(1), run(1), run(2)
    for name in a.channels:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    assert not np.array_equal(a["tau"], c["tau"])


# ---- convergence, paths ----------------------------------------------------------------------
def test_a_sampled_run_converges_to_the_continuous_one_at_first_order():
    duration = 0.2
    continuous = simulate(parse_scene(b1(duration, 1000.0)))

    def error(rate):
        r = simulate(parse_scene(b1(duration, 1000.0, sample_rate=rate)))
        return np.abs(r["tip"] - continuous["tip"]).max()

    e1, e2 = error(1000.0), error(4000.0)
    assert e2 < e1
    assert 3.0 <= e1 / e2 <= 5.0  # ∝ 1/rate: a ZOH's error is half a period's lag


def test_a_sampled_mode_runs_on_the_compiled_call_and_agrees_with_the_interpreted_call():
    run, r = run_of(b1(sample_rate=RATE))
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    plan, held_slots = compiled_mode(run)
    t0, seg = starts(run)[7]
    x = np.asarray(seg.sol(t0)).copy()
    for held in (x[held_slots], np.array([30.0, -12.0])):
        x[held_slots] = held
        ref = interpreted_evaluate(run.system, t0 + 3e-4, x, seg.modes, seg.phase).xdot
        np.testing.assert_allclose(plan.rhs(t0 + 3e-4, x.copy()), ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


def test_a_held_command_through_dc_motors_runs_on_the_compiled_call():
    """The held command (x's held slots) through the motors, on the compiled call."""
    doc = b1(sample_rate=RATE)
    doc["robot"]["drive"] = {"kind": "dc_motor", "C_M": 0.05, "C_E": 0.05, "R": 1.0, "J": 1e-5, "N": 20.0}
    run, r = run_of(doc)
    assert {row["path"] for row in r.stats["paths"].values()} == {PIPELINE}
    plan, held_slots = compiled_mode(run)
    t0, seg = starts(run)[7]
    x = np.asarray(seg.sol(t0)).copy()
    x[held_slots] = [3.0, -1.0]
    ref = interpreted_evaluate(run.system, t0 + 3e-4, x, seg.modes, seg.phase).xdot
    np.testing.assert_allclose(plan.rhs(t0 + 3e-4, x.copy()), ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())
    k = np.floor(r.t * RATE + 1e-9).astype(int)
    for j in range(20):  # the voltages follow the motors' speeds between samples, the command does not
        block, u = r["tau_cmd"][k == j], r["u"][k == j]
        assert np.array_equal(block, np.repeat(block[:1], len(block), axis=0))
        assert np.abs(np.diff(u, axis=0)).max() > 0.0


# ---- keys ----------------------------------------------------------------------------------
@pytest.mark.parametrize("controller, key, expected", [
    ({"delay": 2}, "controller.delay", "set sample_rate"),
    ({"sensor": {"force_noise": 1.0}}, "controller.sensor", "set sample_rate"),
    ({"sample_rate": -5.0}, "controller.sample_rate", "a number >= 0"),
    ({"sample_rate": 1e3, "delay": -1}, "controller.delay", "an integer >= 0"),
    ({"sample_rate": 1e3, "delay": 1.5}, "controller.delay", "an integer"),
    ({"sample_rate": "fast"}, "controller.sample_rate", "a number"),
    ({"sample_rate": 1e3, "sensor": {"force_noise": -1.0}}, "controller.sensor.force_noise", "a number >= 0"),
    ({"sample_rate": 1e3, "sensor": {"force_cutoff": 0.0}}, "controller.sensor.force_cutoff", "a number > 0"),
    ({"sample_rate": 1e3, "sensor": {"seed": -1}}, "controller.sensor.seed", "an integer >= 0"),
    ({"sample_rate": 1e3, "sensor": {"force_nois": 1.0}}, "controller.sensor.force_nois", "force_noise"),
    ({"sample_rate": 5e-324}, "controller.sample_rate", "0 (continuous) or a rate >= 1e-06 Hz"),  # (1 / rate = inf)
    ({"sample_rate": 10**400}, "controller.sample_rate", "a finite number"),  # (float() overflows)
    ({"sample_rate": 1e3, "sensor": {"encoder_resolution": 1e-310}}, "controller.sensor.encoder_resolution",
     "0 (exact) or a resolution >= 1e-12"),  # (q / resolution overflows)
    ({"hold": "voltage"}, "controller.hold", "set sample_rate"),
    ({"sample_rate": 1e3, "hold": "current"}, "controller.hold", "voltage"),
])
def test_bad_sampling_keys_are_named_with_the_file(tmp_path, controller, key, expected):
    with pytest.raises(SceneError) as err:
        parse_scene(b1(**controller), file=str(tmp_path / "s.toml"))
    message = str(err.value)
    assert key in message and expected in message and "s.toml" in message


def test_a_whole_float_or_a_numpy_integer_is_a_delay_and_a_huge_integer_in_a_list_is_named():
    """A sweep's --range point (2.0) and NumPy's integers read as integers; 10**400 in a vector is not an
    OverflowError."""
    for delay in (2.0, np.int64(2)):
        assert parse_scene(b1(sample_rate=RATE, delay=delay)).phases[0].sampling.delay == 2
    doc = b1()
    doc["robot"]["q0"] = [10**400, 0.0]
    with pytest.raises(SceneError, match="robot.q0: expected finite numbers"):
        parse_scene(doc)


def test_sampling_that_changes_nothing_is_warned_of():
    """A force sensor on a law that reads no force; a voltage hold of a voltage law; a period or a delay as long as the
    run."""
    from contactdyn.scene.sanity import scene_warnings

    def warned(doc):
        return " | ".join(scene_warnings(parse_scene(doc)))

    assert "reads no measured force" in warned(b1(sample_rate=RATE, sensor={"force_bias": 3.0}))
    assert "its period (0.05 s) is as long as the run" in warned(b1(duration=0.02, sample_rate=20.0))
    assert "controller.delay = 30 samples" in warned(b1(duration=0.02, sample_rate=RATE, delay=30))
    assert "sample" not in warned(b1(duration=0.02, sample_rate=RATE, delay=3))
    assert "gives voltages already" in warned(b1(kind="voltage", u=1.0, sample_rate=RATE, hold="voltage"))
    assert "hold" not in warned(b1(sample_rate=RATE, hold="voltage"))


def test_a_laws_states_that_overflow_at_a_sample_end_the_run_with_the_law_named():
    """Held until the next sample, an infinite state would make every call between fail: the sample says so."""
    from contactdyn.errors import SimulationError

    with pytest.raises(SimulationError, match=r"t = 0 s: _test_runaway: the law's own states are not finite"):
        simulate(parse_scene(b1(kind="_test_runaway", sample_rate=RATE)))


def test_a_sample_rate_of_zero_turns_a_scenes_sampled_loop_off_by_one_override():
    """``--set controller.sample_rate=0`` on a sampled scene with a delay and sensors: the continuous law, bit for bit
    the scene without the three keys."""
    sampled = b1(sample_rate=RATE, delay=2, sensor={"force_noise": 1.0, "seed": 3})
    off = simulate(parse_scene(sampled, {"controller.sample_rate": 0.0}))
    continuous = simulate(parse_scene(b1()))
    assert "samples" not in off.stats
    for channel in ("contact.tip.F_n", "q"):
        assert np.array_equal(off[channel], continuous[channel])


def test_a_phase_controller_table_merges_its_sampling_over_the_scenes():
    doc = b1(sample_rate=RATE)
    doc["phase"][0]["controller"] = {"sample_rate": 250.0, "delay": 1}
    scene = parse_scene(doc)
    assert scene.phases[0].sampling.rate == 250.0 and scene.phases[0].sampling.delay == 1
    assert parse_scene(b1()).phases[0].sampling is None


def test_a_phase_begun_just_before_an_instant_of_the_grid_samples_there_once():
    """A phase begun 1e-13 s before t = 13 ms samples at its start and next at 14 ms: one sample, not two 1e-13 s
    apart (before: both, and the second pushed the delay line once more); its first hold is that period."""
    doc = b1(duration=0.02, kind="_test_integrator")
    start = 0.013 - 1e-13  # [s]
    second = copy.deepcopy(doc["phase"][0])
    doc["phase"][0]["until"] = start
    second.update(name="sampled", controller={"sample_rate": RATE, "delay": 1})
    doc["phase"].append(second)
    run, r = run_of(doc)
    begun = [t0 for t0, seg in starts(run) if seg.phase.index == 1]
    np.testing.assert_allclose(begun, [start, *np.arange(14, 20) / RATE], rtol=0, atol=1e-15)
    assert r.stats["samples"] == 7
    z0 = 2 * run.system.nQ + run.system.z_slices[1].start
    first = next(seg for seg in run.segments if seg.phase.index == 1)
    z1 = np.asarray(first.sol(0.014))[z0]  # the law's state after its first hold: ż = 2 − t over 14 ms − start
    assert z1 == pytest.approx((0.014 - start) * (2.0 - start), rel=1e-12)


def test_a_phase_begun_at_a_touch_samples_at_once_and_then_on_the_grid():
    from contactdyn.scene.scene_file import load_scene

    rate, duration = 500.0, 1.56
    run = HybridRun(System(load_scene("case3_b_position", {"duration": duration, "controller.sample_rate": rate})))
    r = run.run(0.0)
    touch = next(e for e in r.events if e["kind"] == "touch")["t"]
    assert 1.4 < touch < duration
    s = run.system
    first = next(seg for seg in run.segments if seg.phase.index == 1)
    assert first.t0 == touch
    z0 = 2 * s.nQ + s.z_slices[1].start
    assert np.asarray(first.sol(first.t0))[z0] != 0.0  # the press law's first command, held from the touch
    n = math.ceil(duration * rate)
    begun = [t0 for t0, _ in starts(run)]
    k = np.array(begun) * rate
    on_grid = np.abs(k - np.round(k)) <= 1e-9  # (the trapezoid's corners fall on the grid: a float past it)
    assert set(np.round(k[on_grid]).astype(int)) == set(range(n))  # the grid goes on through the phase change
    others = {t0 for t0, on in zip(begun, on_grid, strict=True) if not on}
    assert others == {e["t"] for e in r.events} | {touch + 0.1}  # events, the force ramp's end
    assert r.stats["samples"] == n + 1  # the grid and the press law's first sample at the touch


def test_auto_switches_to_radau_under_a_hold_only_where_the_period_spans_many_explicit_steps():
    """benchmarks/hard/fast_mass.toml: a 1 g mass on 1e5 N/m holds DOP853 at its stability bound (~0.1 ms steps);
    ``auto`` checks after STEP_BUDGET steps, counted over the sample instants. At 1 kHz a period spans a few such
    steps: DOP853 goes on carrying the samples (Radau would end a segment at each, ~10× the run's cost before
    HOLD_SWITCH). At 100 Hz it spans ~100: Radau, its segments ending at the samples."""
    from contactdyn.numerics.integrators import STEP_BUDGET

    scene = ROOT / "benchmarks" / "hard" / "fast_mass.toml"
    fast = simulate(str(scene), {"duration": 0.25, "controller.sample_rate": RATE})
    assert fast.stats.get("auto_switches") is None and set(fast.stats["segments_by_method"]) == {"DOP853C"}
    assert fast.stats["segments"] < 10 and fast.stats["samples"] == 250 and STEP_BUDGET < fast.stats["steps"]
    slow = simulate(str(scene), {"duration": 0.25, "controller.sample_rate": 100.0})
    assert slow.stats.get("auto_switches") == 1 and slow.stats["segments_by_method"].get("Radau", 0) > 0
    assert slow.stats["samples"] == 25


def test_autos_check_under_a_hold_compares_the_explicit_step_with_the_period():
    """ẋ = −10⁴ x: a step of 0.1 ms (h|λ| = 1) is stability-bound, unless it is the scene's max_step; under a hold it
    goes to Radau (a collapsed 2-D slide to LSODA) only if the period is at least HOLD_SWITCH such steps; the step
    taken under a hold is the longest of the last ones (a step clipped to a sample instant is shorter)."""
    from types import SimpleNamespace

    from contactdyn.hybrid.loop import _explicit_step
    from contactdyn.numerics.integrators import HOLD_SWITCH

    def check(period, max_step=math.inf):
        run = SimpleNamespace(stats={"rhs_evals": 0}, auto_state=None, next_step=None,
                              solver=SimpleNamespace(max_step=max_step))
        HybridRun._auto_check(run, lambda t, x: -1e4 * x, 0.0, np.ones(1), 1e-4, 1.0, period)
        return run.auto_state

    assert check(None) == "Radau" and check(HOLD_SWITCH * 1e-4) == "Radau" and check(None, 2e-4) == "Radau"
    assert check(0.99 * HOLD_SWITCH * 1e-4) == "DOP853C"
    assert check(None, 1e-4) == "DOP853C"  # the step is the scene's max_step: not held by stability

    def collapse(period):  # a 2-D slide's collapsed steps: the same rule
        run = SimpleNamespace(stats={"rhs_evals": 0}, resting=None, next_step=None,
                              solver=SimpleNamespace(max_step=math.inf))
        HybridRun._collapse_check(run, lambda t, x: -1e4 * x, 0.0, np.ones(1), 1e-4, 1.0, period)
        return run.resting

    assert collapse(None) == "LSODA" and collapse(0.99 * HOLD_SWITCH * 1e-4) == ""
    sol = SimpleNamespace(t=np.array([0.0, 0.4e-3, 1e-3, 1.1e-3, 1.7e-3, 2e-3]))  # pieces of 1 ms, clipped steps
    assert _explicit_step(sol, held=False) == pytest.approx(0.3e-3)
    assert _explicit_step(sol, held=True) == pytest.approx(0.6e-3)


# ---- with joint friction -------------------------------------------------------------------------------------


def test_a_stuck_joint_breaks_away_at_the_first_sample_whose_held_command_passes_its_static_limit():
    """B1 at rest, its tip bonded on a frictionless surface, both joints stuck by dry friction: the held command
    (20 t_k, 0) [N·m] jumps at each sample and the joint's holding torque with it, so q1 (τ_s = 0.51 N·m) breaks
    away at the first sample past 0.51 N·m, t = 0.026 s at 1 kHz (no step of the segments sees it: the jump does)."""
    doc = b1(duration=0.04, output_rate=1000.0, kind="_test_ramp", sample_rate=RATE)
    doc["robot"]["v0"] = [0.0, 0.0]
    doc["robot"]["joint"] = {"q1": {"friction": 0.51}, "q2": {"friction": 0.5}}
    doc["contact"]["tip"]["tangent"] = {"model": "free"}
    doc["phase"][0].pop("force")
    result = simulate(parse_scene(doc))
    slips = [e for e in result.events if e["kind"] == "joint_slip"]
    assert slips and slips[0]["name"] == "q1"
    assert slips[0]["torque"] == pytest.approx(-0.52, rel=1e-8)  # the holding torque opposes the held 20 t_k
    assert slips[0]["t"] == pytest.approx(0.026, abs=1e-12)
    stuck = result["joint_stuck"][:, 0]
    assert np.all(stuck[result.t < 0.026 - 1e-9] == 1.0) and np.all(stuck[result.t > 0.026 + 1e-9] == 0.0)


def test_a_sampled_2d_launch_hands_over_to_the_scenes_method_once_its_direction_settles(monkeypatch):
    """case2_writer5dof: the pencil slips from rest at ~0.715 s, its 2-D friction direction stiff near rest: LSODA
    (LAUNCH_METHOD), which ends a segment at every sample and restarts there. Once period·|λ| ≤ LAUNCH_SETTLED for
    every decaying mode the compiled DOP853 carries the samples for the rest of the mode; the run agrees with one kept
    on LSODA to the integration's tolerance (rtol 1e-7 on ~6 N; measured 4e-8 N)."""
    from contactdyn.hybrid import loop

    over = {"controller.sample_rate": RATE, "duration": 0.8}
    handed = simulate("case2_writer5dof", over)
    monkeypatch.setattr(loop, "LAUNCH_SETTLED", 0.0)  # (never settled: LSODA for the whole mode)
    kept = simulate("case2_writer5dof", over)
    assert handed.stats["launches_handed_over"] == 1 and "launches_handed_over" not in kept.stats
    assert handed.stats["segments_by_method"]["LSODA"] < 20 < kept.stats["segments_by_method"]["LSODA"]
    assert handed.stats["samples"] == kept.stats["samples"] == 800
    for key in ("contact.pencil.F_n", "tip"):
        assert np.abs(handed[key] - kept[key]).max() < 1e-5


def test_rk4_checks_its_step_once_per_mode_not_at_each_samples_segment(monkeypatch):
    """RK4 ends a segment at every sample; it checks its fixed step against the mode's eigenvalues (n + 1 calls and an
    eigendecomposition) at a mode's first segment only, not at the later ones of the same mode. The outputs are those
    of a run that checks at every segment, bit for bit."""
    from contactdyn.hybrid import loop
    from contactdyn.numerics import integrators

    checks = []
    check = integrators.fixed_step_instability
    monkeypatch.setattr(integrators, "fixed_step_instability", lambda *a: checks.append(a[1]) or check(*a))
    overrides = {"solver.method": "RK4", "solver.max_step": 2.5e-4, "controller.sample_rate": 1000.0,
                 "duration": 0.1}
    once = simulate("b1", overrides)
    per_mode = len(checks)
    assert once.stats["segments"] >= 100 and 1 <= per_mode <= 1 + once.stats["events"]
    integrate = loop.integrate
    monkeypatch.setattr(loop, "integrate", lambda *a, **k: integrate(*a, **{**k, "checked": False}))
    every = simulate("b1", overrides)
    assert len(checks) - per_mode == every.stats["segments"]
    assert once.stats["rhs_evals"] < every.stats["rhs_evals"]
    for name in ("contact.tip.F_n", "q"):
        np.testing.assert_array_equal(once[name], every[name])
