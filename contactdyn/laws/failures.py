"""A researcher's law that fails inside a run: one error naming it (:class:`LawError`).

A law of a scene's ``imports`` (a controller, a stage law, a friction law, a drive kind) runs inside the model's
call: compiled (an exception cannot leave its C function: the call runs again interpreted, where the law raises it
again: ``Pipeline.failed_call``), as a declared Python stage (its exception kept and re-raised after the call:
:mod:`.abi`) or interpreted. Wherever the exception surfaces, :func:`law_error` finds the law in its traceback (the
innermost frame of a registered law's own code, a law defined outside this package: the package's own laws raising
is a bug of ours, left as it is; else the law the package's call of it was calling, :func:`raised_calling`: a wrong
signature) and gives a :class:`LawError`: the law's kind and name, its file and line (the
traceback's innermost line in the law's file), the exception's type and message and the simulated time when known;
the exception is its ``__cause__``. A law that returned NaN or ±inf is found by the call run again interpreted with
its laws' results checked (:func:`.abi.checking_laws`) and named with what it returned and at what inputs
(:func:`non_finite_error`).
"""

from __future__ import annotations

import math
import sys
import traceback
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import ContactdynError, SimulationError
from .params import departs

__all__ = ["LawError", "law_error", "naming_laws", "non_finite_error", "no_command_error", "is_users", "law_file",
           "raised_calling", "counted_states", "checked_config", "unusable_friction_error", "kinetic_coefficient",
           "checked_flags", "checked_affine_in_forces"]

PACKAGE = __name__.split(".")[0] + "."  #: "contactdyn.": the package's own laws are not a user's
_CALLING = "_contactdyn_calling"  #: an exception's attribute: (kind, class) of the law whose call raised it


class LawError(SimulationError):
    """A user's law failed in a run: ``t = 0.0202 s: controller 'myctl' (ctlmod.py, line 13) raised ValueError:
    my controller gave up``. ``kind`` (controller, stage law, friction law, drive kind), ``name``, ``file`` (its
    path), ``what`` it did, ``line`` (None: not known), ``t`` [s] (None: not known)."""

    def __init__(self, kind: str, name: str, file: str, what: str, line: int | None = None, t: float | None = None):
        self.kind, self.name, self.file, self.what, self.line, self.t = kind, name, file, what, line, t
        when = f"t = {t:.6g} s: " if t is not None else ""
        where = Path(file).name + (f", line {line}" if line else "")
        super().__init__(f"{when}{kind} {name!r} ({where}) {what}")

    def adding(self, words: str) -> LawError:
        """The same error with ``words`` after what the law did (what the run then did)."""
        return LawError(self.kind, self.name, self.file, f"{self.what}; {words}", self.line, self.t)


def is_users(cls: type) -> bool:
    """A class defined outside this package (a researcher's law, or a test's)."""
    module = getattr(cls, "__module__", None) or ""
    return module != "builtins" and not module.startswith(PACKAGE)


def law_file(cls: type) -> str:
    """The file that defines law class ``cls`` (its module's name where it has none)."""
    return getattr(sys.modules.get(cls.__module__), "__file__", None) or cls.__module__


def raised_calling(exc: BaseException, law: tuple[str, type] | None) -> None:
    """Mark ``exc`` as raised where the package called ``law`` ((kind, class); None: nothing to mark), for
    :func:`law_error`: the law it names where no frame of a law's code is in the traceback (a wrong signature). The
    innermost call's mark stays."""
    if law is not None and not hasattr(exc, _CALLING):
        setattr(exc, _CALLING, law)


def law_error(exc: BaseException, t: float | None = None, law: tuple[str, type] | None = None) -> LawError | None:
    """The LawError of ``exc`` where it was raised inside a user's law's code (its traceback says), at t [s], or in
    calling ``law`` ((kind, class) of a user's law the caller called: a wrong signature, a result that does not
    unpack; else the law ``exc`` was marked raised calling, :func:`raised_calling`); else None (the package's own
    errors, which say what failed, and an error not a law's: left as they are)."""
    if isinstance(exc, ContactdynError) or not isinstance(exc, Exception):
        return None
    law = law or getattr(exc, _CALLING, None)
    codes = _law_codes()
    frames = [(frame.f_code, line) for frame, line in traceback.walk_tb(exc.__traceback__)]
    inner = [i for i, (code, _) in enumerate(frames) if code in codes]
    what = f"raised {type(exc).__name__}" + (f": {exc}" if str(exc) else "")
    if not inner:
        return LawError(law[0], law[1].name, law_file(law[1]), what, None, t) if law and is_users(law[1]) else None
    code = frames[inner[-1]][0]
    kind, cls = codes[code]
    line = [n for c, n in frames[inner[-1]:] if c.co_filename == code.co_filename][-1]  # (a helper in its file)
    return LawError(kind, cls.name, code.co_filename, what, line, t)


