"""The scene key reference, read off the scene reader itself.

Every scene value goes through :class:`contactdyn.scene.reader.Reader`. With
:func:`~contactdyn.scene.reader.recording` on, the reader notes each key it reads: its path, type,
unit, default, bounds and choices, and the table's selector in force (``kind``, ``model``).
:func:`reference` parses the documents of :mod:`contactdyn.scene.keytour` (which reach every
branch) that way and adds one line of meaning per key from :data:`MEANINGS`. So the
reference cannot drift from the reader: ``docs/scenes.md`` is :func:`markdown` (a test
compares them), ``contactdyn list keys [PREFIX]`` prints :func:`text`.
"""

from __future__ import annotations

import functools
import math
import re
import tomllib
from pathlib import Path
from typing import Any, NamedTuple

from .budget import STEPS_BASE, STEPS_PER_SAMPLE
from .reader import MISSING, VARIANT_KEYS, KeyRead, recording

__all__ = ["KeyDoc", "reference", "markdown", "text", "list_keys", "table_field_map", "write_generated",
           "MEANINGS"]

#: key paths the reader uses inside that are shown under another name
_ALIASES = ((re.compile(r"^phase\[\]\.controller(?=\.|$)"), "controller"),
            (re.compile(r"^robot\.locked\.[^.]+$"), "robot.locked.<joint>"),
            (re.compile(r"\.axes\.a$"), ".axes[]"))

_SECTIONS = ("", "robot", "body", "contact", "controller", "phase", "solver")

