"""Friction laws: the coefficients of a friction contact, declared once and used at every place friction acts.

A contact with ``tangent.model = "friction"`` names a law (``tangent.law``, default
``coulomb``). A law gives two things (:class:`FrictionLaw`):

- the static coefficient μ_s [-]: a stuck contact holds while |F_f| ≤ μ_s F (the cone, the
  slip event, an impact's jamming test);
- the kinetic coefficient at the slip speed, μ(|v_t|) [-] with |v_t| [m/s]: a sliding contact
  feels F_f = −μ(|v_t|) F d − c v_t (the tilt of a bonded contact's normal column, the chain's
  known force, the impact's sliding impulse at the slip speed before it, the samples, the
  physics checks), c the viscous coefficient [N·s/m].

The laws:

- ``coulomb`` — μ(v) = μ_k: the paper's law (eqs 21–24, 43–44); ``mu`` sets μ_s = μ_k.
- ``stribeck`` — μ(v) = μ_k + (μ_s − μ_k) exp(−(v/v_s)²), v_s [m/s] the Stribeck speed:
  the coefficient falls from μ_s at rest to μ_k when sliding fast.

A law with a constant kinetic coefficient (``constant = True``) is a constant of the compiled call; another is
called by address per call (its ``coefficient`` compiled, :mod:`contactdyn.laws.abi`); one numba cannot compile
is a declared Python stage of the compiled call (called back through ctypes). Adding a law:
subclass :class:`FrictionLaw` (``name``, ``params``, ``constant``, and ``coefficient(mu_s, mu_k, p, speed)``,
the numeric form that :mod:`contactdyn.laws.abi` compiles; ``kinetic(spec, speed)`` gives it a contact's
spec, and a law may override that one instead, in Python only) and decorate
it with :func:`register_friction_law`; the scene then accepts ``tangent.law = "<name>"``
and the parameters it declares (:class:`~contactdyn.laws.params.Param`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from .params import Param, check_declaration, claim_name, read_params

__all__ = ["FrictionLaw", "FrictionSpec", "FRICTION_LAWS", "register_friction_law", "Coulomb", "Stribeck",
           "MU", "MU_S", "MU_K", "VISCOUS"]

MU_S = Param("mu_s", "-", "static friction coefficient (>= mu_k): a stuck contact holds while |F_f| <= mu_s F")
MU_K = Param("mu_k", "-", "kinetic friction coefficient: a sliding contact feels mu_k F (Stribeck: when fast)")
VISCOUS = Param("viscous", "N·s/m", "viscous friction c: F_f = -mu F d - c v", 0.0)
MU = Param("mu", "-", "friction coefficient, static and kinetic (mu_s = mu_k = mu)")  #: Coulomb's shorthand


@dataclass(frozen=True)
class FrictionSpec:
    """A contact's friction as the scene gave it: the static and kinetic coefficients and the law that joins them."""

    mu_s: float  #: static coefficient [-]
    mu_k: float  #: kinetic coefficient [-] (the law's value when sliding fast)
    viscous: float = 0.0  #: viscous coefficient c [N·s/m]
    law: str = "coulomb"  #: a name in FRICTION_LAWS
    params: tuple[float, ...] = ()  #: the law's own parameters, in its declared order
    #: (the law by name, not a class: a spec pickled to a sweep's worker needs the law's module imported there
    #: first, which reading the scene does)

    @property
    def constant(self) -> bool:
        """The kinetic coefficient is μ_k at every slip speed (both paths then read μ_k, no law call)."""
        return FRICTION_LAWS[self.law].constant

    def mu(self, speed):
        """Kinetic coefficient [-] at slip speed |v_t| [m/s] (a float, or an array of speeds)."""
        return FRICTION_LAWS[self.law].kinetic(self, speed)


