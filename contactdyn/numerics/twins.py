"""The one pipeline run interpreted: its own functions as Python twins, a few small leaves compiled.

Why. Compiling the pipeline (:mod:`contactdyn.model.pipeline`) takes a fresh install tens of seconds; a scene
kind's first run (:mod:`contactdyn.first_run`) cannot wait for it. It runs the same functions interpreted instead,
in this process where numba is on, while the compiled code is built in the background: one source of the physics.

How. A numba function keeps its Python source as ``py_func``; its globals are its module's namespace, where the
functions it calls are numba dispatchers (called from Python, a dispatcher compiles). :class:`Twins` makes the
*twin* of a function of the package: the same code object with its globals rebound to a *shadow* of its module's
namespace, a copy in which every function of the package is again its twin (and every module of the package its
shadow). So ``Twins().of(call)(...)`` runs ``call`` and everything it reaches as plain Python, nothing compiled,
the real modules untouched (the compiled path in the same process is unaffected). Two exceptions:

- the **leaves** (:data:`LEAVES`: the rigid-body algorithms of :mod:`contactdyn.robot.rigid_body`, the dense
  linear algebra of :mod:`.linalg`, DOP853's stage sums and error norm of :mod:`contactdyn.hybrid.steps` and its
  interpolants' polynomials of :mod:`.dense_output`, most of an interpreted call's time, self-contained and the same
  for every scene) stay numba dispatchers: compiled once per install (seconds, cached), called from the twins (the
  polynomials from the dense output's Python, through :func:`current`);
- the **handle tables**: interpreted, a stage reached by address (:mod:`.native_call`, the laws' ABIs, the
  controllers) is a *handle* (the Python function's id, given by the address functions while
  :func:`.native_call.giving_handles` is on: the mode is packed that way), looked up in a table; in the shadows
  those tables are seen through :class:`_TwinMap`, so a handle gives the twin.

The arithmetic is the compiled call's, operation for operation (no fastmath: numba keeps the float operations and
their order): a run on the twins gives the compiled run's outputs bit for bit (``tests/test_interpreted_run.py``,
``benchmarks/compare_outputs.py --interpreted``).
Where it is used: :class:`contactdyn.model.pipeline.pipeline.Pipeline` (``twins=``: the mode packed with handles,
its call and the loop's compiled steps and samples run as twins, :meth:`~.pipeline.Pipeline.of`).

A **late leaf** (:data:`LATE_LEAVES`: a law's arithmetic, the robot's terms: seconds to compile) runs as
its twin, unless the run has somewhere it *arrives* from (:func:`late_leaves`: a first run's helper compiles it on
the other core while the run runs, :mod:`contactdyn.first_run`): then the run looks every :data:`LOOK` seconds
whether it has arrived and from then on calls it compiled (the same arithmetic: the same outputs bit for bit).

Outside the pipeline, the loop's Python calls a few numba functions of the model (a transition's velocity
projection calls the chains' ``chain_call``): such a call site asks :func:`current` for the function, its
twin while an interpreted run runs (:func:`running`, around ``HybridRun.run``), so a first run compiles none of it.

Not twinned (run as they are, so they compile if they are numba functions): methods of classes, a function held in
a closure cell, a default argument or a container other than the handle tables below; the tests check that an
interpreted run compiles nothing but the leaves and a law's own compiled form where it is bound.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
import types
from collections.abc import Mapping

from numba import typeof
from numba.core.dispatcher import Dispatcher

__all__ = ["Twins", "RecordingTwins", "LEAVES", "LATE_LEAVES", "name_of", "late_leaves", "run_as", "current",
           "running"]

PACKAGE = "contactdyn."
#: the functions left compiled (numba dispatchers called from the twins): the rigid-body algorithms, the dense
#: linear algebra (numerics.linalg), DOP853's stage sums and error norm (hybrid.steps: each loops over the state
#: and the stages, per step) and its interpolants' polynomials (numerics.dense_output, called through current())
LEAVES = frozenset([*(f"contactdyn.robot.rigid_body.{n}" for n in
                      ("_kinematics", "_nonlinear", "_jacobians", "_inertia", "frame_motion_into")),
                    *(f"contactdyn.numerics.linalg.{n}" for n in
                      ("mv", "mtv", "mm", "mtm", "lu_solve", "residual_ok", "cholesky", "forward_solve", "pinv",
                       "put")),
                    *(f"contactdyn.hybrid.steps.{n}" for n in ("_stage_state", "_step_end", "_error_norm")),
                    *(f"contactdyn.numerics.dense_output.{n}" for n in ("horner_at", "horner_rows"))])
#: the late leaves, twins until they arrive compiled (late_leaves), recorded as leaves (RecordingTwins), in the order a
#: helper compiles those a scene reaches (the most worth first): the operational law's arithmetic (a quarter of the
#: 5-DOF writer's call, 5 s to compile), then the robot's terms, its frames' and a bond's row (~8 % of the real
#: cell's call, 4 s); not kkt_solve (its least squares: numba's LAPACK, not numpy's, and 9 s)
LATE_LEAVES = ("contactdyn.laws.controllers.operational_law.torque",
               *(f"contactdyn.model.pipeline.robot_terms.{n}" for n in ("robot_terms", "frame_terms")),
               "contactdyn.model.pipeline.contacts._bond_row")
LOOK = 0.2  #: [s] of wall time between a late leaf's looks for its compiled form
#: module -> its tables handle -> Python function (or controller class) that must give twins
HANDLE_TABLES = {
    "contactdyn.numerics.native_call": ("_HANDLES",),
    "contactdyn.model.pipeline.control_laws": ("PYTHON_KINDS",),
    "contactdyn.model.pipeline.actuation": ("PYTHON_KINDS",),
    "contactdyn.laws.abi": ("_python",),
}


class _TwinMap(Mapping):
    """A handle table seen through the twins: ``table[h]`` is the twin of what the table holds (writes go through)."""

    def __init__(self, table: dict, twins: Twins) -> None:
        self._table, self._twins = table, twins

    def __getitem__(self, key):
        return self._twins.of(self._table[key])

    def get(self, key, default=None):
        return self._twins.of(self._table[key]) if key in self._table else default

    def __setitem__(self, key, value) -> None:  # (an address function's twin registering a handle)
        self._table[key] = value

    def __contains__(self, key) -> bool:
        return key in self._table

    def __iter__(self):
        return iter(self._table)

    def __len__(self) -> int:
        return len(self._table)


def name_of(function) -> str:
    """A function's (or numba dispatcher's) qualified name: ``module.qualname``."""
    python = getattr(function, "py_func", function)
    return f"{python.__module__}.{python.__qualname__}"


class _Late:
    """A late leaf in a run it may arrive in: its twin until ``arrived(leaf, types)`` says it was compiled (and
    cached), then the leaf itself, loaded (looked at every :data:`LOOK` s, the first time at its first call)."""

    def __init__(self, leaf: Dispatcher, twin, arrived) -> None:
        self.leaf, self.call, self.arrived = leaf, twin, arrived
        self.look = time.monotonic()  #: [s] its next look (0: no more: it arrived, or cannot)

    def __call__(self, *args):
        if self.look and time.monotonic() >= self.look:
            self._look(args)
        return self.call(*args)

    def _look(self, args) -> None:
        types_ = tuple(typeof(a) for a in args)
        if not self.arrived(self.leaf, types_):
            self.look = time.monotonic() + LOOK
            return
        self.look = 0.0
        try:
            self.leaf.compile(types_)  # (loaded from the cache its helper filled)
        except Exception:  # noqa: BLE001 (it stays interpreted: the same results)
            return
        self.call = self.leaf


class Twins:
    """The package's functions as interpreted twins, :data:`LEAVES` (or ``leaves``) compiled, :data:`LATE_LEAVES`
    compiled once arrived where the run has somewhere they arrive from (:func:`late_leaves`; see the module)."""

    def __init__(self, leaves=LEAVES) -> None:
        self.leaves = frozenset(leaves)
        self.arrived = _ARRIVALS[-1] if _ARRIVALS else None  #: (leaf, types) -> compiled elsewhere? (None: never)
        self.shadows: dict[str, dict] = {}  #: module name -> its shadow namespace
        self.made: dict[int, object] = {}  #: id(function) -> its twin (the functions kept alive in ``keep``)
        self.keep: list = []

    def of(self, value):
        """The twin of a function of the package (a numba dispatcher or a plain function); anything else itself."""
        got = self.made.get(id(value))
        if got is not None:
            return got
        if isinstance(value, types.ModuleType):  # (``module.function(...)``: the module's shadow)
            return self._module(value)
        python = value.py_func if isinstance(value, Dispatcher) else value
        if not isinstance(python, types.FunctionType):
            return value
        module = python.__module__ or ""
        if not module.startswith(PACKAGE) or module not in sys.modules:
            return value
        name = f"{module}.{python.__qualname__}" if isinstance(value, Dispatcher) else ""
        if name in self.leaves:
            twin = self._leaf(value)
        elif name in LATE_LEAVES:
            twin = self._late(value)
        elif python.__globals__ is not sys.modules[module].__dict__:  # (generated code: exec'd wrappers) as it is
            twin = python
        else:
            twin = self._interpreted(python)
        self.made[id(value)] = twin
        self.keep.append(value)  # (its id stays its own)
        return twin

    def _leaf(self, leaf: Dispatcher):
        """What a leaf's callers call: the leaf itself, compiled."""
        return leaf

    def _late(self, leaf: Dispatcher):
        """What a late leaf's callers call: its twin, compiled once it arrives (where it can)."""
        twin = self._interpreted(leaf.py_func)
        return twin if self.arrived is None else _Late(leaf, twin, self.arrived)

    def _interpreted(self, python: types.FunctionType) -> types.FunctionType:
        """``python``'s code over its module's shadow: its twin."""
        twin = types.FunctionType(python.__code__, self._shadow(python.__module__), python.__name__,
                                  python.__defaults__, python.__closure__)
        twin.__kwdefaults__, twin.__qualname__ = python.__kwdefaults__, python.__qualname__
        return twin

    def _module(self, module: types.ModuleType):
        """A module of the package as its shadow (a module object whose namespace is the shadow); others as they are."""
        name = module.__name__
        if not name.startswith(PACKAGE) or sys.modules.get(name) is not module:
            return module
        twin = types.ModuleType(name)
        self.made[id(module)] = twin
        self.keep.append(module)
        twin.__dict__.update(self._shadow(name))
        return twin

    def _shadow(self, module: str) -> dict:
        """The shadow of ``module``'s namespace: its functions' twins, its handle tables through :class:`_TwinMap`."""
        shadow = self.shadows.get(module)
        if shadow is None:
            original = sys.modules[module].__dict__
            shadow = self.shadows[module] = dict(original)  # (registered first: the twins made below hold it)
            for name, value in original.items():
                shadow[name] = self.of(value)
            for name in HANDLE_TABLES.get(module, ()):
                shadow[name] = _TwinMap(original[name], self)
        return shadow