@contextmanager
def naming_laws(t: float | None = None):
    """Inside: an exception raised by a user's law leaves as its LawError (at t [s]), chained to it."""
    try:
        yield
    except Exception as exc:
        error = law_error(exc, t)
        if error is None:
            raise
        raise error from exc


def non_finite_error(family: str, law: type, args: tuple, value, t: float | None = None) -> LawError:
    """The LawError of a law of ``family`` ("stage", "friction"; a drive kind's "drive voltage", "drive force") that
    returned the non-finite ``value`` on ``args`` (its Python call's: :func:`.abi.call_stage`'s,
    :func:`.abi.call_friction`'s; a drive kind's with its spec's values first, :func:`.drive_abi.checking_drives`)."""
    kind, what = _NON_FINITE[family]
    return LawError(kind, law.name, law_file(law), what(law, args, value), None, t)


def unusable_friction_error(spec, contact: str, speed: float, value: float, t: float | None = None) -> LawError:
    """The LawError of the friction law of contact ``contact`` (its ``spec``, a FrictionSpec) that returned the
    coefficient ``value`` [-] at slip speed ``speed`` [m/s], negative (it pushes a slide along), NaN or ±inf (the
    run stops at the first call that gets one, compiled or interpreted:
    :meth:`~contactdyn.model.pipeline.pipeline.Pipeline.failed_call`; an impact's, :func:`kinetic_coefficient`)."""
    from .friction_laws import FRICTION_LAWS

    law = FRICTION_LAWS[spec.law]
    what = _friction_returned(law, (spec.mu_s, spec.mu_k, spec.params, speed), value)
    return LawError("friction law", law.name, law_file(law), f"{what} on contact {contact!r}: expected a finite "
                    "coefficient >= 0 (friction opposes the slip)", None, t)


def kinetic_coefficient(spec, contact: str, speed: float, t: float | None = None) -> float:
    """μ [-] of contact ``contact``'s friction ``spec`` (a FrictionSpec) at slip speed ``speed`` [m/s] at t [s]; its
    law returning μ < 0, NaN or ±inf at a finite speed is its LawError (:func:`unusable_friction_error`; at a speed
    that is not finite, an overflowed trial state's, μ is given as it is: the step is rejected)."""
    with naming_laws(t):
        mu = float(spec.mu(speed))
    if not (math.isfinite(mu) and mu >= 0.0) and math.isfinite(speed):
        raise unusable_friction_error(spec, contact, speed, mu, t)
    return mu


def _stage_returned(law: type, args: tuple, value) -> str:
    k, b, p, x, xdot = args
    return (f"returned F = {value} N at x = {x:.6g} m, ẋ = {xdot:.6g} m/s (k = {k:.6g} N/m, b = {b:.6g} N·s/m"
            f"{_params(law, p)})")


def _friction_returned(law: type, args: tuple, value) -> str:
    mu_s, mu_k, p, speed = args
    return f"returned μ = {value} at slip speed {speed:.6g} m/s (mu_s = {mu_s:.6g}, mu_k = {mu_k:.6g}{_params(law, p)})"


def _voltage_returned(kind: type, args: tuple, value) -> str:
    """u [V] for τ [N·m or N] at the coordinate's q̇ (and the motor's ω [rad/s], a kind with a motor coordinate)."""
    p, tau, qd, omega = args
    motor = f", ω = {omega:.6g} rad/s" if kind.motor_coordinate else ""
    return f"returned u = {value} V for τ = {tau:.6g} N·m or N at q̇ = {qd:.6g}{motor}{_drive_params(kind, p)}"


