"""A controller's calling convention (its ABI): the compiled model calls a controller's ``command`` by address.

A user writes ``command(self, inp)`` with attribute access on ``inp`` (a :class:`~.base.ControlInput`) and on
``self.config``. numba compiles that same function with ``inp`` a :class:`ControlArrays` (a named tuple of arrays
and floats with ControlInput's field names) and ``self`` a named tuple whose ``config`` is a named tuple of the
controller's declared parameters (``Controller.params``, in order): attribute access compiles unchanged. The C
function of a controller, its address a plain int64 (:func:`controller_address`):

    ``int64 command(double* buffer, int64* layout, double* params, int64 n_p, double* tau, double* zdot)``

- ``buffer``: the inputs, one field after another, each where ``layout`` says;
- ``layout``: [nv, nz, ns, start_0, stop_0, start_1, stop_1, …, size of the buffer] per field of :data:`LAYOUT`
  (:func:`layout_of`; nz states, ns force set-points); a field an input does not have (no reference, no gravity
  asked, no orientation read, no measured forces for a law that does not read them) is empty (start = stop), as
  ControlInput's None: a law that reads it fails there (bounds-checked) and the call goes Python's way
  (``inp.x_d is None`` is never true compiled: test ``inp.x_d.size`` in a law meant to compile);
- ``params``: the declared parameters' values in their order (``DeclaredConfig.values``);
- ``tau``: the joint torques [N·m or N] (nv; voltages [V] for a law with ``outputs = "voltage"``), written;
  ``zdot``: the states' rates (nz), written (a law without states returns None for them); the status returned:
  1 written, 0 not (the law raised, read past a field, which the bounds checks catch, or gave the wrong number of
  torques or rates; or ``n_p`` is not the number of declared parameters): the call then goes Python's way, where
  the law's own error surfaces.

Units are ControlInput's: t [s], q [rad or m], v [rad/s or m/s], H [kg·m² …], h and gravity [N·m or N], p_tip [m],
v_tip [m/s], J and J_ang (3, nv), drift [m/s²], drift_ang [rad/s²], x_d/v_d/a_d [m, m/s, m/s²] (a joint-space
reference's: nv each [rad or m, /s, /s²]), R_tip (3, 3), z the controller's states, tau_contact [N·m or N]; per
force set-point, in the phase's order
(``ControlInput.SET_POINT_ARRAYS``): force_set F_d [N], force_rate Ḟ_d [N/s], force_dir (ns, 3), force_read the
measured force of the set-point's key [N], surface_p [m] and surface_v [m/s] (ns, 3), touch (1.0 touching).
ControlInput's dictionaries (forces, force_d, normals, surfaces, touching) are not in the buffer: a law meant to
compile reads the arrays, which the readable ControlInput has too (its properties). A law that reads measured
forces (``uses_forces``) is affine in them: the caller folds it by calling it again at unit forces
(:mod:`contactdyn.model.pipeline.force_fold`).

What is not compiled (address 0, the reason in ``cls.compiled_reason``): a controller that has no declared
parameters' config, or whose ``command`` numba cannot compile (a dict, a Python object, ``inp.forces``). The
compiled call runs it as a declared Python stage (:func:`python_controller_address`): a ctypes callback of this
signature rebuilds a ControlInput from the buffer (:func:`control_input`: the
dictionaries by key from the "keys" field and :class:`InputKeys`), calls the controller's own ``command`` (its real
``self``) and writes τ and ż; its exception is kept and re-raised after the call. A controller that outputs
voltages (``outputs = "voltage"``) compiles as one of torques: ``tau`` then holds the joints' voltages [V], which the
drives take as they are.

Caching: the wrapper is generated closure-free and attributed to the controller's own file, as the stage laws'
(:func:`contactdyn.laws.abi.compile_wrapper`), so numba caches it (compile_cache's directory; an edit of that
file recompiles it).
"""

from __future__ import annotations