class RecordingTwins(Twins):
    """The twins with the leaves interpreted too, each leaf's calls recorded (a late leaf's too): ``calls``, (the leaf,
    its argument types) in the order a run first reaches them, what the same run on :class:`Twins` compiles (no leaf
    compiled here). A first run's helper compiles them last-reached first, beside the run (:mod:`contactdyn.first_run`).
    ``deadline`` [s] (``time.monotonic``): a leaf called after it raises :class:`Enough` (the record so far kept)."""

    class Enough(Exception):
        """The recording ran past its deadline."""

    def __init__(self, deadline: float = math.inf) -> None:
        super().__init__()
        self.deadline = deadline
        self.calls: list[tuple[Dispatcher, tuple]] = []
        self.seen: dict[int, set[tuple]] = {}  #: id(leaf) -> the argument types recorded (one set per leaf)

    def _leaf(self, leaf: Dispatcher):
        """The leaf's Python twin, recording each new list of argument types the leaf is called with."""
        twin = self._interpreted(leaf.py_func)
        seen = self.seen.setdefault(id(leaf), set())  # (shared: a module's shadow may wrap its leaf twice)

        def recorded(*args):
            if time.monotonic() > self.deadline:
                raise RecordingTwins.Enough
            types_ = tuple(typeof(a) for a in args)  # (numba's types of the arguments, as its dispatch types them)
            if types_ not in seen:
                seen.add(types_)
                self.calls.append((leaf, types_))
            return twin(*args)

        return recorded

    _late = _leaf  # (a late leaf recorded as a leaf: the helper compiles it after them)


_ARRIVALS: list = []  #: where the late leaves of the twins made meanwhile arrive from (innermost last)


@contextlib.contextmanager
def late_leaves(arrived):
    """Twins made meanwhile run a late leaf compiled once ``arrived(leaf, types)`` (numba's argument types) is True:
    it was compiled and cached by another process (a first run's helper)."""
    _ARRIVALS.append(arrived)
    try:
        yield
    finally:
        _ARRIVALS.pop()


_RUNNING: list[Twins] = []  #: the twins of the interpreted run in progress (innermost last)


def run_as(twins: Twins | None, function):
    """``function`` (of the package) as a pipeline with ``twins`` runs it: itself (None: compiled), or its twin."""
    return function if twins is None else twins.of(function)


def current(function):
    """``function`` (of the package, called from Python outside the pipeline) as the run in progress runs it: its
    twin during an interpreted run (:func:`running`), else itself."""
    return run_as(_RUNNING[-1] if _RUNNING else None, function)


@contextlib.contextmanager
def running(twins: Twins | None):
    """An interpreted run with ``twins`` runs meanwhile (None: a compiled one, nothing changes)."""
    if twins is None:
        yield
        return
    _RUNNING.append(twins)
    try:
        yield
    finally:
        _RUNNING.pop()
