"""A law's declared parameter: name, unit, default, bounds and meaning, written once.

Stage laws (:mod:`contactdyn.laws.stage_laws`), friction laws (:mod:`contactdyn.laws.friction_laws`)
and drive kinds (:mod:`contactdyn.laws.drives`) declare their parameters as :class:`Param`
tuples. The scene reader reads them from the declaration (:func:`read_params`: the bounds
and the unit in the error message), the key reference (``docs/scenes.md``,
``contactdyn list keys``) shows their meaning from it, and the tour of the reader
(:mod:`contactdyn.scene.keytour`) writes an example of each from :attr:`Param.example`. A user's
law gets all of that by declaring its parameters the same way.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..scene.reader import Reader

__all__ = ["Param", "read_params", "with_defaults", "claim_name", "check_declaration", "non_bool_flag", "departs"]

#: a value departs from the affine form a law declares where it differs by more than AFFINE_RTOL × the form's terms'
#: sizes + AFFINE_ATOL (in the value's unit): rounding, not a law's curvature
AFFINE_RTOL, AFFINE_ATOL = 1e-9, 1e-12


@dataclass(frozen=True)
class Param:
    """One parameter of a law, as a scene names it."""

    name: str  #: the scene key
    unit: str  #: e.g. "N/m", "-" for a pure number
    meaning: str  #: one line for the key reference
    default: float | None = None  #: None: the scene must give it
    lo: float = 0.0  #: lower bound
    hi: float | None = None  #: upper bound (None: none)
    lo_open: bool = False  #: the lower bound itself is not allowed
    example: float | None = None  #: a value for the reader's tour (default: the default, else a value in bounds)
    same_as: str | None = None  #: default: the value of that parameter of the same law (C_E = C_M); default is None

    def read(self, r: Reader, key: str | None = None) -> float:
        """This parameter's value from the table of ``r`` (under ``key``, default its own name), checked."""
        from ..scene.reader import MISSING

        required = self.default is None and self.same_as is None  # a same_as parameter reads None when absent
        return r.float(key or self.name, MISSING if required else self.default, lo=self.lo, hi=self.hi,
                       lo_open=self.lo_open, unit="" if self.unit == "-" else self.unit, meaning=self.meaning)

    def sample(self) -> float:
        """A valid value of this parameter (for the reader's tour and the tests)."""
        if self.example is not None:
            return self.example
        if self.default is not None and math.isfinite(self.default):
            return self.default
        return self.lo + 1.0 if self.hi is None else 0.5 * (self.lo + self.hi)


def read_params(r: Reader, params: tuple[Param, ...]) -> tuple[float, ...]:
    """The declared parameters' values, in declaration order."""
    return tuple(with_defaults(params, {p.name: value for p in params if (value := p.read(r)) is not None}).values())


def with_defaults(params: tuple[Param, ...], given: dict[str, float]) -> dict[str, float]:
    """Every declared parameter's value, in declaration order: the given one, else its default, else the value of
    the parameter it is the same as. A required parameter not given raises KeyError naming it."""
    values = {p.name: given[p.name] if p.name in given else p.default for p in params}
    for p in params:
        if values[p.name] is None and p.same_as is not None:
            values[p.name] = values[p.same_as]
        if values[p.name] is None:
            raise KeyError(p.name)
    return values


def claim_name(registry: dict, cls: type, family: str) -> None:
    """Register ``cls`` under its name in its family's ``registry`` (stage laws, friction laws, drive kinds,
    controllers). A name is one law: a class of another module under a name already taken (a second user file with
    the same law name, or one named as a built-in) is refused with both files named, since a scene names its law by
    name alone and would silently run the other. The same module registering again (its file imported anew) replaces
    its own."""
    taken = registry.get(cls.name)
    if taken is not None and taken.__module__ != cls.__module__:
        def where(c: type) -> str:
            return getattr(sys.modules.get(c.__module__), "__file__", None) or c.__module__
        raise ValueError(f"{family} {cls.name!r} of {where(cls)} is already registered by {where(taken)}: "
                         f"give it another name")
    registry[cls.name] = cls