_M = "model"
MEANINGS: dict[str, str] = {
    "imports": "modules of your own laws to import first (names, not paths; next to the scene file, then "
               "sys.path); contactdyn run prints each; --no-imports refuses them",
    # top level
    "name": "scene name (runs and sweeps are named after it)",
    "description": "one line shown by `contactdyn list scenes`",
    "duration": "simulated time",
    "robot": "the robot: its URDF, tip frame, initial posture and drives",
    "body": "active environment bodies (carts; bodies on up to three orthogonal slides), one table per body: "
            "[body.<name>]",
    "contact": "contact interfaces, one table per contact: [contact.<name>]",
    "controller": "the controller of every phase; a phase's own [phase.controller] table overrides its keys (one "
                  "that names another kind takes only sample_rate, delay, hold and sensor from it)",
    "phase": "task phases, in order ([[phase]]); none: one phase 'main' over the whole run",
    "solver": "integrator settings",
    # robot
    "robot.urdf": "a URDF path (relative to the scene file), a file in urdf/, or an example-robot-data name (ur5, "
                  "panda, talos_arm, ...: contactdyn list robots)",
    "robot.tip": "the controlled frame (the tool tip; contactdyn list frames ROBOT); contacts default to it",
    "robot.active_joints": "joints that move (default: the chain from the root to robot.tip); every other joint is "
                           "locked (at robot.locked, else 0 clipped into its limits)",
    "robot.locked": "positions of locked joints, by joint name",
    "robot.locked.<joint>": "position of that locked joint",
    "robot.gravity": "gravity vector in the world frame",
    "robot.gravity_compensation": "fraction of gravity compensated statically (0: none, 1: all)",
    "robot.q0": "initial joint positions, within the limits (default: solved from tip0, else q_seed, else neutral)",
    "robot.v0": "initial joint velocities (default: zero)",
    "robot.tip0": "initial tip position: the start posture is solved for it (and the controller's tool_target), "
                  "within the joint limits, from several seeds",
    "robot.q_seed": "a hint for the posture solved from tip0: used when its size fits the robot and its solution "
                    "keeps 10 % of each joint's range from the limits",
    "robot.inertia": "a link failing the inertia checks: check (stop), repair (nearest valid inertia, reported), "
                     "trust (use it, with a warning)",
    "robot.joint_limits": "enforce: position limits are unilateral constraints (impact, pressing, release); "
                          "ignore: none",
    "robot.joint_friction": "urdf: each joint's damping and dry friction from the URDF's <dynamics damping friction> "
                            "(static = kinetic); ignore: none from the URDF (robot.joint tables still apply)",
    "robot.joint": "per joint, its own damping and dry friction, replacing the URDF's: [robot.joint.<joint>]",
    "robot.joint.<joint>": "that joint's viscous damping and Coulomb friction (keys not given: 0); a stuck joint "
                           "is held exactly and breaks away where its holding torque reaches friction_static",
    "robot.joint.<joint>.damping": "viscous damping b: torque -b q'",
    "robot.joint.<joint>.friction": "dry friction, static = kinetic (not with friction_static)",
    "robot.joint.<joint>.friction_static": "static limit: the largest torque a stuck joint holds",
    "robot.joint.<joint>.friction_kinetic": "sliding friction, <= friction_static (default: friction_static)",
    "robot.drive": "drives of the joints: a kind and its parameters, each a scalar or one per joint",
    # drives: robot.drive.* and body.<body>.drive.* from the kinds' declarations (_drive_rows)
    # bodies
    "body.<body>": "an active body translating along its axis (or its URDF's two or three orthogonal axes, one "
                   "coordinate each); its weight m g·axis acts on each coordinate (g = robot.gravity); or an "
                   "articulated body (a URDF with revolute joints): one coordinate per joint, its own dynamics",
    "body.<body>.urdf": "the body from a URDF whose one to three joints are prismatic and orthogonal: its masses, "
                        "axes and visuals (then no mass or axis; a path beside the scene or a name in urdf/); or "
                        "whose joints, revolute and prismatic, form a tree fixed in the world: an articulated body, "
                        "its H_b and h_b its own (no servo or drive)",
    "body.<body>.free": "the URDF's root link moves freely (a floating joint from a world link, or none): six "
                        "coordinates x, y, z [m] of its frame, then ZYX Euler angles yaw, pitch, roll [rad] (a run "
                        "stops within 1e-6 of pitch = +-90 deg, their singularity); an articulated body",
    "body.<body>.mass": "mass",
    "body.<body>.axis": "direction of travel in the world",
    "body.<body>.position0": "initial coordinate (one per coordinate for a body with several; rad for a revolute "
                             "joint)",
    "body.<body>.velocity0": "initial velocity (one per coordinate for a body with several)",
    "body.<body>.servo": "velocity servo: F = gain (velocity - v), realised by the body's drive",
    "body.<body>.servo.velocity": "velocity set-point (none: no servo force)",
    "body.<body>.servo.gain": "servo gain",
    "body.<body>.drive": "the body's drive (same keys as robot.drive, scalars only)",
    # contacts
    "contact.<contact>": "a contact between a robot frame (or a body's point) and a surface",
    "contact.<contact>.frame": "robot frame whose origin touches (default: robot.tip), or a body whose point "
                               "frame_point touches",
    "contact.<contact>.frame_point": "the touching point [m] of the body named by frame (world, at the body's "
                                     "coordinates 0; for an articulated body in body_frame's coordinates)",
    "contact.<contact>.body_frame": "for an articulated touching body: its frame (a link's or any URDF frame) in "
                                    "whose coordinates frame_point is given; the point moves and turns with it (any "
                                    "normal and tangential model)",
    "contact.<contact>.body": "what carries the surface: the fixed ground, an active body, or the robot (robot: "
                              "a robot frame, surface_frame, carries it: it moves and turns with that frame)",
    "contact.<contact>.surface_frame": "the robot frame carrying the surface when body = \"robot\", or the "
                                       "articulated body's frame when body names one: point, normal.direction and "
                                       "tangent.directions are then in that frame's own coordinates (any model; "
                                       "a chain's masses ride the surface)",
    "contact.<contact>.point": "a point of the undeformed surface (world; on a body at coordinate 0; on the robot "
                               "or an articulated body in surface_frame's coordinates)",
    "contact.<contact>.bonded": "the tip never separates (stays on the surface)",
    "contact.<contact>.normal": "the normal direction and its deformation model",
    "contact.<contact>.normal.direction": "outward surface normal, from the environment towards the robot",
    "contact.<contact>.normal.model": "rigid: constraint, impact at touch; c: massless stage k, b; b: ground-[k, b]-m' "
                                      "struck by the tip; a: ground-[k_int, b_int]-m'-[k_ext, b_ext]-tip; chain: "
                                      "explicit elements",
    "contact.<contact>.normal.k": "stiffness of the stage (Hunt-Crossley: [N/m^n])",
    "contact.<contact>.normal.b": "damping of the stage",
    "contact.<contact>.normal.m": "equivalent mass m' of the contact zone",
    "contact.<contact>.normal.law": "stage force law, a registered name (contactdyn.laws.stage_laws; yours with "
                                    "imports): linear F = k x + b x', hunt_crossley F = k x^n + b x^n x'",
    "contact.<contact>.normal.k_int": "stiffness k'' between the ground and m'",
    "contact.<contact>.normal.b_int": "damping b'' between the ground and m'",
    "contact.<contact>.normal.k_ext": "stiffness k' between m' and the tip",
    "contact.<contact>.normal.b_ext": "damping b' between m' and the tip",
    "contact.<contact>.normal.environment": "elements from the environment body out to the surface: stages {k, b} "
                                            "and masses {m}",
    "contact.<contact>.normal.robot": "elements from the robot's frame out to the surface",
    "chain.k": "stiffness of this stage",
    "chain.b": "damping of this stage",
    "chain.m": "an equivalent mass (an element with m is a mass, without it a stage)",
    "chain.law": "stage force law, a registered name (linear, hunt_crossley, yours with imports)",
    "contact.<contact>.tangent": "the tangential directions and their model",
    "contact.<contact>.tangent.model": "free: no tangential force; friction: Coulomb stick/slip; chain: a "
                                       "tangential deformation chain bonded at touch",
    "contact.<contact>.tangent.directions": "1 or 2 tangent directions, orthogonal to the normal and each other",
    "contact.<contact>.tangent.directions[]": "one tangent direction",
    "contact.<contact>.tangent.law": "friction law, a registered name (contactdyn.laws.friction_laws; yours with "
                                     "imports): coulomb mu(v) = mu_k, stribeck mu(v) = mu_k + (mu_s - mu_k) "
                                     "exp(-(v/v_s)^2)",
    "contact.<contact>.tangent.environment": "tangential chain elements from the environment (like normal.environment)",
    "contact.<contact>.tangent.robot": "tangential chain elements from the robot",
    # controller
    "controller.kind": "the control law (see `contactdyn list controllers`)",
    "controller.kp": "position gain: a stiffness (PD laws) or omega^2 of the error dynamics (dynamic laws); one value "
                     "or one per axis/joint",
    "controller.kd": "damping gain; one value or one per axis/joint",
    "controller.kv": "velocity gain 2 zeta omega of the error dynamics; one value or one per axis",
    "controller.kf": "force gain K_F of A10: the force error decays as exp(-kf t)",
    "controller.cancel": "A10 along the force normals: target subtracts J^T n F* (F* = F_d + integral of Q, the "
                         "paper's A10, no explicit force feedback); measured subtracts the measured force",
    "controller.inertia": "the H the law multiplies by: model (link + reflected rotor) or link (link alone)",
    "controller.k_null": "damping of the null-space motion of redundant arms",
    "controller.axes": "position-controlled directions (the others are left to force set-points)",
    "controller.axes[]": "one position-controlled direction",
    "controller.feedforward": "none; gravity: + g(q); bias: + h(q, q')",
    "controller.tool_axis": "tool direction in the tip frame to hold (none: orientation free)",
    "controller.tool_target": "world direction the tool axis is held along",
    "controller.orientation": "the tip frame's rotation in the world to hold (task_pd), by rows; its moment is "
                              "ko (1/2) vee(R_d R^T - R R_d^T) - do omega (none: orientation free; not with "
                              "tool_axis)",
    "controller.orientation[]": "one row of the rotation matrix",
    "controller.ko": "tool-axis or orientation hold: a stiffness (task_pd) or omega^2 of the tilt's error dynamics "
                     "(operational_space)",
    "controller.do": "tool-axis or orientation hold: a damping (task_pd) or 2 zeta omega of the tilt's error "
                     "dynamics (operational_space)",
    "controller.kd_joint": "joint damping (damps what the task leaves free)",
    "controller.kd_normal": "damping of the tip velocity along each force set-point's direction (zero at rest)",
    "controller.u": "motor voltages, one for every joint or one per joint",
    "controller.force": "constant tip force",
    "controller.rate": "growth rate of the tip force from start for ramp_time",
    "controller.start": "scene time the ramp begins (from the scene start)",
    "controller.ramp_time": "how long the ramp grows (inf: for ever)",
    "controller.amplitude": "sinusoid amplitude per axis",
    "controller.frequency": "sinusoid frequency",
    "controller.phase": "sinusoid phase per axis",
    "controller.space": "task: the tip position; joint: joint positions",
    "controller.force_reference": "along a force set-point, press to the depth F_d/k instead of the surface",
    "controller.nominal": "the environment the controller believes (default: the scene's own model (b) or (c))",
    "controller.nominal.k": "nominal stiffness",
    "controller.nominal.b": "nominal damping",
    "controller.nominal.m": "nominal mass",
    "controller.sample_rate": "run the law sampled at this rate with a zero-order hold (none or 0: continuous, "
                              "so --set controller.sample_rate=0 turns a scene's sampled loop off); the samples are at "
                              "k / rate from the scene start, and at a phase's start",
    "controller.delay": "the law computes on what it measured this many samples ago (needs sample_rate)",
    "controller.hold": "what the zero-order hold keeps (needs sample_rate): \"command\", the law's torques (DC motors "
                       "realise them as an ideal current loop would), or \"voltage\", the motors' voltages the command "
                       "asks at the sample (a motor on every joint)",
    "controller.sensor": "what a sampled law measures (needs sample_rate): force noise, bias and low-pass, encoders",
    "controller.sensor.force_noise": "standard deviation of the Gaussian noise on every measured contact force",
    "controller.sensor.force_bias": "offset of every measured contact force",
    "controller.sensor.force_cutoff": "cut-off of a first-order low-pass on the measured forces (none: no filter)",
    "controller.sensor.encoder_resolution": "joint encoders' resolution: q read as the nearest multiple (0: exact)",
    "controller.sensor.seed": "seed of the force noise's random generator (the same seed: the same run)",
    # phases
    "phase[].name": "phase name (events and plots name it)",
    "phase[].until": "end time from the scene start [s], or 'touch:<contact>' (ends at that contact's first touch)",
    "phase[].controller": "this phase's controller keys (over the scene's [controller] table)",
    "phase[].reference": "the position reference of this phase (none: no position reference)",
    "phase[].reference.space": "task: tip position [m]; joint: joint positions [rad or m]",
    "phase[].reference.body": "active body the reference rides on (its start and moves are relative to the body)",
    "phase[].reference.start": "start point (default: where the previous reference, or the tip, is)",
    "phase[].reference.moves": "moves added to the start point, each along a profile ([[phase.reference.moves]])",
    "phase[].reference.moves[].kind": "profile: trapezoid, triangle, constant_velocity, step, exponential (time "
                                      "constant = duration), velocity_ramp, circle",
    "phase[].reference.moves[].delta": "displacement of the move",
    "phase[].reference.moves[].velocity": "final velocity of a velocity ramp (kept after it)",
    "phase[].reference.moves[].center": "vector from the start point to the circle's centre",
    "phase[].reference.moves[].normal": "the circle's axis",
    "phase[].reference.moves[].turns": "number of turns (negative: clockwise about normal)",
    "phase[].reference.moves[].start": "start time of the move after the phase starts",
    "phase[].reference.moves[].duration": "duration of the move",
    "phase[].reference.moves[].accel_fraction": "fraction of the duration spent accelerating (trapezoid, circle)",
    "phase[].force": "force set-points of this phase ([[phase.force]]), applied by the controller",
    "phase[].force[].contact": "the contact to press on (default: the first contact)",
    "phase[].force[].direction": "n: press along the normal; t1, t2: push along minus that tangent",
    "phase[].force[].value": "force set-point reached at the end of the ramp",
    "phase[].force[].initial": "set-point at the ramp's start",
    "phase[].force[].start": "time the ramp starts after the phase starts",
    "phase[].force[].duration": "duration (linear) or time constant (exponential) of the ramp",
    "phase[].force[].kind": "ramp shape: linear, exponential or step",
    # solver
    "solver.method": "integrator (see `contactdyn list integrators`)",
    "solver.rtol": "relative tolerance",
    "solver.atol": "absolute tolerance",
    "solver.max_step": "largest step (the fixed step of RK4)",
    "solver.output_rate": "sample rate of the result's channels",
    "solver.record_energy": "integrate drive work and damper dissipation (energy.* channels)",
    "solver.max_events": "most events in a run before it stops (event storm guard)",
    "solver.steps_per_second": f"integration steps a run may take per simulated second, besides a base of "
                               f"{STEPS_BASE:g} and {STEPS_PER_SAMPLE} per sample of a sampled law (beyond, it stops "
                               "naming the cause)",
    "solver.storm_window": "events closer than this count towards a storm",
    "solver.storm_count": "that many events inside the window stop the run",
    "solver.stabilization": "Baumgarte rate of bonds, rigid contacts and sticks (0: none)",
    "solver.stick_velocity": "slip-speed band of the stick/slip guard: a slide stops when |v_t| falls to it",
}
for _k in list(MEANINGS):  # chain elements serve every chain
    if _k.startswith("chain."):
        for _side in ("normal.environment", "normal.robot", "tangent.environment", "tangent.robot"):
            MEANINGS[f"contact.<contact>.{_side}[].{_k[6:]}"] = MEANINGS[_k]
        del MEANINGS[_k]

