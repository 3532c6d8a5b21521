"""A law's calling convention (its ABI): the compiled model calls a stage or friction law by address.

A law is one Python function. numba compiles it once into a C function (a ``cfunc``) of one fixed signature
per family; the function's machine address is a plain int64. The model keeps addresses in its packed arrays
and calls a law through its address (:func:`call_stage`, :func:`call_friction`), so one compiled model serves
every law, built in or a user's, with no kernel per law. The families' C signatures:

- stage law:    ``double force(double k, double b, double* p, int64 n_p, double x, double xdot)``:
  F [N] at compression x [m] and rate ẋ [m/s]; k [N/m] and b [N·s/m] are every stage's, p[0:n_p] the law's
  own parameters in their declared order (``StageLaw.force(k, b, p, x, xdot)``);
- friction law: ``double kinetic(double mu_s, double mu_k, double* p, int64 n_p, double speed)``:
  μ [-] at slip speed |v_t| [m/s] from μ_s, μ_k [-] and the law's own parameters
  (``FrictionLaw.coefficient(mu_s, mu_k, p, speed)``).

A law is compiled lazily, once per law class (:func:`stage_address`, :func:`friction_address`). A law numba cannot
compile keeps the reason on the class (``law.compiled_reason``; "" when compiled) and address 0. The compiled call
runs it as a declared Python stage: a C function of the same signature made by ``ctypes`` around its Python function
(:func:`python_stage_address`, :func:`python_friction_address`), its address where the cfunc's would be; the
compiled code calls back into Python for that law only (it holds the GIL). A Python stage's exception is kept
(:func:`python_stage_failed`), its call gives NaN (the call's status then -1), and :func:`raise_python_stage_error`
raises it where the caller reads that status, as the law's :class:`~.failures.LawError` (its name, file and line, the
exception chained): the user sees the law's own error. The calls have a plain-Python twin: under
``NUMBA_DISABLE_JIT=1`` nothing is compiled, an address is a handle of the law's Python function, and the same
calling code runs interpreted; :func:`checking_laws` checks the twins' results while a call with no answer runs
again to name a law that returned NaN or ±inf (nothing is checked otherwise).

Caching: the compiled law is cached on disk by numba (``cache=True``). A cfunc made in a factory as a closure
is not (numba keys a closure's cache on its pickled cells, and a dispatcher pickles with a new id in every
process), so the wrapper is a closure-free function generated from source and attributed to the law's own
file: numba caches it in the package's compiled-code directory (:mod:`contactdyn.numerics.compile_cache`, keyed
by this module's source among others), in a subdirectory keyed by the law's own file and the user's files it imports
(:func:`~contactdyn.numerics.compile_cache.sources_key`): an edit of any of them recompiles it (numba alone checks
the law's file only, and freezes a constant or a compiled helper imported from another).
"""

from __future__ import annotations

import ctypes
import hashlib
import inspect
import math
import os
from contextlib import contextmanager

from llvmlite import ir
from numba import carray, types
from numba.extending import intrinsic, overload

from ..errors import first_line
from ..numerics.compile_cache import cfunc, njit, sources_key
from ..numerics.native_call import handles
from .failures import law_error, raised_calling
from .friction_laws import FRICTION_LAWS, FrictionLaw

__all__ = ["STAGE_SIGNATURE", "FRICTION_SIGNATURE", "stage_address", "friction_address", "call_stage",
           "call_friction", "compile_wrapper", "python_stage_address", "python_friction_address",
           "python_stage_failed", "raise_python_stage_error", "drop_python_stage_error", "checking_laws"]

_P = types.CPointer(types.float64)
#: double force(double k, double b, double* p, int64 n_p, double x, double xdot)
STAGE_SIGNATURE = types.float64(types.float64, types.float64, _P, types.int64, types.float64, types.float64)
#: double kinetic(double mu_s, double mu_k, double* p, int64 n_p, double speed)
FRICTION_SIGNATURE = types.float64(types.float64, types.float64, _P, types.int64, types.float64)

#: the cfunc's body per family: the C arguments to the law's Python arguments (p as an array of n_p)
#: (a law that raises returns NaN: its caller recomputes it in Python, where the law's own error surfaces)
_WRAPPERS = {
    "stage": "def {name}(k, b, p, n_p, x, xdot):\n    try:\n        return law(k, b, carray(p, (n_p,)), x, xdot)\n"
             "    except Exception:\n        return NAN\n",
    "friction": "def {name}(mu_s, mu_k, p, n_p, speed):\n    try:\n"
                "        return law(mu_s, mu_k, carray(p, (n_p,)), speed)\n    except Exception:\n        return NAN\n",
}
_SIGNATURES = {"stage": STAGE_SIGNATURE, "friction": FRICTION_SIGNATURE}

