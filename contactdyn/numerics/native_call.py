"""Compiled functions called by address: each compiled on its own at its first use and cached, so a caller's code
does not hold theirs.

numba compiles a function together with everything it calls: each callee's code is linked into the caller's and
optimized again there, and again in each caller of that caller; and every branch is compiled, taken or not. A
function the caller reaches by address instead is compiled once, on its own, for the one signature declared with
it, when :func:`address` first asks for it (from Python: a scene that never needs it never compiles it), and cached
on disk as any function of the package (:mod:`.compile_cache`). The caller's code holds a call through a pointer
(the address an int64 the caller reads from its data): its arguments, result and exceptions are numba's own, as in
a direct call (the native calling convention, not a C one), so the function keeps its ordinary source.

    declare("name", function, signature)       # once, where the function is imported (numba's Signature)
    ints[SLOT] = address("name")                # from Python: compiled (or loaded) here
    result = call_at(ints[SLOT], "name", (a, b, c))    # in compiled code: the arguments as one tuple

The tuple's types must be the declared signature's (a typing error names both otherwise): the function was
compiled for those. Under NUMBA_DISABLE_JIT, and while :func:`giving_handles` is on (a mode packed for the
pipeline run interpreted, :mod:`.twins`), the address is a handle of the Python function and :func:`call_at`
calls it: the same source, interpreted. An address is valid in the process that asked for it only.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable

import numba
from numba import types
from numba.core import cgutils, errors
from numba.extending import lower_builtin, type_callable

from .compile_cache import directory  # noqa: F401  (a compiled module: this source is in the cache's key)

__all__ = ["declare", "address", "call_at", "handles", "giving_handles"]

_DECLARED: dict[str, tuple[object, object]] = {}  #: name -> (numba dispatcher, its declared signature)
_HANDLES: dict[int, Callable] = {}  #: interpreted: handle -> the Python function
_GIVING = [False]  #: giving_handles is on


def handles() -> bool:
    """Do the address functions (here, the laws' and controllers' ABIs) give handles of Python functions instead of
    compiling: under NUMBA_DISABLE_JIT, and inside :func:`giving_handles`?"""
    return bool(numba.config.DISABLE_JIT or _GIVING[0])


@contextlib.contextmanager
def giving_handles():
    """The address functions give handles meanwhile (a mode packed for the pipeline run interpreted, :mod:`.twins`)."""
    saved, _GIVING[0] = _GIVING[0], True
    try:
        yield
    finally:
        _GIVING[0] = saved


def declare(name: str, function, signature) -> None:
    """``function`` (a numba dispatcher) callable by address as ``name``, compiled for ``signature`` (numba's
    ``Signature``: its return type and the argument types its callers pass)."""
    _DECLARED[name] = (function, signature)


def address(name: str) -> int:
    """The address of ``name``'s function (compiled, or loaded from the cache, at its first use in the process);
    interpreted (:func:`handles`), a handle of its Python function."""
    function, signature = _DECLARED[name]
    if handles():
        python = getattr(function, "py_func", function)
        _HANDLES[id(python)] = python
        return id(python)
    function.compile(signature)
    compiled = function.overloads[signature.args]
    return compiled.library.get_pointer_to_function(compiled.fndesc.llvm_func_name)


def call_at(at: int, name: str, args: tuple):
    """``name``'s function at address ``at`` called with the arguments ``args``; interpreted, the handle's."""
    return _HANDLES[int(at)](*args)


# Compiled, call_at is typed and lowered in place (numba's lower-level extension API, not an @overload whose
# implementation would be one more compiled function per call site's name: ~0.05 s each of a cold first run).
@type_callable(call_at)
def _type_call_at(context):
    def typer(at, name, args):
        if not isinstance(name, types.StringLiteral):  # (numba tries the plain string first)
            return None
        key = name.literal_value
        _, signature = _DECLARED[key]
        if tuple(args) != tuple(signature.args):
            raise errors.TypingError(f"call_at {key!r}: the arguments are ({', '.join(map(str, args))}), "
                                     f"the declared signature's ({', '.join(map(str, signature.args))})")
        return signature.return_type
    return typer


@lower_builtin(call_at, types.Integer, types.StringLiteral, types.BaseTuple)
def _lower_call_at(context, builder, sig, llargs):
    """The pointer ``at`` called with numba's own calling convention; its exception, if any, propagated."""
    _, signature = _DECLARED[sig.args[1].literal_value]
    restype, argtypes = signature.return_type, signature.args
    pointer = builder.inttoptr(llargs[0], context.call_conv.get_function_type(restype, argtypes).as_pointer())
    status, result = context.call_conv.call_function(builder, pointer, restype, argtypes,
                                                     cgutils.unpack_tuple(builder, llargs[2]))
    with cgutils.if_unlikely(builder, status.is_error):
        context.call_conv.return_status_propagate(builder, status)
    return result