#: what the reader's own record cannot say: defaults and choices that depend on the rest of the scene,
#: and types of keys read raw
OVERRIDES: dict[str, dict[str, str]] = {
    "name": {"default": "the file's name"},
    "imports": {"type": "list of strings"},
    "robot.active_joints": {"type": "list of strings", "default": "all joints"},
    "robot.q0": {"type": "list of numbers", "default": "neutral"},
    "robot.v0": {"default": "zero"},
    "body.<body>.urdf": {"type": "string", "default": "none: mass and axis given"},
    "body.<body>.mass": {"default": "required without urdf"},
    "body.<body>.free": {"type": "boolean", "default": "false (only with urdf)"},
    "robot.drive.kind": {"type": "string or list of strings", "default": "torque"},
    "contact.<contact>.normal.model": {"default": "rigid; chain when environment or robot is given"},
    "contact.<contact>.tangent.directions": {"type": "list of 3-vectors", "default": "required with friction or chain"},
    "contact.<contact>.frame": {"default": "robot.tip"},
    "contact.<contact>.frame_point": {"type": "3-vector", "default": "required when frame is a body"},
    "body.<body>.position0": {"type": "number (a list, one per coordinate, for a body with several)", "default": "0"},
    "body.<body>.velocity0": {"type": "number (a list, one per coordinate, for a body with several)", "default": "0"},
    "contact.<contact>.body": {"allowed": "ground, robot or a body name"},
    "contact.<contact>.surface_frame": {"type": "string (a robot frame, or the articulated body's)",
                                        "default": "required when body = \"robot\" or an articulated body"},
    "contact.<contact>.body_frame": {"type": "string (a frame of the touching body)",
                                     "default": "required when frame is an articulated body"},
    "contact.<contact>.normal.environment": {"type": "list of elements"},
    "contact.<contact>.normal.robot": {"type": "list of elements"},
    "contact.<contact>.tangent.environment": {"type": "list of elements"},
    "contact.<contact>.tangent.robot": {"type": "list of elements"},
    "controller.axes": {"type": "list of 3-vectors",
                        "default": "x, y, z (task_pd); every direction orthogonal to the force set-points (hybrid, "
                                   "operational_space)"},
    "controller.orientation": {"type": "3 x 3 rotation matrix (list of 3 rows)"},
    "controller.kp": {"type": "number or list"},
    "controller.kd": {"type": "number or list"},
    "controller.kv": {"type": "number or list"},
    "controller.u": {"type": "number or list"},
    "phase[].name": {"default": "main"},
    "phase[].until": {"type": "number or string", "default": "duration"},
    "phase[].controller": {"type": "table"},
    "phase[].reference.body": {"allowed": "ground or a body name"},
    "phase[].force[].contact": {"default": "the first contact", "allowed": "a contact name"},
}