#: (law class, handles()) -> (address, its cfunc, kept alive while it is used, the compiled_reason)
_compiled: dict[tuple, tuple[int, object, str]] = {}
_python: dict[int, object] = {}  #: address -> the law's Python function (the calls' plain-Python twin)
_laws: dict[int, tuple[str, type]] = {}  #: address -> (family, law class) of the functions in _python
_KINDS = {"stage": "stage law", "friction": "friction law"}  #: family -> the kind a LawError names


def stage_address(law: type) -> int:
    """The address of stage law ``law``'s compiled ``force`` (compiled on first use); 0 if numba cannot compile
    it, the reason then in ``law.compiled_reason``."""
    return _address(law, "stage", law.force)


def friction_address(law: type) -> int:
    """The address of friction law ``law``'s compiled ``coefficient``; 0 if it has none numba can compile (a law
    that only overrides ``kinetic(spec, speed)`` is Python), the reason then in ``law.compiled_reason``."""
    if law.coefficient is FrictionLaw.coefficient:
        law.compiled_reason = (f"friction law {law.name!r} gives its coefficient by kinetic(spec, speed) only "
                               "(Python): define coefficient(mu_s, mu_k, p, speed) to compile it")
        return 0
    return _address(law, "friction", law.coefficient)


def _address(law: type, family: str, fn) -> int:
    key = (law, handles())  # (a process runs compiled and interpreted pipelines: numerics.twins)
    if key in _compiled:
        law.compiled_reason = _compiled[key][2]
        return _compiled[key][0]
    if key[1]:  # nothing compiles: the address is a handle of the Python function
        address, cfunc, reason = id(fn), None, ""
    else:
        cfunc, reason = _compile(law, family, fn)
        address = cfunc.address if cfunc is not None else 0
    law.compiled_reason = reason
    _compiled[key] = (address, cfunc, reason)
    if address:
        _python[address], _laws[address] = fn, (family, law)
    return address


# ---- declared Python stages: a law numba cannot compile, called back by the compiled code through ctypes ---------

_C_P = ctypes.POINTER(ctypes.c_double)
_STAGE_CTYPE = ctypes.CFUNCTYPE(ctypes.c_double, ctypes.c_double, ctypes.c_double, _C_P, ctypes.c_int64,
                                ctypes.c_double, ctypes.c_double)
_FRICTION_CTYPE = ctypes.CFUNCTYPE(ctypes.c_double, ctypes.c_double, ctypes.c_double, _C_P, ctypes.c_int64,
                                   ctypes.c_double)
#: law class (stage) or FrictionSpec (friction) -> (address, its ctypes callback): kept alive for the process, as
#: the cfuncs are (a packed mode holds the address only)
_callbacks: dict[object, tuple[int, object]] = {}
#: (the exception a Python stage raised in a compiled call, (kind, class) of the law it called), until re-raised
_raised: list[tuple[BaseException, tuple | None]] = []


def python_stage_failed(exc: BaseException, law: tuple[str, type] | None = None) -> None:
    """Keep ``exc`` (raised by a Python stage inside a compiled call; ``law``: (its kind, its class), the law the
    stage called) for :func:`raise_python_stage_error`."""
    _raised.append((exc, law))


def raise_python_stage_error(t: float | None = None) -> None:
    """Raise the first exception a Python stage raised since the last such call (the caller read a status that is
    not 1; t [s] the call's time, if one call's): a user's law's as its LawError, chained to it; nothing when none
    did."""
    if _raised:
        exc, law = _raised[0]
        _raised.clear()
        error = law_error(exc, t, law)
        if error is None:
            raise exc
        raise error from exc


def drop_python_stage_error() -> None:
    """Forget the exceptions Python stages raised since the last such call (a compiled step that declines: the
    Python right-hand side repeats its calls, and raises it at its own call's time)."""
    _raised.clear()


def python_stage_address(law: type) -> int:
    """The address of a C function (``STAGE_SIGNATURE``) calling stage law ``law``'s Python ``force`` with p as a
    tuple (as ``ChainStage.force`` calls it): its declared Python stage. Interpreted, the law's handle."""
    address = stage_address(law)
    if address or law in _callbacks:
        return address or _callbacks[law][0]

    def force(k, b, p, n_p, x, xdot):
        try:
            return float(law.force(k, b, tuple(p[:n_p]), x, xdot))
        except BaseException as exc:  # (ctypes would print it and return 0)
            python_stage_failed(exc, ("stage law", law))
            return math.nan

    return _keep(law, _STAGE_CTYPE(force))