def _force_returned(kind: type, args: tuple, value) -> str:
    """The force on the coordinate (and the motor's torque [N·m], θ [rad], ω [rad/s] with a motor coordinate) at the
    command (a voltage [V] or a force [N·m or N]) and the coordinate's q, q̇."""
    p, command, q, qd, theta, omega = args
    unit = "V" if kind.has_voltage else "N·m or N"
    returned, at = f"force = {value[0]} N·m or N", f"command = {command:.6g} {unit}, q = {q:.6g}, q̇ = {qd:.6g}"
    if kind.motor_coordinate:
        returned += f", motor torque = {value[1]} N·m"
        at += f", θ = {theta:.6g} rad, ω = {omega:.6g} rad/s"
    return f"returned {returned} at {at}{_drive_params(kind, p)}"


#: family -> (the kind a LawError names, what the law did: (law, args, value) -> words)
_NON_FINITE = {"stage": ("stage law", _stage_returned), "friction": ("friction law", _friction_returned),
               "drive voltage": ("drive kind", _voltage_returned), "drive force": ("drive kind", _force_returned)}


def no_command_error(ctl, tau, q, v, t: float) -> SimulationError:
    """The error of controller ``ctl`` whose command τ at t [s] is not finite: its own words (``failure``: the
    package's laws', a user's law's own), else its LawError with τ [N·m, N or V] at the joints' q and v."""
    from .controllers.base import Controller

    if not is_users(type(ctl)) or type(ctl).failure is not Controller.failure:
        return SimulationError(ctl.failure(t))
    return LawError("controller", ctl.name, law_file(type(ctl)), f"gave no finite command: τ = {_listed(tau)} at "
                    f"q = {_listed(q)}, v = {_listed(v)}", None, t)


def counted_states(ctl) -> int:
    """``ctl.n_states`` as its class or its bind set it: a LawError unless an integer in [0, MAX_STATES]."""
    from .controllers.base import MAX_STATES, is_count

    if not is_count(ctl.n_states):
        raise LawError("controller", ctl.name, law_file(type(ctl)), f"set n_states = {ctl.n_states!r}: expected an "
                       f"integer in [0, {MAX_STATES}] (the count of its own states)")
    return int(ctl.n_states)


def checked_flags(ctl) -> None:
    """``ctl``'s flags (``uses_forces``, ``needs_gravity``, ``reads_orientation``) as its class or its bind set them: a
    LawError unless each is True or False (its class's are checked where it registers: laws.params)."""
    from .controllers.base import Controller
    from .params import non_bool_flag

    wrong = non_bool_flag(ctl, Controller)
    if wrong:
        raise LawError("controller", ctl.name, law_file(type(ctl)), f"set {wrong[0]} = {wrong[1]!r}: expected True or "
                       "False")


#: the measured forces [N] (each alone, then all at once, in turn) at which a force-reading law's affinity is tried
_TRIED_FORCES = (-2.5, 40.0)


def checked_affine_in_forces(ctl, inp) -> None:
    """``ctl`` (a bound controller that declares ``uses_forces``) affine in the forces it reads at ``inp`` (a
    ControlInput of its phase): its command (τ [N·m, N or V] and ż) at each measured force (``forces`` [N] per key,
    ``tau_contact`` [N·m or N] per joint) moved alone, then at all moved at once, is τ₀ + B F, τ₀ its command at
    ``inp`` and B its differences at +1 (the fold's columns: the solve folds the forces in by them); else a LawError
    naming where. What cannot be tried is not refused (the command raises or gives no finite numbers there)."""
    n_tau = 0 if inp.tau_contact is None else len(inp.tau_contact)
    keys = [("forces", key) for key in inp.forces] + [("tau_contact", i) for i in range(n_tau)]

    def command(moved: dict) -> np.ndarray:
        forces = {key: inp.forces[key] + moved.get(("forces", key), 0.0) for key in inp.forces}
        tau_c = None if inp.tau_contact is None else inp.tau_contact + [moved.get(("tau_contact", i), 0.0)
                                                                         for i in range(n_tau)]
        tau, rates = ctl.command(inp.replaced(forces=forces, tau_contact=tau_c))
        return np.concatenate([np.asarray(tau, float).ravel(), np.asarray(() if rates is None else rates, float)])

    together = {key: _TRIED_FORCES[k % len(_TRIED_FORCES)] for k, key in enumerate(keys)}
    tries = [{key: a} for key in keys for a in _TRIED_FORCES] + ([together] if len(keys) > 1 else [])
    try:
        base = command({})
        B = {key: command({key: 1.0}) - base for key in keys}
        got = [(moved, command(moved)) for moved in tries]
    except Exception:  # noqa: BLE001 (a user's law: whatever it raises, the check gives up)
        return
    if any(y.shape != base.shape for y in (*B.values(), *(y for _, y in got))):
        return  # (a command whose size changes: the run's own check names it)
    for moved, y in got:
        affine = base + sum(a * B[key] for key, a in moved.items())
        scale = np.abs(base) + sum(np.abs(a * B[key]) for key, a in moved.items())
        wrong = [i for i in range(y.size) if departs(y[i], affine[i], scale[i])]
        if np.all(np.isfinite(y)) and np.all(np.isfinite(affine)) and wrong:
            said = _not_affine_in_forces(ctl.nv, moved, y, affine, wrong[0])
            raise LawError("controller", ctl.name, law_file(type(ctl)), said)