class KeyDoc(NamedTuple):
    """One row of the scene reference."""

    key: str  #: key path; ``<contact>`` a name of yours, ``[]`` any item of an array
    when: str  #: the table's selectors under which the key is read ("" : always)
    type: str
    unit: str
    default: str  #: "required" when the key must be given
    allowed: str  #: choices or bounds
    meaning: str

    @property
    def required(self) -> bool:
        return self.default == "required"


def _display(pattern: str) -> str:
    for regex, replacement in _ALIASES:
        pattern = regex.sub(replacement, pattern)
    return pattern


def _fmt(value: Any) -> str:
    if value is MISSING:
        return "required"
    if value is None or (isinstance(value, dict) and not value):
        return ""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, float):
        return "inf" if math.isinf(value) else f"{value:g}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    return str(value)


def _type(types: set[str], sizes: set[int | None]) -> str:
    names = {"list": "list of numbers", "direction": "direction (3-vector, normalised)", "tables": "array of tables",
             "named tables": "tables by name"}
    size = next(iter(sizes), None) if len(sizes) == 1 else None
    out = []
    for t in sorted(types - {"any", "has"}, key=("number", "integer", "boolean", "string", "list", "direction", "table",
                                          "tables", "named tables").index):
        out.append(f"{size}-vector" if t == "list" and size else names.get(t, t))
    return " or ".join(out) or "any"


