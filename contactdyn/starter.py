"""``contactdyn new NAME``: a commented starter scene, an arm pressing on a table then sliding along it.

The scene is placed from the robot itself: its start posture (a known seed, or the neutral
posture), the tip position there (forward kinematics), a surface 2 cm below the tip along the
direction the tip can move in best (the world's z, else y or x), and a slide along the next
free direction. Three phases: approach until touch, press 20 N, slide 10 cm while pressing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .errors import SceneError
from .toml_writer import format_value as toml_value

__all__ = ["starter_scene", "new_command", "CONTACT_MODELS"]

#: contact models offered, with the normal keys of each (our example values)
CONTACT_MODELS = {
    "b": ('normal.model = "b"                     # ground -[k, b]- m\', struck by the tip (Part I model b)\n'
          "normal.k = 1e5                         # [N/m] surface stiffness\n"
          "normal.b = 300.0                       # [N·s/m] surface damping (zeta ~ 0.3 with the tip's mass)\n"
          "normal.m = 1.0                         # [kg] equivalent mass of the surface\n"),
    "a": ('normal.model = "a"                     # ground -[k_int, b_int]- m\' -[k_ext, b_ext]- tip (model a)\n'
          "normal.k_int = 1e5                     # [N/m] between the ground and m'\n"
          "normal.b_int = 300.0                   # [N·s/m]\n"
          "normal.m = 1.0                         # [kg] equivalent mass\n"
          "normal.k_ext = 2e4                     # [N/m] between m' and the tip\n"
          "normal.b_ext = 100.0                   # [N·s/m]\n"),
    "c": ('normal.model = "c"                     # a massless spring-damper (Part I model c)\n'
          "normal.k = 1e4                         # [N/m] surface stiffness\n"
          "normal.b = 50.0                        # [N·s/m] surface damping\n"),
    "rigid": ('normal.model = "rigid"                 # a constraint: plastic impact at touch, then no '
              "penetration\n"),
}
#: robots with a tried start posture: (tip frame, q0 [rad])
POSTURES = {
    "writer2r": ("tip", [0.43, 2.28]),
    "planar2r_b1": ("tip", [0.337307481430, -1.318116071653]),
    "writer5dof": ("tip", [0.3, 0.678629948129, 1.834747110377, 0.428215595084, 0.0]),
    "ur5": ("tool0", [-0.067689712079, -1.034024205522, 2.673650106542, -3.397374088227, -1.499321539814,
                      -0.363136146495]),
}
PRESS = 20.0  #: [N] force set-point
GAP = 0.02  #: [m] tip start above the surface
SLIDE = 0.10  #: [m] slide length


def _inside_limits(arm) -> np.ndarray:
    """Zero posture moved at least 10 % of each joint's range inside its limits [rad or m]."""
    span = np.where(np.isfinite(arm.upper - arm.lower), arm.upper - arm.lower, 0.0)
    lo = np.where(np.isfinite(arm.lower), arm.lower + 0.1 * span, -np.inf)
    hi = np.where(np.isfinite(arm.upper), arm.upper - 0.1 * span, np.inf)
    return np.clip(np.zeros(arm.nq), lo, hi)


def _num(x: float) -> str:
    text = f"{float(x) + 0.0:.6g}"  # + 0.0: no "-0"
    return text if any(c in text for c in ".en") else text + ".0"


def _vec(v) -> str:
    return "[" + ", ".join(_num(x) for x in v) + "]"


def _align(text: str, column: int = 40) -> str:
    """Line up the trailing comments of key lines at ``column``."""
    lines = []
    for line in text.splitlines():
        code, sep, comment = line.partition("  # ")
        if sep and code.strip() and not code.lstrip().startswith("#"):
            line = f"{code.rstrip():<{column - 1}} # {comment.strip()}"
        lines.append(line)
    return "\n".join(lines) + "\n"


