"""Sanity warnings: scenes that validate but would run silently wrong.

Each check returns plain sentences naming the key to look at. They never stop a run:
:func:`contactdyn.simulate.simulate` issues them as :class:`SanityWarning` (Python's
``warnings``), stores them in ``Result.meta["warnings"]`` (saved in the run's JSON), and
``contactdyn run`` prints them. Checks:

- a force set-point that the phase's controller does not apply (a PD in joint space, open-loop
  laws), or that a task PD also position-controls along the same direction (the position
  term fights the set-point);
- a scene without contacts;
- friction coefficients above :data:`MU_MAX`;
- a linear stage whose contact period 2π√(m/k) is shorter than the output step, m its
  lightest neighbouring mass (an equivalent mass, or the robot's effective mass at the tip
  along the chain's direction in the start posture);
- a bonded contact whose tip starts off its surface (the bond then holds it there);
- a tip starting inside a compliant surface (the surface starts deformed by that depth; inside
  a rigid one is an error of :meth:`contactdyn.model.system.System.initial_state`: nothing can be deformed);
- a tip starting off a surface that the first phase's task-space reference never brings it to (and
  no force set-point of that phase pushes it there).

What the run then did is judged after it by :mod:`contactdyn.output.outcome` (a set-point that never
touched, a touch that never came).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ContactdynError
from ..laws.controllers import CONTROLLERS, Controller
from .scene_file import Mass, Scene, Stage

__all__ = ["SanityWarning", "MU_MAX", "scene_warnings", "system_warnings"]

MU_MAX = 2.0  #: [-] friction coefficients above this are almost certainly a typo
GAP_TOL = 1e-9  #: [m] a bonded tip further than this from its surface "starts off it"
REACH_TOL = 1e-4  #: [m] a reference that stays further than this from a surface never brings the tip there


class SanityWarning(UserWarning):
    """A scene that runs but is probably not what its author meant."""


def scene_warnings(scene: Scene) -> list[str]:
    """Checks that need only the scene."""
    out = []
    if not scene.contacts:
        out.append("the scene has no contacts ([contact.<name>]): nothing can touch, no contact force is computed")
    for c in scene.contacts.values():
        f = c.friction
        if f is not None and max(f.mu_s, f.mu_k) > MU_MAX:
            out.append(f"contact.{c.name}.tangent: friction coefficient {max(f.mu_s, f.mu_k):g} > {MU_MAX:g} "
                       "(typical dry friction: 0.1-1); check mu, mu_s, mu_k")
    for i, phase in enumerate(scene.phases):
        out += _force_warnings(scene, i, phase) + _sampling_warnings(scene, i, phase)
    return out


def _sampling_warnings(scene: Scene, i: int, phase) -> list[str]:
    """A sampled controller's settings that change nothing: a force sensor on a law that reads no force, a voltage
    hold of a law that gives voltages, a period or a delay as long as the run."""
    s, where = phase.sampling, f"phase[{i}] ({phase.name})"
    if s is None:
        return []
    out, kind, key = [], phase.controller.kind, phase.controller_key
    if not s.sensor.exact_forces and not getattr(CONTROLLERS.get(kind), "uses_forces", True):
        out.append(f"{where}: {key}.sensor sets a force noise, bias or filter, but the controller {kind!r} "
                   "reads no measured force: the force sensor changes nothing")
    if s.hold == "voltage" and getattr(CONTROLLERS.get(kind), "outputs", "torque") == "voltage":
        out.append(f"{where}: {key}.hold = \"voltage\", but the controller {kind!r} gives voltages already: "
                   "it holds them either way")
    if s.period >= scene.duration:
        out.append(f"{where}: {key}.sample_rate = {s.rate:g} Hz: its period ({s.period:g} s) is as long as the "
                   f"run ({scene.duration:g} s): the law samples once and holds that command")
    elif s.delay * s.period >= scene.duration:
        out.append(f"{where}: {key}.delay = {s.delay} samples ({s.delay * s.period:g} s) is as long as the run "
                   f"({scene.duration:g} s): every command is computed on the first measurement")
    return out


def _force_warnings(scene: Scene, i: int, phase) -> list[str]:
    cfg, where = phase.controller, f"phase[{i}] ({phase.name})"
    out = []
    for f in phase.forces:
        what = f"force set-point {f.ramp.value:g} N on contact {f.contact!r}"
        if not CONTROLLERS[cfg.kind].applies_force_setpoints(cfg):
            out.append(f"{where}: {what}, but its controller {cfg.kind!r} does not apply force set-points "
                       f"({', '.join(_force_controllers())} can; see contactdyn list controllers): "
                       "the force is whatever the motion makes it")
            continue
        c = scene.contacts[f.contact]
        u = c.normal if f.direction == "n" else c.tangents[int(f.direction[1]) - 1]
        axes = getattr(cfg, "axes", None)
        if cfg.kind == "task_pd" and axes is not None and float(np.linalg.norm(axes @ u)) > 1e-6:
            out.append(f"{where}: {what}, but the task PD also controls the position along its direction "
                       f"{np.round(u, 6).tolist()} (controller.axes): the position term fights the set-point; "
                       "leave that direction out of axes (B1: axes = [[1.0, 0.0, 0.0]])")
    return out


def system_warnings(system) -> list[str]:
    """Checks that need the robot in its start posture (``system``: a built model.system.System)."""
    try:
        x, _ = system.initial_state()
    except ContactdynError:  # the run itself reports an unusable start
        return []
    nv = system.nv
    robot = system.robot
    robot.update(x[:nv], np.zeros(nv))
    H_inv = np.linalg.pinv(robot.H)
    step = 1.0 / system.scene.solver.output_rate  # [s]
    out = []
    for c in system.contacts:
        kin = system.kinematics(c, x)
        body_point = c.fid < 0  # a body's point touches: its coordinates' masses move it
        for dc in c.chains:
            if body_point:
                mobility = sum(float(dc.u @ axis) ** 2 / system.M_rest[i - nv] for i, axis in c.touch_coords)
            else:
                J_u = dc.u @ kin.J
                mobility = float(J_u @ H_inv @ J_u)  # [1/kg] of the tip along u
            m_tip = 1.0 / mobility if mobility > 1e-12 else math.inf  # effective mass [kg]
            spec = c.spec.normal_chain if dc.label == "n" else c.spec.tangent_chain
            out += _period_warnings(f"contact.{c.name}.{'normal' if dc.label == 'n' else 'tangent'}", spec, m_tip,
                                    step, system.scene.solver.output_rate)
        gap = kin.gap  # [m]
        tip, where = ("the body's point", f"frame_point, body.{c.spec.frame}.position0") if body_point else \
            ("the tip", "point, robot.q0/tip0")
        if c.spec.bonded and abs(gap) > GAP_TOL:
            out.append(f"contact.{c.name}: bonded, but {tip} starts {gap:+.3g} m off the surface "
                       f"(contact.{c.name}.{where}): the bond holds it there, not on the surface")
        elif not c.spec.bonded and gap < -GAP_TOL:
            out.append(f"contact.{c.name}: {tip} starts {-gap:.3g} m inside the surface (contact.{c.name}.{where}): "
                       "the surface starts deformed by that depth and pushes back from t = 0")
        elif not c.spec.bonded and not body_point:  # (the reference moves the robot's tip, not a body)
            out += _reach_warnings(system.scene, c.name, kin.normal, kin.p_tip, kin.p_env)
    return out


def _overlapping(moves) -> bool:
    """Whether moves overlap in time (their sum then is no path of corners; the reach check stays out)."""
    spans = sorted((m.start, m.start + m.duration) for m in moves)
    return any(b[0] < a[1] for a, b in zip(spans, spans[1:], strict=False))


def _reach_warnings(scene: Scene, contact: str, n: np.ndarray, tip: np.ndarray, point: np.ndarray) -> list[str]:
    """The first phase's task-space reference (on the ground, straight moves) never comes within REACH_TOL of
    the surface along its normal n, and no force set-point of that phase pushes the tip there: it never touches
    (unless it falls or a later phase brings it)."""
    phase = scene.phases[0]
    ref = phase.reference
    if ref is None or ref.space != "task" or ref.body != "ground" or any(f.contact == contact for f in phase.forces) \
            or any(m.kind in ("circle", "velocity_ramp", "constant_velocity") for m in ref.moves) \
            or _overlapping(ref.moves):
        return []
    start = np.asarray(ref.start, float) if ref.start is not None else np.asarray(tip, float)
    ordered = sorted(ref.moves, key=lambda m: m.start)
    path = start + np.cumsum([np.zeros(3)] + [np.asarray(m.delta, float) for m in ordered], axis=0)
    gaps = path @ n - float(point @ n)  # [m] of the reference's corners above the surface
    closest, start_gap = float(gaps.min()), float(n @ (tip - point))  # [m]
    if closest <= REACH_TOL or start_gap <= REACH_TOL:
        return []
    return [f"contact.{contact}: the tip starts {start_gap:.3g} m from the surface and phase[0] "
            f"({phase.name})'s reference comes no closer than {closest:.3g} m: it never brings the tip there "
            f"(robot.tip0, contact.{contact}.point, the phase's moves)"]


def _period_warnings(where: str, chain, m_tip: float, step: float, rate: float) -> list[str]:
    """Affine stages whose period 2π√(m/k) is below the output step; the chain runs ground ... tip."""
    elements = [*chain.environment, *reversed(chain.robot)]
    masses = [math.inf, *(e.m if isinstance(e, Mass) else None for e in elements), m_tip]  # ground ... tip
    out = []
    for i, e in enumerate(elements):
        kv = e.kelvin_voigt() if isinstance(e, Stage) else None
        if kv is None or kv[0] <= 0.0:
            continue
        inner = next(m for m in reversed(masses[: i + 1]) if m is not None)
        outer = next(m for m in masses[i + 2:] if m is not None)
        m = min(inner, outer)
        period = 2.0 * math.pi * math.sqrt(m / kv[0])  # [s]
        if period < step:
            out.append(f"{where}: stage {i + 1} (from the ground), stiffness {kv[0]:g} N/m with {m:.3g} kg oscillates "
                       f"with period {period * 1e3:.3g} ms, shorter than the output step {step * 1e3:.3g} ms "
                       f"(solver.output_rate = {rate:g} Hz): the sampled force aliases; raise solver.output_rate "
                       "or check k")
    return out


def _force_controllers() -> list[str]:
    """The controller kinds that can act on force set-points (some only when so configured)."""
    return sorted(name for name, cls in CONTROLLERS.items()
                  if cls.applies_force_setpoints is not Controller.applies_force_setpoints)