def _allowed(reads: list[KeyRead]) -> str:
    choices = {r.choices for r in reads if r.choices is not None}
    if len(choices) == 1:
        return ", ".join(next(iter(choices)))
    if len(choices) > 1:
        return "?"  # depends on the scene: an OVERRIDES entry must say what
    parts = []
    for r in reads:
        if r.lo is not None:
            parts.append(f"{'>' if r.lo_open else '>='} {_fmt(float(r.lo))}")
        if r.hi is not None:
            parts.append(f"<= {_fmt(float(r.hi))}")
        if parts:
            break
    return ", ".join(parts)


def _rows(reads: list[KeyRead]) -> list[KeyDoc]:
    by_variant: dict[tuple[str, tuple[str, ...]], list[KeyRead]] = {}
    for r in reads:
        leaf = r.pattern.rpartition(".")[2]
        if leaf in VARIANT_KEYS and any(v.startswith(f"{leaf} = ") for v in r.variant):
            continue  # a selector read again inside its own variant (tangent chains reuse the normal's reader)
        by_variant.setdefault((_display(r.pattern), r.variant), []).append(r)
    asked_only = {k for k, group in by_variant.items() if all(r.type == "has" for r in group)}
    declared = {_display(r.pattern): r.meaning for r in reads if r.meaning}  #: a law's parameters (params.Param)
    answered = {k[0] for k in by_variant if k not in asked_only}
    table_variants: dict[str, set[tuple[str, ...]]] = {}
    rendered: dict[tuple, list[tuple[str, ...]]] = {}
    for (key, variant), group in by_variant.items():
        if (key, variant) in asked_only and key in answered:
            continue
        table_variants.setdefault(key.rpartition(".")[0], set()).add(variant)
        rendered.setdefault(_render(key, group), []).append(variant)
    rows = []
    for (key, type_, unit, default, allowed), variants in rendered.items():
        others = table_variants[key.rpartition(".")[0]] - {()}
        when = "" if () in variants or set(variants) >= others else "; ".join(", ".join(v) for v in variants)
        rows.append(KeyDoc(key, _merge_when(when), type_, unit, default, allowed,
                           MEANINGS.get(key) or declared.get(key, "")))
    order = {k: i for i, k in enumerate(dict.fromkeys(_display(r.pattern) for r in reads))}
    return _drive_rows(sorted(rows, key=lambda d: (_SECTIONS.index(_section(d.key)), order[d.key])))


