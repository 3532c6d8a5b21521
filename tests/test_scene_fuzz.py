"""Fuzzing the scene loader: any document either validates or raises SceneError, never anything else.

Documents are mutations of sims/b1.toml: keys deleted, unknown keys inserted, values
replaced by wrong types, NaN, ±inf, negatives, zero, empty containers. A few hundred
examples per property; parse_scene does not load the robot, so each costs ~1 ms.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import tomllib

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from contactdyn.errors import SceneError
from contactdyn.laws.friction_laws import FRICTION_LAWS
from contactdyn.laws.stage_laws import STAGE_LAWS
from contactdyn.scene.scene_file import parse_scene, sims_dir

BASE = tomllib.loads((sims_dir() / "b1.toml").read_text())
FILE = str(sims_dir() / "b1.toml")

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6), st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([math.nan, math.inf, -math.inf, -1.0, 0.0, -1e-300, 1e300, "", "rigid", "touch:tip", "x"]),
    st.text(max_size=6),
)
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=5), inner, max_size=3)),
                      max_leaves=6)


#: optional keys b1.toml does not use, so that insertions reach their validation too
KNOWN_KEYS = ["drive", "active_joints", "locked", "tip0", "q_seed", "gravity_compensation", "body", "bonded",
              "max_step", "record_energy", "max_events", "storm_window", "storm_count", "law",
              "environment", "robot", "k_int", "b_int", "k_ext", "b_ext", "mu_s", "mu_k", "viscous", "until",
              "space", "start", "accel_fraction", "velocity", "initial", "feedforward", "servo", "axis", "mass",
              "frame_point", "surface_frame", "urdf", "position0", "velocity0",
              *(p.name for laws in (STAGE_LAWS, FRICTION_LAWS) for law in laws.values() for p in law.params)]
#: (the last line: the registered laws' declared parameters)


def _paths(node, prefix=()):
    """Every (path to a container, key) in the document, tables and arrays alike."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for k, v in items:
        yield prefix, k
        yield from _paths(v, (*prefix, k))


def _get(doc, path):
    for p in path:
        doc = doc[p]
    return doc


@st.composite
def mutated(draw, base=BASE):
    doc = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 4))):
        spots = list(_paths(doc))
        if not spots:
            break
        path, key = draw(st.sampled_from(spots))
        parent = _get(doc, path)
        action = draw(st.sampled_from(["delete", "replace", "replace", "insert", "number"]))
        if action == "delete":
            del parent[key]
        elif action == "replace":
            parent[key] = draw(values)
        elif action == "number":
            parent[key] = draw(st.sampled_from([math.nan, math.inf, -math.inf, -1.0, 0.0, -1e9, 1e30, 3, True]))
        elif isinstance(parent, dict):
            parent[draw(st.one_of(st.sampled_from(KNOWN_KEYS), st.text(min_size=1, max_size=8)))] = draw(values)
        else:
            parent.append(draw(values))
    return doc


def _parse_or_scene_error(doc) -> None:
    try:
        parse_scene(doc, file=FILE)
    except SceneError as exc:
        assert exc.file == FILE and exc.key, f"SceneError without file or key path: {exc}"


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mutated())
def test_mutated_documents_validate_or_raise_scene_error(doc):
    _parse_or_scene_error(doc)


@settings(max_examples=150, deadline=None)
@given(st.dictionaries(st.sampled_from(["duration", "solver.rtol", "solver.output_rate", "contact.tip.normal.k",
                                        "contact.tip.tangent.mu", "controller.kp", "controller.axes",
                                        "robot.q0", "phase.0.until", "phase.0.force.0.value", "name"]),
                       values, min_size=1, max_size=3))
def test_overrides_validate_or_raise_scene_error(overrides):
    try:
        parse_scene(BASE, overrides, file=FILE)
    except SceneError as exc:
        assert exc.file == FILE and exc.key


@pytest.mark.parametrize("doc", [{}, {"duration": 1.0}, {"robot": []}, {"contact": 1}, {"phase": {"a": 1}}])
def test_skeleton_documents(doc):
    with pytest.raises(SceneError):
        parse_scene(doc, file=FILE)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(mutated())
def test_valid_mutants_build_a_system_or_raise_the_packages_errors(doc):
    """What parse_scene accepts, System must build or reject with SceneError/RobotError (URDF-level checks)."""
    from contactdyn.errors import RobotError
    from contactdyn.model.system import System

    try:
        scene = parse_scene(doc, file=FILE)
    except SceneError:
        return
    try:
        System(scene)
    except (SceneError, RobotError):
        pass


#: scenes with objects: bodies from URDFs beside them (several coordinates), a body's point touching, a surface
#: carried by the robot
OBJECTS = {name: (tomllib.loads((sims_dir() / f"{name}.toml").read_text()), str(sims_dir() / f"{name}.toml"))
           for name in ("push_box", "tilt_tray")}


@pytest.mark.parametrize("name", sorted(OBJECTS))
def test_mutated_object_scenes_validate_build_or_raise_the_packages_errors(name):
    """The object scenes mutated as b1 is: parse_scene validates or raises SceneError, and what it accepts System
    builds or rejects with SceneError/RobotError."""
    from contactdyn.errors import RobotError
    from contactdyn.model.system import System

    base, file = OBJECTS[name]

    @settings(max_examples=120, deadline=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
    @given(mutated(base))
    def check(doc):
        try:
            scene = parse_scene(doc, file=file)
        except SceneError as exc:
            assert exc.file == file and exc.key, f"SceneError without file or key path: {exc}"
            return
        try:
            System(scene)
        except (SceneError, RobotError):
            pass

    check()


@pytest.mark.parametrize("overrides", [{5: 1.0}, [("duration", 1.0)], "duration=1.0"])
def test_overrides_that_are_no_dict_of_key_paths_raise_scene_error(overrides):
    """The Python API's overrides: a dict keyed by key paths (a key 5 was a TypeError from inside ``re``)."""
    with pytest.raises(SceneError, match="<overrides>: expected"):
        parse_scene(BASE, overrides, file=FILE)


@pytest.mark.parametrize("key, value", [("controller.kp", np.float32(500.0)), ("controller.kp", np.int64(500)),
                                        ("robot.q0", np.array([0.5, -1.25], dtype=np.float32)),
                                        ("robot.drive", {"kind": "dc_motor", "R": np.array([1.0, 2.0]), "C_M": 0.5,
                                                         "J": np.float32(0.25)})])
def test_numpy_numbers_read_as_the_numbers_they_are(key, value):
    """A NumPy number from a user's script is a number (it was 'expected a number, found np.float32(500.0)'), and
    reads as the same float as Python's."""
    plain = {k: v.tolist() if hasattr(v, "tolist") else v for k, v in value.items()} if isinstance(value, dict) \
        else value.tolist()
    def read(v):  # (the scene as read: its raw document keeps what was given)
        return repr(dataclasses.replace(parse_scene(BASE, {key: v}, file=FILE), document={}))

    assert read(value) == read(plain)