import ctypes
import functools
from collections import namedtuple
from dataclasses import dataclass, field, fields

import numpy as np
from numba import carray, types
from numba.extending import intrinsic, overload

from ...errors import SimulationError
from ...numerics.compile_cache import njit
from ...numerics.native_call import handles
from ..abi import _data_at, _indirect_call, compile_wrapper, python_stage_failed
from .base import ControlInput, Controller

__all__ = ["CONTROLLER_SIGNATURE", "LAYOUT", "LAYOUT_SIZE", "NOT_IN_LAYOUT", "ControlArrays", "control_arrays",
           "layout_of", "put_field", "controller_address", "params_of", "buffer_of", "call_controller", "InputKeys",
           "control_input", "python_controller_address", "PYTHON_STAGE_FIELDS", "KEY_W", "command_arrays"]

_P = types.CPointer(types.float64)
#: int64 command(double* buffer, int64* layout, double* params, int64 n_p, double* tau, double* zdot)
CONTROLLER_SIGNATURE = types.int64(_P, types.CPointer(types.int64), _P, types.int64, _P, _P)

#: the buffer's fields in order: name -> (size as a function of (nv, nz, ns, nr, nk), columns: 0 a float, 1 a vector,
#: else a matrix of that many columns as a function of nv). nz the controller's states, ns the phase's force
#: set-points, nr the reference's coordinates (3: a task reference [m]; nv: a joint one [rad or m]), nk the keys of
#: ControlInput's dictionaries (a declared Python stage's only: :data:`PYTHON_STAGE_FIELDS`).
#: A new input is one line here and one in control_arrays.
LAYOUT = (
    ("t", lambda nv, nz, ns, nr, nk: 1, 0),
    ("q", lambda nv, nz, ns, nr, nk: nv, 1),
    ("v", lambda nv, nz, ns, nr, nk: nv, 1),
    ("H", lambda nv, nz, ns, nr, nk: nv * nv, lambda nv: nv),
    ("h", lambda nv, nz, ns, nr, nk: nv, 1),
    ("gravity", lambda nv, nz, ns, nr, nk: nv, 1),
    ("p_tip", lambda nv, nz, ns, nr, nk: 3, 1),
    ("v_tip", lambda nv, nz, ns, nr, nk: 3, 1),
    ("J", lambda nv, nz, ns, nr, nk: 3 * nv, lambda nv: nv),
    ("drift", lambda nv, nz, ns, nr, nk: 3, 1),
    ("x_d", lambda nv, nz, ns, nr, nk: nr, 1),
    ("v_d", lambda nv, nz, ns, nr, nk: nr, 1),
    ("a_d", lambda nv, nz, ns, nr, nk: nr, 1),
    ("z", lambda nv, nz, ns, nr, nk: nz, 1),
    ("R_tip", lambda nv, nz, ns, nr, nk: 9, lambda nv: 3),
    ("J_ang", lambda nv, nz, ns, nr, nk: 3 * nv, lambda nv: nv),
    ("drift_ang", lambda nv, nz, ns, nr, nk: 3, 1),
    ("tau_contact", lambda nv, nz, ns, nr, nk: nv, 1),
    ("force_set", lambda nv, nz, ns, nr, nk: ns, 1),
    ("force_rate", lambda nv, nz, ns, nr, nk: ns, 1),
    ("force_dir", lambda nv, nz, ns, nr, nk: 3 * ns, lambda nv: 3),
    ("force_read", lambda nv, nz, ns, nr, nk: ns, 1),
    ("surface_p", lambda nv, nz, ns, nr, nk: 3 * ns, lambda nv: 3),
    ("surface_v", lambda nv, nz, ns, nr, nk: 3 * ns, lambda nv: 3),
    ("touch", lambda nv, nz, ns, nr, nk: ns, 1),
    ("keys", lambda nv, nz, ns, nr, nk: KEY_W * nk, lambda nv: KEY_W),
)
#: per key of the ControlInput's dictionaries (per contact, then its tangential chains: evaluation.surface_keys)
#: in the "keys" field: the measured force [N], touching (1.0), the surface point [m] (3) and its velocity [m/s] (3)
KEY_FORCE, KEY_TOUCH, KEY_P, KEY_V, KEY_W = 0, 1, 2, 5, 8
FIELD = {name: k for k, (name, _, _) in enumerate(LAYOUT)}  #: a field's index in LAYOUT
LAYOUT_HEAD = 3  #: the layout table's header: nv, nz, ns; then (start, stop) per field, then the buffer's size
LAYOUT_SIZE = LAYOUT_HEAD + 2 * len(LAYOUT) + 1  #: the layout table's length (layout_of)
#: ControlInput's fields a compiled controller does not read (its dictionaries: their arrays by set-point are
#: ControlInput.SET_POINT_ARRAYS)
NOT_IN_LAYOUT = ("forces", "force_d", "normals", "surfaces", "touching")
#: the fields only a declared Python stage reads (python_controller_address: it rebuilds the dictionaries from them);
#: not in ControlArrays (a compiled law's inputs), empty in the layout of a compiled law
PYTHON_STAGE_FIELDS = ("keys",)

