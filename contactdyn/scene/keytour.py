"""Documents that walk the scene reader through every branch, so that it reads (and records) every key.

:mod:`contactdyn.scene.keys` parses these with :func:`contactdyn.scene.reader.recording` on; the scene reference
(``docs/scenes.md``, ``contactdyn list keys``) is what the reader read. A new key in a branch these
documents do not reach makes ``tests/test_keys.py`` fail until a document here reaches it.
"""

from __future__ import annotations

__all__ = ["TOUR", "tour"]

_ROBOT = '''
duration = 1.0
[robot]
urdf = "writer2r"
tip = "tip"
'''

_FULL = '''
imports = []
name = "tour"
description = "every key of the robot, a body, a contact, a phase and the solver"
duration = 1.0
[robot]
urdf = "writer2r"
tip = "tip"
active_joints = ["q1", "q2"]
locked = { q3 = 0.0 }
gravity = [0.0, 0.0, -9.81]
gravity_compensation = 0.5
q0 = [0.1, 0.2]
v0 = [0.0, 0.0]
tip0 = [0.4, 0.0, 0.0]
q_seed = [0.1, 0.2]
joint_friction = "urdf"
[robot.joint.q1]
damping = 0.01
friction = 0.2
[robot.joint.q2]
friction_static = 0.3
friction_kinetic = 0.2
[robot.drive]
kind = "dc_motor"
R = 1.0
C_M = 0.1
C_E = 0.1
J = 1e-4
N = 100.0
N_star = 80.0
wheel_radius = 0.1
u_max = 24.0
[body.cart]
mass = 10.0
axis = [1.0, 0.0, 0.0]
position0 = 0.0
velocity0 = 0.0
servo = { velocity = 0.1, gain = 100.0 }
[body.cart.drive]
kind = "elastic"
R = 1.0
C_M = 0.1
C_E = 0.1
J = 1e-4
N = 100.0
wheel_radius = 0.1
u_max = 24.0
c = 1e3
d = 1.0
I1 = 1e-5
I2 = 1e-5
twist_damping = 0.1
[contact.tip]
frame = "tip"
body = "cart"
point = [0.0, 0.0, 0.0]
bonded = false
normal = { direction = [0.0, 0.0, 1.0], model = "c", k = 1e4, b = 10.0, law = "hunt_crossley", exponent = 1.5 }
tangent = { model = "friction", directions = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], mu_s = 0.5, mu_k = 0.4, viscous = 0.1 }
[contact.side]
point = [0.0, 0.0, 0.0]
normal = { direction = [1.0, 0.0, 0.0], model = "b", k = 1e4, b = 10.0, m = 1.0, law = "hunt_crossley" }
tangent = { model = "friction", directions = [[0.0, 0.0, 1.0]], mu = 0.3 }
[solver]
method = "DOP853"
rtol = 1e-8
atol = 1e-10
max_step = 0.01
output_rate = 1000.0
record_energy = false
max_events = 10000
steps_per_second = 20000.0
storm_window = 1e-9
storm_count = 50
stabilization = 20.0
stick_velocity = 1e-9
[controller]
kind = "task_pd"
[[phase]]
name = "approach"
until = "touch:tip"
[phase.reference]
space = "task"
body = "cart"
start = [0.4, 0.0, 0.1]
moves = [{ kind = "trapezoid", delta = [0.0, 0.0, -0.1], start = 0.0, duration = 0.5, accel_fraction = 0.2 },
         { kind = "velocity_ramp", velocity = [0.1, 0.0, 0.0], duration = 0.5 },
         { kind = "circle", center = [0.4, 0.0, 0.0], normal = [0.0, 0.0, 1.0], turns = 1.0, duration = 0.5 }]
[[phase]]
name = "press"
until = 1.0
[[phase.force]]
contact = "tip"
direction = "n"
value = 10.0
initial = 0.0
start = 0.0
duration = 0.1
kind = "linear"
'''

