"""Contacts and joints at rest decided together: one consistent mode for all the dry friction at an instant.

The transitions decide each dry-friction item on its own, the others' modes fixed: a contact at rest sticks if its
holding force is within the cone, else slides where that force pushes (:func:`~.transitions._at_rest`); a joint at
rest sticks if its holding torque is within τ_s, else slides where the load pushes
(:meth:`~contactdyn.model.joint_friction.JointFriction.switch`). Where a contact and a joint hold the same motion,
each decision changes the other's load, and the pair can be left in a mode the next instant contradicts: a joint
set sliding from rest while the contact it pushed against is stuck, which the contact's slip then decelerates back
through zero (``joint_stick``), whose decision makes the contact stick again, and so on: an event storm at one
instant (``benchmarks/hard/stickslip.toml`` with dry friction on q2).

:func:`consistent_at_rest` checks the mode the transitions left where a joint with dry friction is at rest: stuck,
within the stick band, or so slow against its acceleration that it would reverse within ``solver.storm_window`` (a
residual speed another item's stick left it). Every item at rest, joint or contact, must be *consistent*:

- a stuck contact's friction within its cone, |F_f| ≤ μ_s F_n; a stuck joint's holding torque |λᵢ| ≤ τ_s;
- a contact sliding from rest along d accelerates along it, d · ȧ_t ≥ 0 (ȧ_t: its slip's rate); a joint sliding
  from rest with sign s, s q̈ᵢ ≥ 0 (Coulomb's: a slide from rest goes where it accelerates against τ_k).

Where one is not, it searches the items' modes (each: stuck, or sliding either way from rest, a contact first where
its holding force pushes) for a consistent one, fewest slides first (the mode that holds most), and takes the first
it finds; a stick it tries must be inside its cone or τ_s by the cone tests' slack (at the very edge its slip event
would fire at once, the hysteresis of :func:`~contactdyn.model.friction.in_cone`). Where none is, the transitions'
mode stays (the storm guard stops a run that then chatters). A mode the transitions leave consistent is kept as it
is (a run whose decisions are never contradicted is unchanged).
"""

from __future__ import annotations

from itertools import combinations, product

import numpy as np

from ..model.friction import CONE_TOL, FORCE_ABS_TOL, direction_of, in_cone, slip_acceleration
from ..model.impact import project_velocity
from ..model.joint_friction import STUCK

__all__ = ["settle_together", "consistent_at_rest", "MAX_ITEMS", "MAX_TRIALS", "ACCEL_TOL"]

MAX_ITEMS = 8  #: items at rest (contacts and joints) searched together at most
#: modes tried at most per search, fewest slides first (each a solve, and a mode packed where it is new: ~ms): all
#: 3^n of up to 3 items, the sticks and single slides of up to 8
MAX_TRIALS = 27
#: [-] a slide from rest is consistent where its acceleration along its slide is ≥ −ACCEL_TOL × (1 + |its
#: acceleration|) [m/s² or rad/s²], a joint's ≥ −ACCEL_TOL × (1 + the call's largest |q̈|): the solve's rounding, which
#: is normwise (a joint that slips where τ_s = τ_k starts at q̈ ≈ 0, off by the rounding of the others')
ACCEL_TOL = 1e-9


class _Probe:
    """What the checks read of a mode at (t [s], x): one plain call of its compiled call (ẋ and the event values: the
    stuck contacts' friction, the normal forces, the slips, the stuck joints' holding torques), not an Evaluation."""

    def __init__(self, mode, t: float, x: np.ndarray):
        self.mode, self.t, self.x = mode, t, x
        self.xdot = mode.rhs(t, x)
        self._rates: dict[int, np.ndarray] = {}

    def slip_rate(self, system, ci: int) -> np.ndarray:
        """Contact ci's slip acceleration ȧ_t [m/s²] in tangent coordinates (the robot's kinematics at x)."""
        if ci not in self._rates:
            c, nQ = system.contacts[ci], system.nQ
            self._rates[ci] = slip_acceleration(system, c, system.kinematics(c, self.x), self.xdot[nQ:2 * nQ])
        return self._rates[ci]

    def hold(self, i: int) -> float:
        """Stuck joint i's holding torque [N·m or N]."""
        return self.mode.joint_hold(self.t, self.x).get(i, 0.0)

    def friction(self, ci: int) -> np.ndarray:
        """Stuck contact ci's friction force [N] in tangent coordinates."""
        return self.mode.stick_force(ci, self.t, self.x)

    def normal(self, ci: int) -> float:
        """Contact ci's normal force [N], > 0 pressing."""
        return self.mode.normal_force(ci, self.t, self.x)

    def slip(self, ci: int) -> np.ndarray:
        """Contact ci's slip velocity [m/s] in tangent coordinates."""
        return self.mode.slip(ci, self.t, self.x)


