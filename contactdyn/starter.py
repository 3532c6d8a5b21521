"""``contactdyn new NAME``: a commented starter scene, an arm pressing on a table then sliding along it.

The scene is placed from the robot itself: a start posture where the tip moves well along two
world axes and the joints are away from their limits (:func:`working_posture`: a known seed
and postures drawn within the limits, the best-conditioned kept), the tip position there
(forward kinematics), a surface 2 cm below the tip along the axis it moves along best (z on a
tie), and a slide along the next. A robot whose tip cannot move along two axes is refused
(exit 2, saying why). Three phases: approach until touch, press 20 N, slide 10 cm while pressing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from .errors import SceneError
from .scene.toml_writer import format_value as toml_value

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
N_POSTURES = 64  #: postures drawn within the limits when choosing the start (working_posture)
MIN_QUALITY = 1e-3  #: [m/rad] a start posture worse than this cannot press and slide (working_posture)
MARGIN_ENOUGH = 0.3  #: [-] a limit margin (of the half-range) beyond which only the conditioning counts
TABLE_BIAS = 0.3  #: [-] the table goes under the tip (normal z) where the tip moves along z this well
PRESS = 20.0  #: [N] force set-point
GAP = 0.02  #: [m] tip start above the surface
SLIDE = 0.10  #: [m] slide length


def _load_arm(robot: str, tip: str | None):
    """(the robot with the chain to its tip active, the tip, the scene's inertia line). No tip given: the
    leaf frame with the most joints above it (a hand, a foot). Inertia data that fail the checks: repaired,
    and the scene says so (``robot.inertia = "repair"``)."""
    from .errors import RobotError
    from .robot.robot import Robot

    inertia, at_tip = "", {"tip": tip} if tip is not None else {}
    try:
        try:
            arm = Robot.load(robot, **at_tip)
        except RobotError as exc:
            if 'robot.inertia = "repair"' not in str(exc):
                raise
            inertia = 'inertia = "repair"  # its inertia data fail the checks: the nearest valid ones\n'
            arm = Robot.load(robot, **at_tip, inertia="repair")
        if tip is None:
            tip = _longest_leaf(arm)
            arm = Robot.load(robot, tip=tip, inertia="repair" if inertia else "check")
    except RobotError as exc:
        hint = "" if "no frame" not in str(exc) else f" (choose the pressing frame with --tip; `contactdyn list " \
            f"frames {robot}` lists them)"
        raise SceneError("--robot", f"a loadable robot and its tip frame{hint}", exc) from None
    return arm, tip, inertia


def _longest_leaf(arm) -> str:
    """The leaf body frame with the most joints between it and the root (ties: the first listed)."""
    from .robot.frames import find_frame
    from .robot.listing import end_effectors

    model = arm.model
    leaves = end_effectors(model)
    if not leaves:
        raise SceneError("--robot", "a robot with a moving leaf frame to press with", "none")
    def depth(name: str) -> int:  # joints between the frame and the root
        return len(model.supports[model.frames[find_frame(model, name, "--robot")].parentJoint])

    return max(leaves, key=depth)


def working_posture(arm, tip: str, seed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A start posture from which the tip can press and slide: (q, normal n, slide direction t, quality).

    The seed (a tried posture) where its quality reaches MIN_QUALITY; else, among the middle of the limits
    and N_POSTURES postures drawn within them (a fixed random seed: deterministic), the one of largest
    quality: the smallest singular value σ [m/rad] of the tip's linear Jacobian over the directions the tip
    has (:func:`_tip_rank`: two for a planar arm) and along n and t (:func:`_press_and_slide`), times
    min(margin, MARGIN_ENOUGH) / MARGIN_ENOUGH, the margin the smallest normalized distance of a bounded
    joint to its limits (beyond that margin the best-conditioned posture wins). Quality 0: the tip cannot
    move along two axes."""
    from .robot.posture import sampling_bounds

    lo, hi = sampling_bounds(arm)
    rng = np.random.default_rng(0)
    candidates = [0.5 * (lo + hi)] + [lo + (hi - lo) * rng.random(arm.nq) for _ in range(N_POSTURES)]
    seeded = seed is not None and len(seed) == arm.nq
    if seeded:
        candidates.insert(0, np.asarray(seed, float))
    half = np.where(hi > lo, 0.5 * (hi - lo), 1.0)
    bounded = np.isfinite(arm.lower) & np.isfinite(arm.upper) & (arm.upper > arm.lower)  # (a locked joint: none)
    jacobians = [arm.frame_jacobian(q, tip)[:3] for q in candidates]  # linear part, world-aligned [m/rad]
    rank = _tip_rank(jacobians)
    best = (-1.0, None, None, None)
    for k, (q, J) in enumerate(zip(candidates, jacobians, strict=True)):
        sigma, n, t = _press_and_slide(J, rank)
        margin = max(float(np.min((np.minimum(q - lo, hi - q) / half)[bounded])), 0.0) if bounded.any() else 1.0
        if k == 0 and seeded and sigma * margin >= MIN_QUALITY:
            return np.asarray(q, float), n, t, sigma * margin  # the tried posture, where it works
        quality = sigma * min(margin, MARGIN_ENOUGH) / MARGIN_ENOUGH  # far enough from the limits: σ decides
        if quality > best[0]:
            best = (quality, q, n, t)
    quality, q, n, t = best
    return np.asarray(q, float), n, t, max(quality, 0.0)


def _tip_rank(jacobians: list[np.ndarray]) -> int:
    """The directions the tip can move in at all (2: a planar arm, 3: a spatial one): the largest numerical rank
    of its linear Jacobian over the candidate postures."""
    ranks = [0]
    for J in jacobians[:16]:
        s = np.linalg.svd(J, compute_uv=False) if J.size else np.zeros(1)
        ranks.append(int(np.sum(s > 1e-9 * max(float(s[0]), 1e-300))))
    return max(ranks)


def _press_and_slide(J: np.ndarray, rank: int) -> tuple[float, np.ndarray, np.ndarray]:
    """(σ_min [m/rad], n, t) at a posture whose tip's linear Jacobian is J (3, nq) [m/rad]: n the world z if the
    tip moves along it at least TABLE_BIAS as well as along its best axis (a table under the tip), else that best
    axis; t the best of the other two."""
    axes = np.eye(3)[[2, 1, 0]]  # z, y, x
    mobility = np.array([float(np.linalg.norm(a @ J)) for a in axes])
    first = 0 if mobility[0] >= TABLE_BIAS * mobility.max() else int(np.argmax(mobility))
    rest = [i for i in range(3) if i != first]
    second = max(rest, key=lambda i: mobility[i])
    n, t = axes[first], axes[second]
    if rank < 2:
        return 0.0, n, t
    s = np.linalg.svd(J, compute_uv=False)
    # the tip must move along n and t, and away from the singularities of the directions the robot has
    return min(float(s[rank - 1]), float(np.linalg.svd(np.vstack([n @ J, t @ J]), compute_uv=False).min())), n, t


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


def _declared(params, prefix: str) -> str:
    """A law's declared parameters as scene lines under ``prefix`` (``normal.``, ``tangent.``), with units and
    meanings."""
    return "".join(f"{prefix}{p.name} = {_num(p.sample())}  # [{p.unit}] {p.meaning}\n" for p in params)


def _normal(contact: str, law: str | None) -> str:
    """The normal's keys of a contact model, with a stage law of the registry (its declared parameters) if given."""
    from .laws.stage_laws import STAGE_LAWS

    if law is None:
        return CONTACT_MODELS[contact]
    if contact == "rigid" or law not in STAGE_LAWS:
        raise SceneError("--law", f"a registered stage law ({', '.join(STAGE_LAWS)}; yours with --imports) on "
                         "contact model a, b or c", law if contact != "rigid" else f"{law} on a rigid contact")
    lines = f'normal.law = "{law}"                   # the stages\' force law (contactdyn.laws.stage_laws)\n'
    return CONTACT_MODELS[contact] + lines + _declared(STAGE_LAWS[law].params, "normal.")


def _tangent(friction: bool, friction_law: str | None, t: np.ndarray) -> str:
    """The tangent's keys: Coulomb with mu = 0.3, another registered law (its declared parameters), or none."""
    from .laws.friction_laws import FRICTION_LAWS

    if friction_law is not None and friction_law not in FRICTION_LAWS:
        raise SceneError("--friction-law", f"a registered friction law ({', '.join(FRICTION_LAWS)}; yours with "
                         "--imports)", friction_law)
    if not friction and friction_law is None:
        return "# tangent.model = \"friction\"  # add Coulomb friction: also tangent.directions and tangent.mu\n"
    head = f"tangent.model = \"friction\"              # stick/slip along the slide\ntangent.directions = [{_vec(t)}]\n"
    if friction_law in (None, "coulomb"):
        return head + "tangent.mu = 0.3                        # friction coefficient\n"
    return (head + f'tangent.law = "{friction_law}"\n'
            "tangent.mu_s = 0.35                     # static coefficient (the cone)\n"
            "tangent.mu_k = 0.3                      # kinetic coefficient\n"
            + _declared(FRICTION_LAWS[friction_law].params, "tangent."))


def starter_scene(name: str, robot: str = "writer2r", contact: str = "b", friction: bool = False,
                  tip: str | None = None, law: str | None = None, friction_law: str | None = None,
                  imports: tuple[str, ...] = (), run: str | None = None) -> str:
    """The TOML text of a starter scene (see the module docstring); ``law``, ``friction_law``: registered laws
    (a user's from ``imports``, which the caller has imported), written with their declared parameters; ``run``:
    what its comment says to run (default ``name``: a scene in sims/)."""
    from .robot.catalog import TOOL_FRAMES

    if contact not in CONTACT_MODELS:
        raise SceneError("--contact", f"one of {list(CONTACT_MODELS)}", contact)
    normal = _normal(contact, law)
    known_tip, q0 = POSTURES.get(robot, (None, None))
    arm, tip, inertia = _load_arm(robot, tip or known_tip or TOOL_FRAMES.get(robot))
    q, n, t, quality = working_posture(arm, tip, q0)
    if quality < MIN_QUALITY:
        raise SceneError("--robot", "a robot whose tip can move along two world directions (press along one, "
                         f"slide along the other) away from its joint limits; {robot}'s {tip!r} ({arm.nq} active "
                         f"joints) cannot in any posture tried (best: the tip's Jacobian's smallest singular value "
                         f"{quality:.2g} m/rad, less near a limit; at least {MIN_QUALITY:g} needed)", robot)
    p0 = arm.frame_position(q, tip)
    rest = [a for a in np.eye(3) if abs(a @ n) < 0.5]  # position-controlled axes while pressing
    tangent = _tangent(friction, friction_law, t)
    first = f"imports = {toml_value(list(imports))}  # your laws' modules (beside this file or on sys.path)\n" \
        if imports else ""
    wrist = "kd_joint = 0.1                          # [N·m·s/rad] damps what the task leaves free (the wrist)\n" \
        if arm.nv > 3 else ""
    return _align(f"""\
# {name}: a starter scene written by `contactdyn new` (robot {robot}, contact model {contact}).
# The tip approaches a table, presses {PRESS:g} N on it, then slides {SLIDE * 100:g} cm while pressing.
# Every key: docs/scenes.md or `contactdyn list keys`. Run: contactdyn run {run or name}
{first}name = {toml_value(name)}
description = {toml_value(f"{robot} pressing {PRESS:g} N on a model ({contact}) table and sliding {SLIDE * 100:g} cm")}
duration = 3.0                          # [s] simulated time

[robot]
urdf = {toml_value(robot)}                       # a name in urdf/, of example-robot-data, or a path beside this file
tip = {toml_value(tip)}                          # the controlled frame
{inertia}q0 = {_vec(q)}                          # [rad] start posture: tip at {_vec(p0)} m

[contact.table]                         # the name is yours; frame: robot.tip by default
point = {_vec(p0 - GAP * n)}            # [m] a point of the table, {GAP * 100:g} cm below the tip
normal.direction = {_vec(n)}            # outward normal: from the table towards the robot
{normal}{tangent}
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
    from .errors import is_plain_name
    from .output.result import atomic_write

    if not is_plain_name(args.name):
        raise SceneError("NAME", "a plain name (letters, digits, '_', '.', '+', '-'; no '/' or leading '.'): the "
                         "scene goes to sims/NAME.toml (--out chooses another file)", args.name)
    out = Path(args.out) if args.out else Path("sims") / f"{args.name}.toml"
    if out.exists() and not args.force:
        raise SceneError("--out" if args.out else "NAME", "a file that does not exist yet (or --force)", str(out))
    imports = tuple(m for group in args.imports or () for m in group.split(",") if m)
    if imports:
        from .scene.user_laws import IMPORTED, import_scene_modules

        import_scene_modules(list(imports), str(out.resolve()))  # next to the scene to be, then sys.path
        for module in imports:
            print(f"imported {module} from {IMPORTED.get(module, '?')}")
    run = args.name if not args.out else str(out)
    text = starter_scene(args.name, args.robot, args.contact, args.friction, args.tip, args.law,
                         args.friction_law, imports, run)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, text)  # a full disk leaves no half-written scene
    print(f"wrote {out}; run it: contactdyn run {run}")
    return 0
