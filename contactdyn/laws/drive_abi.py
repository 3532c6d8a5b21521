"""A drive kind's calling convention (its ABI): the compiled model calls a kind's ``voltage`` and ``force`` by address.

A drive kind (:mod:`contactdyn.laws.drive_kinds`) writes its law as two functions of the drive's
:class:`~contactdyn.laws.drives.DriveSpec` (its parameters and transmission figures as attributes, ``spec.R``,
``spec.n_speed``). numba compiles those same functions with ``spec`` a named tuple of the kind's declared
parameters (in order) followed by the figures of ``DriveSpec.DERIVED``, so attribute access compiles unchanged.
The two C functions of a kind, each address a plain int64 (:func:`drive_addresses`):

- ``double voltage(double* p, int64 n_p, double tau, double qd, double omega)``: the voltage u [V] asking for the
  generalized force τ [N·m or N] at coordinate speed q̇ and motor speed ω [rad/s] (kinds with a voltage);
  NaN when the law raised or ``n_p`` is not the kind's count;
- ``int64 force(double* p, int64 n_p, double command, double q, double qd, double theta, double omega,
  double* out)``: out[0:4] = (force on the coordinate [N·m or N], torque on the motor coordinate [N·m], power
  delivered [W], power dissipated [W]) at the command (a voltage [V] for a kind with one, else a force), the
  coordinate's (q, q̇) and the motor's (θ, ω) (NaN without a motor coordinate); status 1 written, 0 not (the law
  raised): the caller then goes Python's way, where the law's own error surfaces.

``p[0:n_p]`` is :func:`spec_values` of the drive. An ideal source (a kind that is not motorized) has no functions:
its command acts as it is. A kind whose functions numba cannot compile (a helper that is not jittable, a Python
object) has address 0 and the reason in ``kind.compiled_reason``: the compiled model runs it as a declared Python
stage, a ctypes callback of each function for the drive's own spec (:func:`python_drive_addresses`; its exception
kept and re-raised after the call, :func:`contactdyn.laws.abi.raise_python_stage_error`).

Under ``NUMBA_DISABLE_JIT=1`` nothing is compiled: an address is a handle of the kind's Python function and the
same calling code runs interpreted (:func:`call_drive_voltage`, :func:`call_drive_force`; from Python with numba
on, they call the compiled functions; what the kind raises there is marked as its, a wrong signature named);
:func:`checking_drives` checks their results while a call with no answer runs again, to name a kind that returned
NaN or ±inf (as :func:`contactdyn.laws.abi.checking_laws` does the stage and friction laws). Caching: the wrappers
are generated closure-free and attributed to the kind's own file (:func:`contactdyn.laws.abi.compile_wrapper`).
"""

from __future__ import annotations

import ctypes
import math
from collections import namedtuple
from contextlib import contextmanager

from numba import carray, types
from numba.extending import intrinsic, overload, register_jitable

from ..numerics.compile_cache import njit
from ..numerics.native_call import handles
from . import drive_kinds
from .abi import _data_at, _finite, _indirect_call, compile_wrapper, python_stage_failed
from .drives import DriveSpec
from .failures import raised_calling

__all__ = ["VOLTAGE_SIGNATURE", "FORCE_SIGNATURE", "drive_addresses", "python_drive_addresses", "spec_values",
           "call_drive_voltage", "call_drive_force", "checking_drives"]

# the built-in kinds' shared helper (the output lever), compiled inline where a kind's law calls it
register_jitable(drive_kinds._lever)

_P = types.CPointer(types.float64)
#: double voltage(double* p, int64 n_p, double tau, double qd, double omega)
VOLTAGE_SIGNATURE = types.float64(_P, types.int64, types.float64, types.float64, types.float64)
#: int64 force(double* p, int64 n_p, double command, double q, double qd, double theta, double omega, double* out)
FORCE_SIGNATURE = types.int64(_P, types.int64, types.float64, types.float64, types.float64, types.float64,
                              types.float64, _P)

_WRAPPERS = {
    "voltage": """def {name}(p, n_p, tau, qd, omega):
    if n_p != {n}:
        return NAN
    a = carray(p, (n_p,))
    try:
        return law(Spec({args}), tau, qd, omega)
    except Exception:
        return NAN
""",
    "force": """def {name}(p, n_p, command, q, qd, theta, omega, out):
    if n_p != {n}:
        return 0
    a = carray(p, (n_p,))
    try:
        r = law(Spec({args}), command, q, qd, theta, omega)
    except Exception:
        return 0
    o = carray(out, (4,))
    o[0], o[1], o[2], o[3] = r[0], r[1], r[2], r[3]
    return 1
""",
}
_SIGNATURES = {"voltage": VOLTAGE_SIGNATURE, "force": FORCE_SIGNATURE}