_NORMALS = '''
[body.cart]
mass = 1.0
drive = { kind = "dc_motor", R = 1.0, C_M = 0.1, J = 1e-4, N = 10.0, N_star = 8.0 }
[contact.a]
point = [0.0, 0.0, 0.0]
normal = { direction = [0.0, 0.0, 1.0], model = "a", k_int = 1e5, m = 1.0, k_ext = 1e4, law = "hunt_crossley" }
[contact.a2]
point = [0.0, 0.0, 0.0]
normal = { direction = [0.0, 0.0, 1.0], model = "a", k_int = 1e5, b_int = 10.0, m = 1.0, k_ext = 1e4, b_ext = 1.0 }
[contact.r]
point = [0.0, 0.0, 0.0]
normal = { direction = [0.0, 0.0, 1.0], model = "rigid" }
[contact.ch]
point = [0.0, 0.0, 0.0]
normal.direction = [0.0, 0.0, 1.0]
normal.model = "chain"
normal.environment = [{ k = 1e5, b = 1.0, law = "hunt_crossley", exponent = 2.0 }, { m = 1.0 }]
normal.robot = [{ k = 1e4, b = 0.0, law = "hunt_crossley", exponent = 1.5 }, { m = 0.1 }]
tangent.model = "chain"
tangent.directions = [[1.0, 0.0, 0.0]]
tangent.environment = [{ k = 1e4, law = "hunt_crossley" }, { m = 1.0 }]
tangent.robot = [{ k = 1e4, b = 1.0, law = "hunt_crossley" }, { m = 0.1 }]
[contact.fr]
point = [0.0, 0.0, 0.0]
normal = { direction = [0.0, 0.0, 1.0] }
tangent = { model = "free" }
'''

_PD = '''
[[phase]]
[phase.controller]
kind = "task_pd"
kp = 2000.0
kd = 100.0
axes = [[1.0, 0.0, 0.0]]
feedforward = "gravity"
tool_axis = [0.0, 0.0, 1.0]
tool_target = [0.0, 0.0, -1.0]
ko = 50.0
do = 2.0
kd_joint = 0.1
[[phase]]
[phase.controller]
kind = "task_pd"
orientation = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]
[[phase]]
controller = { kind = "joint_pd", kp = 100.0, kd = 10.0, feedforward = "none" }
reference.space = "joint"
reference.start = [0.1, 0.2]
reference.moves = [{ kind = "triangle", delta = [0.1, 0.0], duration = 0.5 },
                   { kind = "constant_velocity", delta = [0.1, 0.0], duration = 0.5 },
                   { kind = "step", delta = [0.1, 0.0], duration = 0.5 },
                   { kind = "exponential", delta = [0.1, 0.0], duration = 0.5 }]
[[phase]]
controller = { kind = "voltage", u = 1.0 }
[[phase]]
[phase.controller]
kind = "task_pd"
sample_rate = 1000.0
delay = 1
sensor = { force_noise = 0.1, force_bias = 0.0, force_cutoff = 200.0, encoder_resolution = 1e-5, seed = 7 }
[[phase]]
[phase.controller]
kind = "task_force"
force = [0.0, 0.0, 1.0]
rate = [0.0, 0.0, 0.0]
start = 0.0
ramp_time = 1.0
amplitude = [0.0, 0.0, 0.0]
frequency = 0.0
phase = [0.0, 0.0, 0.0]
feedforward = "bias"
'''