def _resting(v: float, a: float, band: float, window: float) -> bool:
    """Is an item moving at v [m/s or rad/s] with acceleration a at rest at this instant: within the stick band, or so
    slow against its acceleration that it would reverse within the storm window (a residual speed another item's stick
    left it, the projection's)?"""
    return abs(v) <= band or (v * a < 0.0 and abs(v) <= abs(a) * window)


def _touching_with_friction(system, modes) -> list[int]:
    """The touching contacts with friction along their tangents."""
    return [i for i, (c, m) in enumerate(zip(system.contacts, modes, strict=True))
            if m.touching and c.friction is not None and len(c.tangents)]


def _contacts_at_rest(system, probe: _Probe, modes, touching: list[int]) -> list[int]:
    """The contacts of ``touching`` (with friction) that are stuck or at rest (:func:`_resting`, along their slide)."""
    out, window = [], system.scene.solver.storm_window
    for i in touching:
        d, v_t = np.asarray(modes[i].slip), probe.slip(i)
        if not modes[i].stuck and float(np.linalg.norm(v_t)) > system.slip_band:  # (a 1-D slide: slowing at once?)
            if len(d) > 1 or not _resting(float(d @ v_t), float(d @ probe.slip_rate(system, i)), system.slip_band,
                                          window):
                continue
        out.append(i)
    return out


def _joints_at_rest(system, probe: _Probe, phase) -> list[int]:
    """The joints with dry friction off their limits that are stuck or at rest (:func:`_resting`; |q̇ᵢ| read in rad/s
    or m/s against ``solver.stick_velocity``)."""
    pressing = {i for i, _ in phase.limits}
    nQ, band, window = system.nQ, system.slip_band, system.scene.solver.storm_window
    x, xdot = probe.x, probe.xdot
    return [i for i, m in phase.joint_modes if i not in pressing and
            (m == STUCK or _resting(float(x[nQ + i]), float(xdot[nQ + i]), band, window))]


def _consistent(system, probe: _Probe, modes, phase, contacts, joints, strictly: bool = False) -> bool:
    """Is every item at rest consistent where ``probe`` was taken (the module docstring)? ``strictly``: a stuck item
    inside its limit by the cone tests' slack (a trial's stick: at the limit itself its slip event would fire at
    once)."""
    nQ = system.nQ
    qdd = probe.xdot[nQ:2 * nQ]
    rounding = ACCEL_TOL * (1.0 + float(np.max(np.abs(qdd))))  # [rad/s² or m/s²] a joint's slide's, normwise
    jf = system.joint_friction
    for i in contacts:
        c, m = system.contacts[i], modes[i]
        if m.stuck:
            if not in_cone(probe.friction(i), probe.normal(i), c.friction.mu_s, strictly):
                return False
            continue
        a_t = probe.slip_rate(system, i)
        if float(np.asarray(m.slip) @ a_t) < -ACCEL_TOL * (1.0 + float(np.linalg.norm(a_t))):
            return False
    for i, m in phase.joint_modes:
        if i not in joints:
            continue
        if m == STUCK:
            limit = jf.static[i] * (1.0 - CONE_TOL) - FORCE_ABS_TOL if strictly else jf.static[i]
            if abs(probe.hold(i)) > limit:
                return False
        elif m * float(qdd[i]) < -rounding:
            return False
    return True