def _render(key: str, group: list[KeyRead]) -> tuple[str, str, str, str, str]:
    """(key, type, unit, default, allowed) of one key read under one variant."""
    typed = [r for r in group if r.type not in ("any", "has")] or [r for r in group if r.type == "any"] or group
    types = {r.type for r in typed}
    if "named tables" in types:
        types.discard("table")
    defaults = {_fmt(r.default) for r in typed}
    if "required" in defaults and any(r.type == "has" for r in group):
        defaults = {""}  # read only when present (``x if r.has(k) else None``)
    over = OVERRIDES.get(key, {})
    return (key, over.get("type") or _type(types, {r.size for r in typed}),
            "; ".join(sorted({r.unit for r in typed if r.unit})),
            over.get("default") or ("?" if len(defaults) > 1 else defaults.pop()),  # "?": depends on the scene
            over.get("allowed") or _allowed(typed))


def _drive_rows(rows: list[KeyDoc]) -> list[KeyDoc]:
    """Drive keys from the kinds' declarations (:mod:`contactdyn.laws.drive_kinds`): ``kind`` names every registered
    kind, each parameter is one row with the kinds that declare it as "when"."""
    from ..laws.drive_kinds import DRIVE_KINDS

    out: list[KeyDoc] = []
    for d in rows:
        table, _, name = d.key.rpartition(".")
        if not table.endswith("drive"):
            out.append(d)
            continue
        if name == "kind":
            kinds = "; ".join(f"{k}: {cls.meaning}" if cls.meaning else k for k, cls in DRIVE_KINDS.items())
            out.append(d._replace(meaning=kinds + "; a list gives one per joint"))
            continue
        if any(o.key == d.key for o in out):
            continue
        kinds = [k for k, cls in DRIVE_KINDS.items() if any(p.name == name for p in cls.params)]
        p = next(p for p in DRIVE_KINDS[kinds[0]].params if p.name == name)
        default = "required" if p.default is None and p.same_as is None else (
            f"= {p.same_as}" if p.same_as is not None else _fmt(float(p.default)))
        allowed = f"{'>' if p.lo_open else '>='} {_fmt(float(p.lo))}"
        if p.hi is not None:
            allowed += f", <= {_fmt(float(p.hi))}"
        out.append(d._replace(
            when="kind = " + ", ".join(kinds), unit=p.unit if p.unit != "-" else "",
            type="number or list (one per joint)" if table == "robot.drive" else "number",
            default=default, allowed=allowed, meaning=p.meaning))
    return out