_DYNAMIC = '''
[contact.tip]
point = [0.0, 0.0, 0.0]
normal = { direction = [0.0, 0.0, 1.0], model = "c", k = 1e4, b = 10.0 }
[[phase]]
[phase.controller]
kind = "position_dynamic"
space = "task"
kp = 400.0
kv = 40.0
k_null = 10.0
force_reference = false
nominal = { k = 1e4, b = 10.0, m = 0.0 }
[[phase]]
controller = { kind = "force_dynamic", kv = 40.0, kf = 20.0, k_null = 10.0, nominal = { k = 1e4, b = 10.0, m = 1.0 } }
force = [{ contact = "tip", value = 10.0 }]
[[phase]]
force = [{ contact = "tip", value = 10.0 }]
[phase.controller]
kind = "hybrid"
kp = 400.0
kv = 40.0
kf = 20.0
k_null = 10.0
axes = [[1.0, 0.0, 0.0]]
nominal = { k = 1e4, b = 10.0, m = 1.0 }
[[phase]]
force = [{ contact = "tip", value = 10.0 }]
[phase.controller]
kind = "operational_space"
kp = 800.0
kd = 40.0
axes = [[1.0, 0.0, 0.0]]
tool_axis = [0.0, 0.0, 1.0]
tool_target = [0.0, 0.0, -1.0]
ko = 400.0
do = 40.0
k_null = 10.0
kd_normal = 1000.0
'''

_TORQUE = '''
[robot.drive]
kind = ["torque", "elastic"]
R = [1.0, 1.0]
C_M = 0.1
J = 1e-4
c = 1e3
'''

#: the documents, in TOML; every one is a valid scene
TOUR: tuple[str, ...] = (_FULL, _ROBOT + _NORMALS, _ROBOT + _PD, _ROBOT + _DYNAMIC,
                         _ROBOT.replace('tip = "tip"', 'tip = "tip"' + _TORQUE))


def _laws_document() -> str:
    """A chain with one stage per registered stage law, a contact per friction law, a phase per controller that
    declares its parameters and a body per drive kind, each with the declared parameters' example values
    (:mod:`contactdyn.laws.params`): a law added later, a user's included, is toured without an edit here."""
    from ..laws.controllers import CONTROLLERS
    from ..laws.drive_kinds import DRIVE_KINDS
    from ..laws.friction_laws import FRICTION_LAWS
    from ..laws.stage_laws import STAGE_LAWS

    def own(law) -> str:
        return "".join(f", {p.name} = {p.sample()!r}" for p in law.params)

    stages = ", ".join(f'{{ k = 1e4, b = 1.0, law = "{name}"{own(law)} }}, {{ m = 1.0 }}'
                       for name, law in STAGE_LAWS.items())
    doc = _ROBOT + f'''
[contact.laws]
point = [0.0, 0.0, 0.0]
normal.direction = [0.0, 0.0, 1.0]
normal.model = "chain"
normal.environment = [{stages}]
'''
    declared = [(name, cls) for name, cls in CONTROLLERS.items() if cls.params]
    for i, (name, cls) in enumerate(declared):
        until = f"until = {i + 1}.0\n" if i + 1 < len(declared) else ""
        doc += f'''
[[phase]]
name = "{name}"
{until}controller = {{ kind = "{name}"{own(cls)} }}
'''
    for name, law in FRICTION_LAWS.items():
        doc += f'''
[contact.{name}]
point = [0.0, 0.0, 0.0]
normal.direction = [0.0, 0.0, 1.0]
tangent = {{ model = "friction", directions = [[1.0, 0.0, 0.0]], law = "{name}", mu_s = 0.5, mu_k = 0.4{own(law)} }}
'''
    for name, kind in DRIVE_KINDS.items():
        doc += f'''
[body.drive_{name}]
mass = 1.0
drive = {{ kind = "{name}"{own(kind)} }}
'''
    return doc


def _drive_documents() -> tuple[str, ...]:
    """A robot driven by each registered drive kind, its declared parameters at their example values."""
    from ..laws.drive_kinds import DRIVE_KINDS

    return tuple(_ROBOT + f'[robot.drive]\nkind = "{name}"\n' + "".join(f"{p.name} = {p.sample()!r}\n"
                                                                       for p in kind.params)
                 for name, kind in DRIVE_KINDS.items())


def tour() -> tuple[str, ...]:
    """Every document of the tour: :data:`TOUR` and those written from the registries' declarations."""
    return (*TOUR, _laws_document(), *_drive_documents())