class FrictionLaw:
    """A friction law: the kinetic coefficient as a function of the slip speed; μ_s, μ_k and c are every law's."""

    name: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()  #: the law's own parameters besides mu_s, mu_k and viscous
    constant: ClassVar[bool] = False  #: μ(v) = μ_k for every v

    #: why numba cannot compile the law's ``coefficient`` ("" when it can; None until first asked,
    #: :mod:`contactdyn.laws.abi`): the model then calls it in Python
    compiled_reason: ClassVar[str | None] = None

    @staticmethod
    def coefficient(mu_s: float, mu_k: float, p, speed):
        """μ(|v_t|) [-] at slip speed ``speed`` [m/s] (float or array) from μ_s, μ_k [-] and the law's own
        parameters ``p`` (declared order): the law's numeric form, compiled for the model (laws.abi)."""
        raise NotImplementedError

    @classmethod
    def kinetic(cls, spec: FrictionSpec, speed):
        """μ(|v_t|) [-] at slip speed ``speed`` [m/s] (float or array) of a contact's ``spec``: its
        :meth:`coefficient`. A law may override this instead (in Python only: it then is not compiled)."""
        return cls.coefficient(spec.mu_s, spec.mu_k, spec.params, speed)

    @classmethod
    def read(cls, r) -> FrictionSpec:
        """The contact's ``tangent`` table: μ_s, μ_k (μ_s ≥ μ_k), viscous and the law's own parameters."""
        return cls._spec(r, MU_S.read(r), MU_K.read(r))

    @classmethod
    def _spec(cls, r, mu_s: float, mu_k: float) -> FrictionSpec:
        """The spec from μ_s ≥ μ_k (checked), the viscous c and the law's own parameters read from ``r``."""
        if mu_s < mu_k:
            raise r.error("mu_s", f"a static coefficient >= mu_k = {mu_k}", mu_s)
        return FrictionSpec(mu_s, mu_k, VISCOUS.read(r), cls.name, read_params(r, cls.params))


FRICTION_LAWS: dict[str, type[FrictionLaw]] = {}  #: name -> law, the ``tangent.law`` values a scene accepts
#: the keys of a contact's tangent table, which no law parameter may take
TABLE_KEYS = ("model", "directions", "law", "mu", "mu_s", "mu_k", "viscous", "environment", "robot")


def register_friction_law(cls: type[FrictionLaw]) -> type[FrictionLaw]:
    """Make ``cls`` a law scenes can name (``tangent.law = cls.name``)."""
    check_declaration(cls, "friction law", FrictionLaw, TABLE_KEYS)
    problem = _not_constant(cls) if cls.constant else ""
    if problem:
        raise ValueError(f"friction law {cls.name!r}: constant = True, but {problem}: declare constant = False")
    claim_name(FRICTION_LAWS, cls, "friction law")
    return cls


_TRIED_MU, _TRIED_SPEEDS = (0.8, 0.5), (0.0, 1e-4, 0.01, 0.1, 1.0, 10.0)  #: (μ_s, μ_k), slip speeds [m/s] tried


def _not_constant(cls: type[FrictionLaw]) -> str:
    """Where a constant law's coefficient is not μ_k (the model then reads μ_k, not the law) at its parameters'
    sample values (:meth:`Param.sample`), or "" (also where a call raises: what cannot be tried is not refused)."""
    spec = FrictionSpec(*_TRIED_MU, 0.0, cls.name, tuple(p.sample() for p in cls.params))
    try:
        tried = [(v, float(cls.kinetic(spec, v))) for v in _TRIED_SPEEDS]
    except Exception:  # noqa: BLE001 (a user's law: whatever it raises, the check gives up)
        return ""
    for speed, mu in tried:
        if not abs(mu - spec.mu_k) <= 1e-12:
            at = "".join(f", {q.name} = {v:g}" for q, v in zip(cls.params, spec.params, strict=True))
            return f"its mu at slip speed {speed:g} m/s is {mu:g}, not mu_k = {spec.mu_k:g} (mu_s = {spec.mu_s:g}{at})"
    return ""


@register_friction_law
class Coulomb(FrictionLaw):
    name = "coulomb"
    constant = True

    @staticmethod
    def coefficient(mu_s: float, mu_k: float, p, speed):
        return mu_k + 0.0 * speed

    @classmethod
    def read(cls, r) -> FrictionSpec:
        """``mu`` (μ_s = μ_k), or ``mu_s`` and ``mu_k`` (either defaults to ``mu``; μ_s to μ_k)."""
        got = {p.name: p.read(r) if r.has(p.name) else None for p in (MU, MU_K, MU_S)}
        if got["mu"] is None and got["mu_k"] is None:
            raise r.missing("mu", "a friction coefficient (mu, or mu_s and mu_k)")
        mu_k = got["mu_k"] if got["mu_k"] is not None else got["mu"]
        mu_s = got["mu_s"] if got["mu_s"] is not None else (got["mu"] if got["mu"] is not None else mu_k)
        return cls._spec(r, mu_s, mu_k)


@register_friction_law
class Stribeck(FrictionLaw):
    name = "stribeck"
    params = (Param("v_s", "m/s", "Stribeck speed: mu(v) = mu_k + (mu_s - mu_k) exp(-(v/v_s)^2)", lo=0.0,
                    lo_open=True, example=0.01),)

    @staticmethod
    def coefficient(mu_s: float, mu_k: float, p, speed):
        return mu_k + (mu_s - mu_k) * np.exp(-(speed / p[0]) ** 2)