def _merge_when(when: str) -> str:
    """``kind = a; kind = b`` -> ``kind = a, b``."""
    parts = [p.split(" = ") for p in when.split("; ") if p]
    if parts and all(len(p) == 2 and p[0] == parts[0][0] for p in parts):
        return f"{parts[0][0]} = " + ", ".join(p[1] for p in parts)
    return when


def _section(key: str) -> str:
    head = re.split(r"[.\[]", key, maxsplit=1)[0]
    return head if head in _SECTIONS and key != head else ""


@functools.cache
def reference() -> tuple[KeyDoc, ...]:
    """Every scene key the reader reads, with its meaning (see the module docstring)."""
    from .keytour import tour
    from .scene_file import parse_scene

    with recording() as reads:
        for doc in tour():
            parse_scene(tomllib.loads(doc))
    return tuple(_rows(reads))


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def markdown() -> str:
    """``docs/scenes.md``."""
    lines = ["# Scene keys", "",
             "Generated from the scene reader by `python -m contactdyn.scene.keys` (a test checks it is "
             "current); `contactdyn list keys [PREFIX]` prints the same. `<contact>`, `<body>`: a name of your "
             "choosing; `[]`: every item of an array of tables (`[[phase]]`, `[[phase.force]]`). The controller's "
             "keys go in `[controller]` (every phase) or `[phase.controller]` (that phase: its keys over "
             "`[controller]`'s; a phase whose table names another `kind` takes only the sampling keys `sample_rate`, "
             "`delay`, `hold` and `sensor` from `[controller]`, not the other kind's parameters, and an error in a key "
             "it took is named where the file has it, `controller.kp (inherited by phase[1].controller)`). "
             "\"when\": the key is read only under that `kind` or `model` of its table. Units are SI.", ""]
    section = None
    for d in reference():
        if _section(d.key) != section:
            section = _section(d.key)
            lines += ["", f"## {section or 'top level'}", "",
                      "| key | when | type | unit | default | allowed | meaning |", "|---|---|---|---|---|---|---|"]
        lines.append("| " + " | ".join(_cell(c) for c in (f"`{d.key}`", d.when, d.type, d.unit, d.default, d.allowed,
                                                            d.meaning)) + " |")
    return "\n".join(lines) + "\n"


_TOKEN = re.compile(r"\[[^\]]*\]?|[^.\[]+")  #: a key's parts: names, ``<placeholders>`` and ``[]`` / ``[0]``