#: (kind, handles()) -> (voltage address, force address, kept alive, compiled_reason)
_compiled: dict[tuple, tuple[int, int, tuple, str]] = {}
#: handle -> (the kind's Python function, its Spec, the kind, its family "voltage" or "force"): the calls'
#: plain-Python twin
_python: dict[int, tuple] = {}


def spec_fields(kind: type) -> list[str]:
    """The named tuple ``spec`` of a kind's compiled law: its declared parameters, then DriveSpec's figures."""
    return [p.name for p in kind.params] + list(DriveSpec.DERIVED)


def spec_values(spec: DriveSpec) -> list[float]:
    """``p`` of a drive's calls: its parameters' values in declared order, then its figures (DriveSpec.DERIVED)."""
    return [float(v) for v in spec.params] + [float(getattr(spec, name)) for name in DriveSpec.DERIVED]


def drive_addresses(kind: type) -> tuple[int, int]:
    """(voltage, force) addresses of motorized kind ``kind`` (compiled on first use; voltage 0 for a kind without
    one); force 0 if numba cannot compile the kind, the reason then in ``kind.compiled_reason``."""
    key = (kind, handles())  # (a process runs compiled and interpreted pipelines: numerics.twins)
    if key in _compiled:
        kind.compiled_reason = _compiled[key][3]
        return _compiled[key][:2]
    spec = namedtuple(f"{kind.__name__}Spec", spec_fields(kind))
    families = (("voltage", kind.voltage), ("force", kind.force)) if kind.has_voltage else (("force", kind.force),)
    found, kept, reason = {}, [], ""
    for family, fn in families:
        if key[1]:  # nothing compiles: a handle of the Python function
            holder = (fn, spec, kind, family)
            kept.append(holder)
            found[family] = id(holder)
            _python[id(holder)] = holder
            continue
        name = f"{kind.__name__}_{family}_drive_abi"
        args = ", ".join(f"a[{i}]" for i in range(len(spec._fields)))
        source = _WRAPPERS[family].format(name=name, n=len(spec._fields), args=args)
        cfunc, reason = compile_wrapper(fn, name, source, _SIGNATURES[family],
                                        {"carray": carray, "NAN": math.nan, "Spec": spec})
        if cfunc is None:
            found = {}
            break
        kept.append(cfunc)
        found[family] = cfunc.address
    kind.compiled_reason = reason
    _compiled[key] = (found.get("voltage", 0), found.get("force", 0), tuple(kept), reason)
    return _compiled[key][:2]


_C_P = ctypes.POINTER(ctypes.c_double)
_VOLTAGE_CTYPE = ctypes.CFUNCTYPE(ctypes.c_double, _C_P, ctypes.c_int64, ctypes.c_double, ctypes.c_double,
                                  ctypes.c_double)
_FORCE_CTYPE = ctypes.CFUNCTYPE(ctypes.c_int64, _C_P, ctypes.c_int64, ctypes.c_double, ctypes.c_double,
                                ctypes.c_double, ctypes.c_double, ctypes.c_double, _C_P)
_callbacks: dict[DriveSpec, tuple[int, int, tuple]] = {}  #: spec -> (voltage, force addresses, callbacks kept)


def python_drive_addresses(spec: DriveSpec) -> tuple[int, int]:
    """(voltage, force) addresses of C functions (the ABI's signatures) calling the Python ``voltage`` and ``force``
    of ``spec``'s kind with ``spec`` itself: the declared Python
    stage of a kind numba cannot compile (voltage 0 for a kind without one)."""
    if spec in _callbacks:
        return _callbacks[spec][:2]
    kind = spec.law

    def voltage(p, n_p, tau, qd, omega):
        try:
            return float(kind.voltage(spec, tau, qd, omega))
        except BaseException as exc:  # (ctypes would print it and return 0)
            python_stage_failed(exc, ("drive kind", kind))
            return math.nan

    def force(p, n_p, command, q, qd, theta, omega, out):
        try:
            out[0], out[1], out[2], out[3] = kind.force(spec, command, q, qd, theta, omega)
            return 1
        except BaseException as exc:
            python_stage_failed(exc, ("drive kind", kind))
            return 0

    kept = (_VOLTAGE_CTYPE(voltage), _FORCE_CTYPE(force))
    v_addr, f_addr = (ctypes.cast(c, ctypes.c_void_p).value for c in kept)
    _callbacks[spec] = (v_addr if kind.has_voltage else 0, f_addr, kept)
    return _callbacks[spec][:2]