def check_declaration(cls: object, family: str, base: type, reserved: tuple[str, ...], read_defaults: bool = True
                      ) -> None:
    """A law's class as its family's register takes it (``family``: "controller", "stage law", ...): a subclass of
    ``base`` named by an identifier, its ``params`` a tuple of :class:`Param` named each once and none of
    ``reserved`` (the keys of the tables the law is read from: the table would give one value to both, or read the
    key as the wrong type), each with bounds that hold a value and its example in them, and its default too where the
    reader checks the defaults (``read_defaults``; a drive kind's default may be a value a scene cannot write: 0, no
    wheel), and its flags (``base``'s bool attributes: ``affine``, ``constant``, ``uses_forces``, ...) a bool each;
    else a ValueError naming it."""
    if not isinstance(cls, type) or not issubclass(cls, base):
        raise ValueError(f"a {family} must subclass contactdyn.laws.{base.__name__}, got {cls!r}")
    if not isinstance(cls.name, str) or not cls.name.isidentifier():
        raise ValueError(f"a {family}'s name must be an identifier, got {cls.name!r}")
    params = cls.params
    if not isinstance(params, tuple | list) or not all(isinstance(p, Param) for p in params):
        raise ValueError(f"{family} {cls.name!r}: params must be a tuple of Param, got {params!r}")
    names = [p.name for p in params]
    if len(set(names)) != len(names):
        raise ValueError(f"{family} {cls.name!r}: parameter names must be unique, got {names}")
    clash = [n for n in names if n in reserved]
    if clash:
        raise ValueError(f"{family} {cls.name!r}: parameter {clash[0]!r} is named like a key of the table it is read "
                         f"from (the table would give one value to both): give it another name")
    for p in params:
        problem = _bounds_problem(p, read_defaults)
        if problem:
            raise ValueError(f"{family} {cls.name!r}: parameter {p.name!r} {problem}")
    wrong = non_bool_flag(cls, base)
    if wrong:  # (a flag's truth decides the physics: "no" would read as True)
        raise ValueError(f"{family} {cls.name!r}: {wrong[0]} must be True or False, got {wrong[1]!r}")


def departs(value: float, affine: float, scale: float) -> bool:
    """Does ``value`` depart from ``affine``, the affine form a law declares, beyond rounding: by more than
    AFFINE_RTOL × ``scale`` (the sizes of the form's terms) + AFFINE_ATOL? A NaN departs. (A stage law's ``affine``, a
    drive kind's voltage, a force-reading controller's command are checked by it.)"""
    return not abs(value - affine) <= AFFINE_RTOL * scale + AFFINE_ATOL


def non_bool_flag(law: object, base: type) -> tuple[str, object] | None:
    """(name, value) of the first flag a family's ``base`` declares (its class attributes that are a bool:
    ``affine``, ``constant``, ``uses_forces``, ``motorized``, ...) that ``law`` (a law's class, or a bound law) holds
    as something other than True or False; None where each is a bool."""
    for name in [name for k in reversed(base.__mro__) for name, value in vars(k).items() if isinstance(value, bool)]:
        value = getattr(law, name)
        if not isinstance(value, bool):
            return name, value
    return None


def _bounds_problem(p: Param, read_default: bool) -> str:
    """What is wrong with a parameter's bounds, default (``read_default``: the reader checks it) or example (a scene
    that leaves it out would fail on a key it never wrote; ``contactdyn new`` would write a value its reader
    refuses), or ""."""
    if p.hi is not None and not p.lo <= p.hi:
        return f"has lo = {p.lo:g} > hi = {p.hi:g}: no value is in its bounds"
    for what, value in (("default", p.default if read_default else None), ("example", p.example)):
        if value is None:
            continue
        inside = value > p.lo if p.lo_open else value >= p.lo
        if math.isnan(value) or not inside or (p.hi is not None and value > p.hi):
            bounds = f"{'(' if p.lo_open else '['}{p.lo:g}, {'inf)' if p.hi is None else f'{p.hi:g}]'}"
            return (f"has {what} {value:g} outside its bounds {bounds} (lo = 0 unless declared): declare lo and hi "
                    f"around it")
    return ""