def key_matches(key: str, prefix: str) -> bool:
    """True when ``key`` starts with ``prefix``, where a table's own name or index may stand for its placeholder
    and an array's ``[]`` may be left out, as in TOML headers: ``contact.pencil.normal``, ``phase[1].force`` and
    ``phase.force`` all match ``contact.<contact>.normal...`` or ``phase[].force...``."""
    parts, typed = _TOKEN.findall(key), _TOKEN.findall(prefix)
    i = 0
    for k, word in enumerate(typed):
        last = k == len(typed) - 1 and not prefix.endswith(".")
        if i < len(parts) and parts[i] == "[]" and not word.startswith("["):
            i += 1  # `phase.force` for `phase[].force`
        if i == len(parts):
            return False
        part = parts[i]
        if part.startswith("<"):
            ok = not word.startswith("[")
        elif part == "[]":
            ok = re.fullmatch(r"\[\d*\]?" if last else r"\[\d*\]", word) is not None
        else:
            ok = part.startswith(word) if last else part == word
        if not ok:
            return False
        i += 1
    return i < len(parts) or not prefix.endswith(".")


def text(prefix: str = "") -> str:
    """The reference for the terminal, keys starting with ``prefix`` (``contactdyn list keys``)."""
    out = []
    for d in reference():
        if not key_matches(d.key, prefix):
            continue
        details = ", ".join(p for p in (d.type, f"[{d.unit}]" if d.unit else "",
                                        f"default {d.default}" if d.default not in ("", "required") else d.default,
                                        f"allowed {d.allowed}" if d.allowed else "") if p)
        when = f" (when {d.when})" if d.when else ""
        out.append(f"{d.key}{when}: {details}\n    {d.meaning}")
    return "\n".join(out)


def list_keys(args: Any) -> int:
    """``contactdyn list keys [PREFIX]``: text, or ``--json`` rows; exit 2 when no key starts with PREFIX."""
    import json

    from ..errors import SceneError

    if args.what != "keys":
        raise SceneError("list", "a prefix only after `keys` (contactdyn list keys PREFIX)", args.prefix)
    prefix = args.prefix or ""
    rows = [d for d in reference() if key_matches(d.key, prefix)]
    if not rows:
        sections = sorted({re.split(r"[.\[]", d.key, maxsplit=1)[0] for d in reference()})
        raise SceneError("PREFIX", f"the start of a scene key ({', '.join(sections)})", prefix)
    if args.json:
        print(json.dumps({"keys": [d._asdict() for d in rows]}, indent=1))
    else:
        print(text(prefix))
    return 0


def table_field_map() -> dict[str, str]:
    """Table pattern -> its fields, required ones first (``"phase[].force[]": "value (required), contact, ..."``).

    Written into :mod:`contactdyn.scene.keyfields` for the reader's error messages (the reader cannot
    import this module: it reads scenes itself).
    """
    fields: dict[str, dict[str, bool]] = {}
    for d in reference():
        parent, _, leaf = d.key.rpartition(".")
        if not parent or leaf.endswith("[]"):  # items of a list are not fields
            continue
        for table in (parent, f"phase[].{parent}") if parent.startswith("controller") else (parent,):
            own = fields.setdefault(table, {})
            own[leaf] = own.get(leaf, False) or (d.required and not d.when and not leaf.startswith("<"))
    return {table: ", ".join(sorted((f"{k} (required)" if req else k for k, req in f.items()),
                                    key=lambda k: not k.endswith("(required)")))
            for table, f in fields.items()}


def keyfields_source() -> str:
    """The text of ``contactdyn/scene/keyfields.py``."""
    lines = ["# ruff: noqa: E501", '"""Fields of every scene table, for the reader\'s error messages.', "",
             "Generated by ``python -m contactdyn.scene.keys`` from the scene reader (``tests/test_keys.py`` checks",
             'it is current); do not edit."""', "", "TABLE_FIELDS = {"]
    lines += [f"    {table!r}: {fields!r}," for table, fields in table_field_map().items()]
    return "\n".join(lines) + "\n}\n"


def write_generated(root: Path | None = None) -> list[Path]:
    """Write ``docs/scenes.md`` and ``contactdyn/scene/keyfields.py`` (in the checkout at ``root``)."""
    root = root or Path(__file__).resolve().parents[2]  # the checkout
    out = [(root / "docs" / "scenes.md", markdown()),
           (root / "contactdyn" / "scene" / "keyfields.py", keyfields_source())]
    for path, content in out:
        path.write_text(content)
    return [p for p, _ in out]


if __name__ == "__main__":
    for written in write_generated():
        print(f"wrote {written}")