def _directions(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(normal, slide direction): the first world axis of z, y, x the tip moves along, then the next one."""
    axes = [np.eye(3)[i] for i in (2, 1, 0)]
    mobile = [a for a in axes if np.linalg.norm(a @ J) > 1e-3]
    if len(mobile) < 2:
        raise SceneError("--robot", "a robot whose tip moves in at least two world directions", "fewer")
    return mobile[0], mobile[1]


def starter_scene(name: str, robot: str = "writer2r", contact: str = "b", friction: bool = False,
                  tip: str | None = None) -> str:
    """The TOML text of a starter scene (see the module docstring)."""
    from .errors import RobotError
    from .robot import Robot
    from .robot_catalog import TOOL_FRAMES

    if contact not in CONTACT_MODELS:
        raise SceneError("--contact", f"one of {list(CONTACT_MODELS)}", contact)
    known_tip, q0 = POSTURES.get(robot, (None, None))
    tip = tip or known_tip or TOOL_FRAMES.get(robot) or "tip"
    try:
        arm = Robot.load(robot, tip=tip)  # active joints: the chain to the tip
        q = np.asarray(q0, float) if q0 is not None and len(q0) == arm.nq else _inside_limits(arm)
        p0 = arm.frame_position(q, tip)
        J = arm.frame_jacobian(q, tip)[:3]  # linear part, world-aligned
    except RobotError as exc:
        raise SceneError("--robot", "a loadable robot and its tip frame (--tip)", exc) from None
    n, t = _directions(J)
    rest = [a for a in np.eye(3) if abs(a @ n) < 0.5]  # position-controlled axes while pressing
    tangent = (f"tangent.model = \"friction\"              # Coulomb stick/slip along the slide\n"
               f"tangent.directions = [{_vec(t)}]\n"
               "tangent.mu = 0.3                        # friction coefficient\n") if friction else \
        "# tangent.model = \"friction\"  # add Coulomb friction: also tangent.directions and tangent.mu\n"
    wrist = "kd_joint = 0.1                          # [N·m·s/rad] damps what the task leaves free (the wrist)\n" \
        if arm.nv > 3 else ""
    return _align(f"""\
# {name}: a starter scene written by `contactdyn new` (robot {robot}, contact model {contact}).
# The tip approaches a table, presses {PRESS:g} N on it, then slides {SLIDE * 100:g} cm while pressing.
# Every key: docs/scenes.md or `contactdyn list keys`. Run: contactdyn run {name}
name = {toml_value(name)}
description = {toml_value(f"{robot} pressing {PRESS:g} N on a model ({contact}) table and sliding {SLIDE * 100:g} cm")}
duration = 3.0                          # [s] simulated time

[robot]
urdf = {toml_value(robot)}                       # a name in urdf/, of example-robot-data, or a path beside this file
tip = {toml_value(tip)}                          # the controlled frame
q0 = {_vec(q)}                          # [rad] start posture: tip at {_vec(p0)} m

[contact.table]                         # the name is yours; frame: robot.tip by default
point = {_vec(p0 - GAP * n)}            # [m] a point of the table, {GAP * 100:g} cm below the tip
normal.direction = {_vec(n)}            # outward normal: from the table towards the robot
{CONTACT_MODELS[contact]}{tangent}
[controller]                            # one controller for every phase; a phase may override keys
kind = "task_pd"                        # tip-space PD: f = kp (x_d - x) + kd (v_d - v) - F_d n
kp = 2000.0                             # [N/m]
kd = 100.0                              # [N·s/m]
feedforward = "gravity"                 # cancel the arm's weight
{wrist}
[[phase]]
name = "approach"                       # move towards the table until the tip touches it
until = "touch:table"
[phase.reference]                       # start: where the tip is
moves = [{{ kind = "trapezoid", delta = {_vec(-2 * GAP * n)}, duration = 1.0 }}]  # [m] aims past the table

[[phase]]
name = "press"                          # hold the tip, press along the normal
until = 1.5                             # [s] from the scene start
controller = {{ axes = [{", ".join(_vec(a) for a in rest)}] }}  # position control off the normal only
[phase.reference]
moves = []                              # hold where the reference is
[[phase.force]]
contact = "table"
value = {_num(PRESS)}                       # [N] force set-point, reached after the ramp
duration = 0.2                          # [s] linear ramp from 0

[[phase]]
name = "slide"                          # slide along the table, still pressing
controller = {{ axes = [{", ".join(_vec(a) for a in rest)}] }}
[phase.reference]
moves = [{{ kind = "trapezoid", delta = {_vec(SLIDE * t)}, duration = 1.0 }}]  # [m], [s] after the phase starts
[[phase.force]]
contact = "table"
value = {_num(PRESS)}                       # [N] already reached: keep it
kind = "step"
""")


def new_command(args: argparse.Namespace) -> int:
    """``contactdyn new NAME``: write ``sims/NAME.toml`` (or ``--out``), refusing to overwrite."""
    out = Path(args.out) if args.out else Path("sims") / f"{args.name}.toml"
    if out.exists() and not args.force:
        raise SceneError("--out" if args.out else "NAME", "a file that does not exist yet (or --force)", str(out))
    text = starter_scene(args.name, args.robot, args.contact, args.friction, args.tip)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    run = args.name if not args.out else str(out)
    print(f"wrote {out}; run it: contactdyn run {run}")
    return 0