def _trial(system, x, modes, phase, contacts, joints, choice):
    """(x, modes, phase) of one choice per item: None (stuck) or a slide (a contact's direction, a joint's sign),
    the stuck ones' velocities projected onto their rows and the joints at rest set to exactly 0."""
    modes = list(modes)
    jf = system.joint_friction
    for i, pick in zip(contacts, choice[:len(contacts)], strict=True):
        modes[i] = modes[i].with_(stuck=True) if pick is None else \
            modes[i].with_(stuck=False, slip=pick, from_rest=True)
    for i, pick in zip(joints, choice[len(contacts):], strict=True):
        phase = jf.with_mode(phase, i, STUCK if pick is None else pick)
    x = x.copy()
    nQ = system.nQ
    for i in joints:
        x[nQ + i] = 0.0
    if any(p is None for p in choice):
        x = project_velocity(system, x, modes, phase.limits, phase.joint_modes)
    return x, modes, phase


def _options(probe: _Probe, modes, contacts, joints) -> list[list]:
    """Per item its modes to try: stuck, then a slide where its holding force pushes, then the other way."""
    out = []
    for i in contacts:
        push = direction_of(-probe.friction(i)) if modes[i].stuck else tuple(modes[i].slip)
        out.append([None, push, tuple(-v for v in push)])
    return out + [[None, 1, -1] for _ in joints]


def consistent_at_rest(system, runner, t: float, x: np.ndarray, modes, phase):
    """(x, modes, phase, changed): the transitions' mode at (t [s], x) if every item at rest is consistent there
    (or no joint is at rest), else the first consistent mode of the search (the module docstring).
    ``runner(modes, phase)``: the run's mode (a PipelineMode: its plain call, :class:`_Probe`)."""
    if not phase.joint_modes:  # (no joint with dry friction: nothing to check, no call)
        return x, modes, phase, False
    probe = _Probe(runner(modes, phase), t, x)
    joints = _joints_at_rest(system, probe, phase)
    if not joints:
        return x, modes, phase, False
    touching = _touching_with_friction(system, modes)
    if touching:  # (their slips' rates read the robot's kinematics)
        system.update_at(x)
    contacts = _contacts_at_rest(system, probe, modes, touching)
    if len(contacts) + len(joints) > MAX_ITEMS or _consistent(system, probe, modes, phase, contacts, joints):
        return x, modes, phase, False
    for choice in _choices(_options(probe, modes, contacts, joints)):
        xt, mt, pt = _trial(system, x, modes, phase, contacts, joints, choice)
        if touching:
            system.update_at(xt)
        if _consistent(system, _Probe(runner(mt, pt), t, xt), mt, pt, contacts, joints, strictly=True):
            return xt, mt, pt, True
    return x, modes, phase, False


def _choices(options: list[list]):
    """The items' modes to try (one pick per item of its ``options``), fewest slides first, MAX_TRIALS at most."""
    n, tried = len(options), 0
    for slides in range(n + 1):
        for sliding in combinations(range(n), slides):
            picks = [opts[1:] if k in sliding else opts[:1] for k, opts in enumerate(options)]
            for choice in product(*picks):
                if tried == MAX_TRIALS:
                    return
                tried += 1
                yield list(choice)


def settle_together(transitions, t: float, x: np.ndarray, modes, phase):
    """(x, modes, phase) after :func:`consistent_at_rest` on the transitions' mode at t [s]: a mode it changes is
    logged per item (``stick``/``slip``, ``joint_stick``/``joint_slip``/``joint_reverse``) and counted
    (``Result.stats["decided_together"]``)."""
    system, log = transitions.system, transitions.log
    x_new, modes_new, phase_new, changed = consistent_at_rest(system, transitions.evaluate.runner, t, x, modes, phase)
    if not changed:
        return x, modes, phase
    transitions.stats["decided_together"] += 1
    for c, before, after in zip(system.contacts, modes, modes_new, strict=True):
        if before != after:
            log.log(t, "stick" if after.stuck else "slip", c.name)
    for (i, before), (_, after) in zip(phase.joint_modes, phase_new.joint_modes, strict=True):
        if before != after:
            kind = "joint_stick" if after == STUCK else "joint_slip" if before == STUCK else "joint_reverse"
            log.log(t, kind, system.joint_friction.names[i])
    return x_new, modes_new, phase_new