# ---- the calls: Python twins (interpreted), and their compiled form by overload --------------------------------

def call_drive_voltage(address: int, p, at: int, n_p: int, tau: float, qd: float, omega: float) -> float:
    """u [V] of the kind's voltage at ``address`` with the drive's values p[at:at + n_p] (float64, contiguous):
    interpreted, a handle's Python function; from Python with numba on, the compiled function."""
    if address not in _python:
        return _voltage_compiled(address, p, at, n_p, tau, qd, omega)
    fn, spec, kind, _ = _python[address]
    values = spec(*p[at:at + n_p])
    try:
        return fn(values, tau, qd, omega)
    except Exception as exc:
        raised_calling(exc, ("drive kind", kind))
        raise


def call_drive_force(address: int, p, at: int, n_p: int, command: float, q: float, qd: float, theta: float,
                     omega: float, out) -> int:
    """Status of the kind's force at ``address`` (out[0:4] written: coordinate force, motor torque, power,
    dissipation) with the drive's values p[at:at + n_p]; interpreted, a handle's Python function."""
    if address not in _python:
        return _force_compiled(address, p, at, n_p, command, q, qd, theta, omega, out)
    fn, spec, kind, _ = _python[address]
    values = spec(*p[at:at + n_p])
    try:
        out[:4] = fn(values, command, q, qd, theta, omega)
    except Exception as exc:
        raised_calling(exc, ("drive kind", kind))
        raise
    return 1


@contextmanager
def checking_drives(notes: list):
    """Inside: each drive kind's plain-Python call (:func:`call_drive_voltage`'s, :func:`call_drive_force`'s twins)
    checked, the first non-finite result from finite inputs noted in ``notes`` as (family "drive voltage" or "drive
    force", the kind, (the spec's values, the call's arguments), its result): the drives of a call with no answer, run
    again interpreted (nothing is checked outside)."""
    saved = dict(_python)
    for handle, (fn, spec, kind, family) in saved.items():
        _python[handle] = (_checked(fn, kind, family, notes), spec, kind, family)
    try:
        yield notes
    finally:
        _python.update(saved)


def _checked(fn, kind: type, family: str, notes: list):
    """The kind's ``fn`` noting in ``notes`` its first result that is not finite from finite inputs. Those a kind
    without a motor coordinate does not have are NaN (θ, ω) and its motor torque is not read: neither is checked."""
    motor = kind.motor_coordinate
    motor_inputs = 1 if family == "voltage" else 2  #: the last arguments: ω (voltage), θ and ω (force)

    def checked(spec, *args):
        value = fn(spec, *args)
        inputs = args if motor else args[:-motor_inputs]
        outputs = (value,) if family == "voltage" else tuple(value[:2 if motor else 1])
        if not notes and _finite(inputs) and not _finite(outputs):  # (None: not a number)
            notes.append((f"drive {family}", kind, (tuple(spec), *args), outputs if family == "force" else value))
        return value
    return checked


@njit(cache=True)
def _voltage_compiled(address, p, at, n_p, tau, qd, omega):
    return call_drive_voltage(address, p, at, n_p, tau, qd, omega)


@njit(cache=True)
def _force_compiled(address, p, at, n_p, command, q, qd, theta, omega, out):
    return call_drive_force(address, p, at, n_p, command, q, qd, theta, omega, out)


@overload(call_drive_voltage)
def _call_drive_voltage_compiled(address, p, at, n_p, tau, qd, omega):
    def impl(address, p, at, n_p, tau, qd, omega):
        return _call_at_voltage(address, _data_at(p, at), n_p, tau, qd, omega)
    return impl


@overload(call_drive_force)
def _call_drive_force_compiled(address, p, at, n_p, command, q, qd, theta, omega, out):
    def impl(address, p, at, n_p, command, q, qd, theta, omega, out):
        return _call_at_force(address, _data_at(p, at), n_p, command, q, qd, theta, omega, _data_at(out, 0))
    return impl


@intrinsic
def _call_at_voltage(typingctx, address, p, n_p, tau, qd, omega):
    return types.float64(types.int64, *VOLTAGE_SIGNATURE.args), _indirect_call(VOLTAGE_SIGNATURE)


@intrinsic
def _call_at_force(typingctx, address, p, n_p, command, q, qd, theta, omega, out):
    return types.int64(types.int64, *FORCE_SIGNATURE.args), _indirect_call(FORCE_SIGNATURE)