def python_friction_address(spec) -> int:
    """The address of a C function (``FRICTION_SIGNATURE``) giving μ [-] of a contact's friction ``spec`` (a
    FrictionSpec) by its Python ``spec.mu(speed)``: its law's declared Python stage.
    Interpreted, a handle of the same function."""
    if (spec, handles()) in _callbacks:
        return _callbacks[spec, handles()][0]

    def mu(mu_s, mu_k, p, n_p, speed):
        try:
            return float(spec.mu(speed))
        except BaseException as exc:
            python_stage_failed(exc, ("friction law", FRICTION_LAWS.get(spec.law, FrictionLaw)))
            return math.nan

    if handles():  # the twin's call: (mu_s, mu_k, p[at:at + n_p], speed)
        def twin(mu_s, mu_k, p, speed):
            return float(spec.mu(speed))
        _python[id(twin)], _laws[id(twin)] = twin, ("friction", FRICTION_LAWS[spec.law])
        _callbacks[spec, True] = (id(twin), twin)
        return id(twin)
    return _keep((spec, False), _FRICTION_CTYPE(mu))


@contextmanager
def checking_laws():
    """Inside: each law's plain-Python call (:func:`call_stage`'s and :func:`call_friction`'s twins) checked, the
    first non-finite result kept in the list given, as (family, law class, the call's arguments, its result): the
    laws of a call with no answer, run again interpreted (nothing is checked outside)."""
    notes: list[tuple] = []
    saved = dict(_python)
    for address, fn in saved.items():
        if address in _laws:
            _python[address] = _checked(fn, *_laws[address], notes)
    try:
        yield notes
    finally:
        _python.update(saved)


def _checked(fn, family: str, law: type, notes: list):
    """``fn`` noting in ``notes`` its first non-finite result from finite arguments (with a copy of them)."""
    def checked(*args):
        value = fn(*args)
        if not notes and _finite([value]) is False and _finite(args):
            notes.append((family, law, tuple(list(map(float, a)) if hasattr(a, "__len__") else a for a in args),
                          value))
        return value
    return checked


def _finite(values) -> bool | None:
    """Every number among ``values`` (numbers, or sequences of numbers) finite; None where one is not a number."""
    try:
        return all(math.isfinite(v) for a in values for v in (a if hasattr(a, "__len__") else (a,)))
    except (TypeError, ValueError):  # (not a number: the call's own code says so)
        return None


def _keep(key, callback) -> int:
    address = ctypes.cast(callback, ctypes.c_void_p).value
    _callbacks[key] = (address, callback)
    return address


def _compile(law: type, family: str, fn) -> tuple[object | None, str]:
    """(the law's cfunc, "") or (None, why numba cannot compile it): :func:`compile_wrapper` of the family's wrapper."""
    name = f"{law.__name__}_{fn.__name__}_abi"
    return compile_wrapper(fn, name, _WRAPPERS[family].format(name=name), _SIGNATURES[family],
                           {"carray": carray, "NAN": math.nan})


def compile_wrapper(fn, name: str, source: str, signature, namespace: dict) -> tuple[object | None, str]:
    """(the cfunc of ``signature`` compiled from ``source``, which defines ``name`` calling the law's function as
    ``law``, "") or (None, why numba cannot compile it). The source is attributed to ``fn``'s own file (numba
    caches the cfunc beside it). Cached first; if that fails (a cache that does not load counts too), once more
    uncached, whose error is the reason."""
    try:
        path = inspect.getfile(fn)
    except TypeError:
        path = "<unknown>"
    exec(compile(source, path, "exec"), namespace)
    wrapper = namespace[name]
    # numba keys a cached function by its file and qualified name, not by the globals it calls: the name carries
    # the law's class and a digest of the wrapper (two classes sharing an inherited function stay apart), and a
    # law with closure cells (made in a factory) or without a real file is not cached at all
    digest = hashlib.sha256(f"{name}\0{source}".encode()).hexdigest()[:12]
    wrapper.__module__, wrapper.__qualname__ = fn.__module__, f"{fn.__qualname__}_{name}_{digest}"
    cacheable = os.path.isfile(path) and not fn.__closure__
    under = sources_key(fn) if cacheable else None  # (keyed by the law's file and the user's files it imports)
    for cache in ((True, False) if cacheable else (False,)):
        try:
            namespace["law"] = _jit(fn, cache, under)
            return _cfunc(wrapper, signature, cache, under), ""
        except Exception as exc:  # numba's typing or lowering errors, and whatever the law's code raises in them
            reason = f"numba cannot compile {fn.__qualname__}: {_first_line(exc)}"
    return None, reason