def _not_affine_in_forces(nv: int, moved: dict, y: np.ndarray, affine: np.ndarray, first: int) -> str:
    """What a force-reading law did where its command (τ, then ż: ``y``) is not ``affine`` at the forces ``moved``
    ((field, key) -> its value [N, or N·m or N]; ``first``: the first entry that differs)."""
    forces = [f"forces[{key!r}] = {a:g} N" for (field, key), a in moved.items() if field == "forces"]
    tau_c = [a for (field, _), a in moved.items() if field == "tau_contact"]
    if len(moved) == 1 and tau_c:
        forces = [f"tau_contact[{next(iter(moved))[1]}] = {tau_c[0]:g} N·m or N"]
    elif tau_c:
        forces.append(f"tau_contact = {_listed(tau_c)} N·m or N")
    at = ", ".join(forces) + (" (all at once)" if len(moved) > 1 else "")
    part, name, zero, column = (slice(0, nv), "τ", "τ₀", "B") if first < nv else (slice(nv, None), "ż", "ż₀", "D")
    return (f"declares uses_forces = True, but its command at {at} gives {name} = {_listed(y[part])}, not {zero} + "
            f"{column} F = {_listed(affine[part])} ({zero}, {column}: its command at forces 0 and its differences at "
            "1): expected a command affine in the forces it reads (the solve folds them in)")


def checked_config(kind: str, config):
    """``config``, what controller ``kind``'s ``read`` returned: a LawError unless it has a registered kind (the
    system builds the controller of ``config.kind``)."""
    from .controllers.base import CONTROLLERS

    if not isinstance(getattr(config, "kind", None), str) or config.kind not in CONTROLLERS:
        raise LawError("controller", kind, law_file(CONTROLLERS[kind]), f"read returned {type(config).__name__}: "
                       "expected a config with the kind of its controller (Controller.read gives a DeclaredConfig)")
    return config


def _listed(values) -> str:
    """Numbers as a short list: [0.1, nan]."""
    return "[" + ", ".join(f"{float(v):.6g}" for v in values) + "]"


def _params(law: type, p) -> str:
    """", name = value" per declared parameter of ``law`` (its values ``p``)."""
    return "".join(f", {param.name} = {float(v):.6g}" for param, v in zip(law.params, p, strict=False))


def _drive_params(kind: type, p) -> str:
    """" (name = value, ...)" of a drive kind's declared parameters (its spec's values ``p``, first), or ""."""
    listed = _params(kind, p)[2:]
    return f" ({listed})" if listed else ""


def _law_codes() -> dict:
    """code object -> (kind, law class) of every function of the registered users' laws (their own bases' too)."""
    from .controllers.base import CONTROLLERS
    from .drive_kinds import DRIVE_KINDS
    from .friction_laws import FRICTION_LAWS
    from .stage_laws import STAGE_LAWS

    out: dict = {}
    for kind, registry in (("controller", CONTROLLERS), ("stage law", STAGE_LAWS), ("friction law", FRICTION_LAWS),
                           ("drive kind", DRIVE_KINDS)):
        for cls in filter(is_users, registry.values()):
            for base in filter(is_users, cls.__mro__):
                for value in vars(base).values():
                    code = _code(value)
                    if code is not None:
                        out.setdefault(code, (kind, cls))
    return out


def _code(value):
    """The code object of a class attribute that is a function (a static or class method, a property's getter, a
    numba dispatcher's Python function), else None."""
    fn = value.fget if isinstance(value, property) else getattr(value, "__func__", value)
    return getattr(getattr(fn, "py_func", fn), "__code__", None)