ControlArrays = namedtuple("ControlArrays", [*(f.name for f in fields(ControlInput) if f.name not in NOT_IN_LAYOUT),
                                             *ControlInput.SET_POINT_ARRAYS])


def layout_of(nv: int, nz: int, absent: tuple[str, ...] = (), ns: int = 0, nr: int = 3, nk: int = 0) -> np.ndarray:
    """The layout table [nv, nz, ns, (start, stop) per field, size of the buffer] for nv joints, nz states, ns
    force set-points, a reference of nr coordinates and nk dictionary keys; the fields in ``absent`` empty."""
    out, at = [nv, nz, ns], 0
    for name, size, _ in LAYOUT:
        n = 0 if name in absent else size(nv, nz, ns, nr, nk)
        out += [at, at + n]
        at += n
    return np.array([*out, at], dtype=np.int64)


def buffer_of(inp: ControlInput, nz: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(buffer, layout) of a readable ControlInput (its None fields absent): the compiled call's inputs, in Python."""
    nv = len(inp.q)
    absent = tuple(name for name, _, _ in LAYOUT if getattr(inp, name, None) is None)
    layout = layout_of(nv, nz, absent, len(inp.force_d), len(inp.x_d) if inp.x_d is not None else 3)
    buffer = np.empty(layout[-1])
    for k, (name, _, _) in enumerate(LAYOUT):
        if name not in absent:
            buffer[layout[LAYOUT_HEAD + 2 * k]:layout[LAYOUT_HEAD + 1 + 2 * k]] = np.ravel(getattr(inp, name))
    return buffer, layout


def put_field(buf, lay, k, values):
    """Field k of a controller's buffer from ``values`` (flat) where the layout table ``lay`` puts it (nothing for a
    field the layout leaves empty): how a compiled caller fills the buffer it passes by address. (A copy: in Python
    one slice assignment, compiled element by element, :func:`_put_field_compiled`: no slice's shape check.)"""
    start, stop = lay[LAYOUT_HEAD + 2 * k], lay[LAYOUT_HEAD + 1 + 2 * k]
    buf[start:stop] = values[:stop - start]


@overload(put_field, inline="always")
def _put_field_compiled(buf, lay, k, values):
    def impl(buf, lay, k, values):
        start = lay[LAYOUT_HEAD + 2 * k]
        for i in range(lay[LAYOUT_HEAD + 1 + 2 * k] - start):
            buf[start + i] = values[i]
    return impl


def control_arrays(buf, lay):
    """The :class:`ControlArrays` of a buffer by its layout table (views, no copies). Compiled, each field is an
    array over the buffer's memory at its start (:func:`_control_arrays_compiled`: 0.08 µs for the 25 fields, where
    slices and reshapes cost 0.44 µs); the same arrays, shapes and values. (In Python the table as Python ints:
    slicing by them costs less than by numpy's.)"""
    bounds = lay.tolist()
    nv, fields = bounds[0], []
    for k in range(1, len(ControlArrays._fields)):
        start, stop = bounds[LAYOUT_HEAD + 2 * k], bounds[LAYOUT_HEAD + 1 + 2 * k]
        field_k = buf[start:stop]
        if k in _COLUMNS:
            cols = _COLUMNS[k](nv)
            field_k = field_k.reshape(((stop - start) // cols, cols))
        fields.append(field_k)
    return ControlArrays(buf[bounds[LAYOUT_HEAD]], *fields)


_COLUMNS = {k: cols for k, (_, _, cols) in enumerate(LAYOUT) if callable(cols)}  #: a matrix field -> its columns


@njit(cache=True, inline="always")
def _vector_at(buf, lay, k):
    """Field k as a vector over the buffer's memory (no slice: a C array at its start, the buffer owns it)."""
    start = lay[LAYOUT_HEAD + 2 * k]
    return carray(_data_at(buf, start), (lay[LAYOUT_HEAD + 1 + 2 * k] - start,))


@njit(cache=True, inline="always")
def _matrix_at(buf, lay, k, cols):
    """Field k as a (size / cols, cols) matrix over the buffer's memory."""
    start = lay[LAYOUT_HEAD + 2 * k]
    return carray(_data_at(buf, start), ((lay[LAYOUT_HEAD + 1 + 2 * k] - start) // cols, cols))


@overload(control_arrays, inline="always")
def _control_arrays_compiled(buf, lay):
    def impl(buf, lay):
        nv = lay[0]
        return ControlArrays(buf[lay[LAYOUT_HEAD]], _vector_at(buf, lay, 1), _vector_at(buf, lay, 2),
                             _matrix_at(buf, lay, 3, nv), _vector_at(buf, lay, 4), _vector_at(buf, lay, 5),
                             _vector_at(buf, lay, 6), _vector_at(buf, lay, 7), _matrix_at(buf, lay, 8, nv),
                             _vector_at(buf, lay, 9), _vector_at(buf, lay, 10), _vector_at(buf, lay, 11),
                             _vector_at(buf, lay, 12), _vector_at(buf, lay, 13), _matrix_at(buf, lay, 14, 3),
                             _matrix_at(buf, lay, 15, nv), _vector_at(buf, lay, 16), _vector_at(buf, lay, 17),
                             _vector_at(buf, lay, 18), _vector_at(buf, lay, 19), _matrix_at(buf, lay, 20, 3),
                             _vector_at(buf, lay, 21), _matrix_at(buf, lay, 22, 3), _matrix_at(buf, lay, 23, 3),
                             _vector_at(buf, lay, 24))
    return impl


#: the wrapper's source per controller: {name}, {n_layout}, {params} (p[0], p[1], … of the declared parameters)
_WRAPPER = """def {name}(buffer, layout, params, n_p, tau, zdot):  # config: {names}
    lay = carray(layout, ({n_layout},))
    nv = lay[0]
    if n_p != {n_params}:
        return 0
    p = carray(params, (n_p,))
    try:
        out, rates = law(Self(Config({params}), nv), control_arrays(carray(buffer, (lay[{n_layout} - 1],)), lay))
    except Exception:  # the Python path runs the law again, and its own error surfaces there
        return 0
    if out.shape[0] != nv:
        return 0
    t = carray(tau, (nv,))
    for i in range(nv):
        t[i] = out[i]
    return put_states(rates, zdot, lay[1])
"""


def put_states(rates, zdot, nz) -> int:
    """The law's state rates ż written at ``zdot`` (nz of them; a law without states returns None): status 1, or 0
    where it gave another number of rates (compiled only: the wrapper's helper)."""
    raise NotImplementedError("put_states is compiled only (the controller's wrapper)")


@overload(put_states)
def _put_states(rates, zdot, nz):
    if isinstance(rates, types.NoneType):
        def none(rates, zdot, nz):
            return 1 if nz == 0 else 0
        return none

    def impl(rates, zdot, nz):
        if rates.shape[0] != nz:
            return 0
        z = carray(zdot, (nz,)) if nz else np.empty(0)
        for i in range(nz):
            z[i] = rates[i]
        return 1
    return impl


_compiled: dict[tuple, tuple[int, object, str]] = {}  #: (controller class, handles()) -> (address, cfunc, reason)


def controller_address(cls: type) -> int:
    """The address of controller class ``cls``'s compiled ``command`` (compiled on first use); 0 if it has none, the
    reason then in ``cls.compiled_reason``."""
    key = (cls, handles())  # (a process runs compiled and interpreted pipelines: numerics.twins)
    if key in _compiled:
        cls.compiled_reason = _compiled[key][2]
        return _compiled[key][0]
    reason = _declined(cls)
    cfunc = None
    if not reason:
        names = [p.name for p in cls.params]
        config = namedtuple(f"{cls.__name__}Config", names)
        name = f"{cls.__name__}_command_abi"
        source = _WRAPPER.format(name=name, n_layout=LAYOUT_SIZE, names=", ".join(names),
                                 n_params=len(names), params=", ".join(f"p[{i}]" for i in range(len(names))))
        namespace = {"carray": carray, "control_arrays": control_arrays, "Config": config, "put_states": put_states,
                     "Self": namedtuple(f"{cls.__name__}Self", ["config", "nv"])}
        cfunc, reason = compile_wrapper(cls.command, name, source, CONTROLLER_SIGNATURE, namespace)
    cls.compiled_reason = reason
    address = cfunc.address if cfunc is not None else 0
    _compiled[key] = (address, cfunc, reason)
    return address


def _declined(cls: type) -> str:
    """Why ``cls`` is not compiled before numba tries ("" if it may be)."""
    if handles():
        return "numba is disabled (NUMBA_DISABLE_JIT), or the pipeline runs interpreted"
    if getattr(cls.read, "__func__", cls.read) is not Controller.read.__func__:  # (a staticmethod has none)
        return f"controller {cls.name!r} reads its own config (not its declared parameters, Controller.params)"
    return ""


def params_of(config) -> np.ndarray:
    """The declared parameters' values of a controller's config, in order (the C call's ``params``)."""
    return np.array([value for _, value in config.values], dtype=float)


# ---- a declared Python stage: a controller numba cannot compile, called back by the compiled code through ctypes --

@dataclass(frozen=True)
class InputKeys:
    """The keys of the readable ControlInput's dictionaries, which the buffer's fields hold by position: what a
    declared Python stage needs, beyond the buffer, to rebuild that ControlInput (:func:`control_input`)."""

    keys: tuple[str, ...]  #: the "keys" field's rows: per contact its name, then "<contact>.<label>" per chain
    contacts: tuple[str, ...]  #: the contacts' names (``forces`` lists them first, then the chains; ``touching``)
    set_points: tuple[str, ...]  #: ``force_d``'s keys: the phase's set-points in order
    normals: dict = field(compare=False)  #: ``normals`` itself (the system's force directions)
    uses_forces: bool = False  #: ``surfaces`` and ``touching`` filled (as ``evaluation.set_force_inputs`` does)


_OPTIONAL = ("gravity", "x_d", "v_d", "a_d", "R_tip", "J_ang", "drift_ang", "tau_contact")  #: None when empty


def control_input(buf: np.ndarray, lay: np.ndarray, keys: InputKeys) -> ControlInput:
    """The ControlInput a buffer holds, by its layout table: its fields, shapes and values, and the dictionaries
    (by ``keys``); arrays are views of ``buf``."""
    fields_at, (at_set, at_rate, at_keys, nk) = _input_plan(lay.tobytes())
    values = {name: None if shape is None else buf[a:b] if shape == () else buf[a:b].reshape(shape)
              for name, a, b, shape in fields_at}
    rows = buf[at_keys:at_keys + KEY_W * nk].reshape(nk, KEY_W)
    force = dict(zip(keys.keys, rows[:, KEY_FORCE].tolist(), strict=True))
    forces = {**{name: force[name] for name in keys.contacts}, **{k: f for k, f in force.items()
                                                                  if k not in keys.contacts}}
    ns = len(keys.set_points)
    force_d = dict(zip(keys.set_points, zip(buf[at_set:at_set + ns].tolist(), buf[at_rate:at_rate + ns].tolist(),
                                            strict=True), strict=True))
    inp = ControlInput(float(buf[lay[LAYOUT_HEAD]]), forces=forces, force_d=force_d, normals=keys.normals, **values)
    if keys.uses_forces:
        inp.surfaces = {k: (row[KEY_P:KEY_P + 3], row[KEY_V:KEY_V + 3]) for k, row in zip(keys.keys, rows, strict=True)}
        inp.touching = {k: bool(row[KEY_TOUCH]) for k, row in zip(keys.keys, rows, strict=True) if k in keys.contacts}
    return inp


@functools.lru_cache(maxsize=256)
def _input_plan(layout: bytes) -> tuple:
    """Per layout table (its bytes): ((name, start, stop, shape: () a vector, None an empty optional field) per
    ControlInput array field, (where F_d, Ḟ_d and the keys start, the number of keys)): :func:`control_input`'s
    slices, found once."""
    lay = np.frombuffer(layout, dtype=np.int64)
    nv = int(lay[0])
    out = []
    for k, (name, _, cols) in enumerate(LAYOUT[1:], start=1):
        a, b = int(lay[LAYOUT_HEAD + 2 * k]), int(lay[LAYOUT_HEAD + 1 + 2 * k])
        if name in ControlInput.SET_POINT_ARRAYS or name in PYTHON_STAGE_FIELDS:
            continue
        shape = None if a == b and name in _OPTIONAL else ((b - a) // cols(nv), cols(nv)) if callable(cols) else ()
        out.append((name, a, b, shape))
    start = {name: int(lay[LAYOUT_HEAD + 2 * FIELD[name]]) for name in ("force_set", "force_rate", "keys")}
    n_keys = (int(lay[LAYOUT_HEAD + 1 + 2 * FIELD["keys"]]) - start["keys"]) // KEY_W
    return tuple(out), (start["force_set"], start["force_rate"], start["keys"], n_keys)


def command_arrays(name: str, result, nv: int, nz: int) -> tuple[np.ndarray, np.ndarray | None]:
    """(τ (nv), ż (nz) or None) of a controller's ``command`` result, checked: a pair (τ, ż) of those sizes, ż None
    for a law without states. Anything else is the law's error, named (a bare τ of two joints would be taken apart
    as two numbers and the first broadcast to both joints: the wrong torques, silently)."""
    expected = f"(τ, ż): τ {nv} numbers [N·m, N or V], ż {nz} numbers or None"
    if not isinstance(result, tuple) or len(result) != 2:
        raise SimulationError(f"controller {name!r}: its command must return {expected}; it returned "
                              f"{type(result).__name__} {np.shape(result)}")
    tau = np.asarray(result[0], dtype=float)
    rates = None if result[1] is None else np.asarray(result[1], dtype=float)
    if tau.shape != (nv,) or (rates is not None and rates.shape != (nz,)):
        raise SimulationError(f"controller {name!r}: its command must return {expected}; it returned τ of shape "
                              f"{tau.shape} and ż of shape {None if rates is None else rates.shape}")
    return tau, rates


_CONTROLLER_CTYPE = ctypes.CFUNCTYPE(ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                                     ctypes.c_int64, ctypes.c_void_p, ctypes.c_void_p)
#: (id of the controller, id of its normals, its keys) -> (the controller, its keys, address, ctypes callback): kept
#: alive for the process, as the compiled laws are (a packed mode holds the address only)
_python_stages: dict[tuple, tuple] = {}


def python_controller_address(ctl: Controller, keys: InputKeys) -> int:
    """The address of a C function (``CONTROLLER_SIGNATURE``) running controller ``ctl``'s own Python ``command``
    (its real ``self``) on the ControlInput rebuilt from the buffer (:func:`control_input`): its declared
    Python stage. τ and ż are written into the caller's arrays (a wrong shape raises); an
    exception is kept (``laws.abi.python_stage_failed``) and the status is 0, the caller re-raising it."""
    key = (id(ctl), id(keys.normals), keys)
    if key in _python_stages:
        return _python_stages[key][2]

    def command(buffer, layout, params, n_p, tau, zdot):
        try:
            lay = _c_array(layout, ctypes.c_int64, LAYOUT_SIZE)
            nv, nz = int(lay[0]), int(lay[1])
            buf = _c_array(buffer, ctypes.c_double, int(lay[LAYOUT_SIZE - 1])).copy()  # (the caller's is freed)
            out, rates = command_arrays(ctl.name, ctl.command(control_input(buf, lay, keys)), nv, nz)
            _c_array(tau, ctypes.c_double, nv)[:] = out
            if nz:
                _c_array(zdot, ctypes.c_double, nz)[:] = 0.0 if rates is None else rates
            return 1
        except BaseException as exc:  # (ctypes would print it and return 0)
            python_stage_failed(exc, ("controller", type(ctl)))
            return 0

    callback = _CONTROLLER_CTYPE(command)
    address = ctypes.cast(callback, ctypes.c_void_p).value
    _python_stages[key] = (ctl, keys, address, callback)
    return address


def _c_array(pointer: int, ctype, n: int) -> np.ndarray:
    """The n values at ``pointer`` as an array over that memory."""
    return np.frombuffer((ctype * n).from_address(pointer), dtype=ctype) if n else np.empty(0)


# ---- the call: its Python twin (by ctypes), and its compiled form by overload ----------------------------------

def call_controller(address: int, buffer, layout, params, tau, zdot=None) -> int:
    """Status of the controller at ``address`` on ``buffer`` by ``layout`` with ``params``, τ written into ``tau``
    and its states' rates into ``zdot`` (float64 and int64 arrays, contiguous: the C function reads them by
    pointer; ``zdot`` may be omitted for a law without states)."""
    if not address:
        raise ValueError("call_controller: address 0 (the controller is not compiled: see its compiled_reason)")
    buffer, layout, params = (np.ascontiguousarray(buffer, float), np.ascontiguousarray(layout, np.int64),
                              np.ascontiguousarray(params, float))
    zdot = np.zeros(max(int(layout[1]), 1)) if zdot is None else zdot
    for name, out in (("tau", tau), ("zdot", zdot)):
        if not (out.dtype == np.float64 and out.flags.c_contiguous):
            raise ValueError(f"call_controller: {name} must be a contiguous float64 array (it is written)")
    fn = _CONTROLLER_CTYPE(int(address))
    return fn(buffer.ctypes.data, layout.ctypes.data, params.ctypes.data, params.size, tau.ctypes.data,
              zdot.ctypes.data)


@overload(call_controller, inline="always")
def _call_controller_compiled(address, buffer, layout, params, tau, zdot):
    def impl(address, buffer, layout, params, tau, zdot):
        return _call_at_controller(address, _data_at(buffer, 0), _data_at(layout, 0), _data_at(params, 0),
                                   params.size, _data_at(tau, 0), _data_at(zdot, 0))
    return impl


@intrinsic
def _call_at_controller(typingctx, address, buffer, layout, params, n_p, tau, zdot):
    return types.int64(types.int64, *CONTROLLER_SIGNATURE.args), _indirect_call(CONTROLLER_SIGNATURE)