def _jit(fn, cache: bool, under: str | None):
    """The law's function under numba, cached (compile_cache's directory, its subdirectory ``under``) when it has a
    source file."""
    try:
        return njit(cache=cache, boundscheck=True, under=under)(fn)
    except RuntimeError:  # "no locator available": a law without a source file (exec'd, a notebook's cell)
        return njit(boundscheck=True)(fn)


def _cfunc(wrapper, signature, cache: bool, under: str | None):
    """The wrapper compiled to a C function of ``signature``, cached (as :func:`_jit`) when the law has a source
    file."""
    try:
        return cfunc(signature, cache=cache, under=under)(wrapper)
    except RuntimeError as exc:
        if "locator" not in str(exc):
            raise
        return cfunc(signature)(wrapper)


def _first_line(exc: Exception) -> str:
    """The informative line of a numba error, whole (its first line names the pipeline step only:
    :func:`~contactdyn.errors.first_line` of the lines after it)."""
    lines = str(exc).splitlines()
    told = [line for line in lines if line.strip() and not first_line(line).startswith("Failed in ")]
    return first_line("\n".join(told or lines)) or type(exc).__name__


# ---- the calls: Python twins, and their compiled form by overload ----------------------------------------------

def call_stage(address: int, k: float, b: float, p, at: int, n_p: int, x: float, xdot: float) -> float:
    """F [N] of the stage law at ``address`` with parameters p[at:at + n_p], at compression x [m], rate ẋ [m/s]
    (interpreted: what it raises marked as the law's, :func:`~.failures.raised_calling`)."""
    try:
        return _python[address](k, b, p[at:at + n_p], x, xdot)
    except Exception as exc:
        _raised_calling(exc, address)
        raise


def call_friction(address: int, mu_s: float, mu_k: float, p, at: int, n_p: int, speed: float) -> float:
    """μ [-] of the friction law at ``address`` with parameters p[at:at + n_p] at slip speed [m/s] (interpreted: what
    it raises marked as the law's)."""
    try:
        return _python[address](mu_s, mu_k, p[at:at + n_p], speed)
    except Exception as exc:
        _raised_calling(exc, address)
        raise


def _raised_calling(exc: Exception, address: int) -> None:
    """``exc``, raised calling the law at ``address``, marked as its (a wrong signature names it)."""
    family, law = _laws.get(address, (None, None))
    raised_calling(exc, (_KINDS[family], law) if law is not None else None)


@overload(call_stage)
def _call_stage_compiled(address, k, b, p, at, n_p, x, xdot):
    def impl(address, k, b, p, at, n_p, x, xdot):
        return _call_at_stage(address, k, b, _data_at(p, at), n_p, x, xdot)
    return impl


@overload(call_friction)
def _call_friction_compiled(address, mu_s, mu_k, p, at, n_p, speed):
    def impl(address, mu_s, mu_k, p, at, n_p, speed):
        return _call_at_friction(address, mu_s, mu_k, _data_at(p, at), n_p, speed)
    return impl


def _indirect_call(c_signature):
    """Codegen of a call to the C function of ``c_signature`` whose address is the first argument."""
    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(context.get_value_type(c_signature.return_type),
                               [context.get_value_type(t) for t in c_signature.args])
        return builder.call(builder.inttoptr(args[0], fnty.as_pointer()), args[1:])
    return codegen


@intrinsic
def _call_at_stage(typingctx, address, k, b, p, n_p, x, xdot):
    return types.float64(types.int64, *STAGE_SIGNATURE.args), _indirect_call(STAGE_SIGNATURE)


@intrinsic
def _call_at_friction(typingctx, address, mu_s, mu_k, p, n_p, speed):
    return types.float64(types.int64, *FRICTION_SIGNATURE.args), _indirect_call(FRICTION_SIGNATURE)


@intrinsic
def _data_at(typingctx, arr, at):
    """&arr[at] of a contiguous 1-D float64 or int64 array (a law's parameters inside a packed array)."""
    if not (isinstance(arr, types.Array) and arr.ndim == 1 and arr.dtype in (types.float64, types.int64)
            and arr.layout == "C"):
        return None

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        return builder.gep(data, [args[1]])
    return types.CPointer(arr.dtype)(arr, types.intp), codegen
