"""Stage laws: the force of one deformation stage at its compression and compression rate.

A stage of a deformation chain (:mod:`contactdyn.model.chain`) between a lower node (nearer the
environment) and an upper node (nearer the tip) has compression x = s_lower − s_upper [m]
and rate ẋ [m/s]; its force F [N] pushes the upper node along the chain's direction +u.
Every stage has a stiffness k and a damping b; a law declares its own further parameters
(:class:`~contactdyn.laws.params.Param`: name, unit, default, bounds, meaning) and the scene
reads them from the declaration. The laws (``law = "<name>"`` on a stage in a scene):

- ``linear`` — Kelvin–Voigt, Part I's stage: F = k x + b ẋ (k [N/m], b [N·s/m]). Affine.
- ``hunt_crossley`` — F = max(k xⁿ + b xⁿ ẋ, 0) in compression (x > 0), else 0
  (k [N/mⁿ], b [N·s/mⁿ⁺¹], n = ``exponent``): never pulls, no force jump at touch.

Adding a law: subclass :class:`StageLaw` (``name``, ``params``, ``affine``, a ``force``)
and decorate it with :func:`register_stage_law`; the scene then accepts its name and its
parameters. Its properties decide the physics, never its name: every law whose ``force`` numba compiles runs on
the compiled call by address (:mod:`contactdyn.laws.abi`; one that does not is a declared Python stage of it,
called back through ctypes); an ``affine`` law (F = K x + B ẋ, :meth:`StageLaw.coefficients`) may also sit at a
massless junction and gives the dynamic laws and the sanity check their nominal model; another needs a solid node
(tip, mass or body) at both ends of its stage.
See ``docs/architecture.md`` for a worked example.
"""

from __future__ import annotations

from typing import ClassVar

from .params import Param, check_declaration, claim_name, departs

__all__ = ["StageLaw", "STAGE_LAWS", "register_stage_law", "kelvin_voigt", "Linear", "HuntCrossley"]


class StageLaw:
    """A stage's force law F(x, ẋ) [N]; k, b and the law's own ``params`` (values ``p``, in order) from the scene."""

    name: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()  #: the law's parameters besides k and b
    affine: ClassVar[bool] = False  #: F = K x + B ẋ with (K, B) = coefficients(k, b, p): junction-safe
    #: why numba cannot compile ``force`` ("" when it can; None until first asked, :mod:`contactdyn.laws.abi`):
    #: the model then calls it in Python
    compiled_reason: ClassVar[str | None] = None

    @staticmethod
    def force(k: float, b: float, p: tuple[float, ...], x: float, xdot: float) -> float:
        """Compressive force [N] at compression x [m] and rate ẋ [m/s]."""
        raise NotImplementedError

    @staticmethod
    def coefficients(k: float, b: float, p: tuple[float, ...]) -> tuple[float, float]:
        """(K [N/m], B [N·s/m]) of an affine law, F = K x + B ẋ (the default: the stage's k and b)."""
        return k, b

    @staticmethod
    def potential(k: float, p: tuple[float, ...], x: float) -> float | None:
        """Energy [J] stored at compression x [m] (the integral of the law's elastic part), None if not known
        (the run's energy check then says so: :mod:`contactdyn.output.physics_checks`)."""
        return None


STAGE_LAWS: dict[str, type[StageLaw]] = {}  #: name -> law, the ``law`` values a scene accepts
#: the keys of the tables a stage is read from (a contact's normal or tangent table, a chain's element), which no law
#: parameter may take
TABLE_KEYS = ("k", "b", "law", "m", "model", "direction", "directions", "k_int", "b_int", "k_ext", "b_ext",
              "environment", "robot", "mu", "mu_s", "mu_k", "viscous")


def register_stage_law(cls: type[StageLaw]) -> type[StageLaw]:
    """Make ``cls`` a law scenes can name (``law = cls.name``)."""
    check_declaration(cls, "stage law", StageLaw, TABLE_KEYS)
    problem = _not_affine(cls) if cls.affine else ""
    if problem:
        raise ValueError(f"stage law {cls.name!r}: affine = True, but {problem}: declare affine = False")
    claim_name(STAGE_LAWS, cls, "stage law")
    return cls


#: (k [N/m], b [N·s/m]) and the (x [m], ẋ [m/s]) at which an affine declaration is tried (both signs: a junction's
#: stage is stretched too)
_TRIED_KB, _TRIED_AT = (1000.0, 10.0), ((-0.01, 0.0), (0.0, -0.3), (0.002, 0.0), (0.0, 0.2), (0.05, -0.3),
                                        (-0.02, 0.4))


def _not_affine(cls: type[StageLaw]) -> str:
    """Where an affine law's ``force`` is not K x + B ẋ, (K, B) = ``coefficients(k, b, p)``, at its parameters' sample
    values (:meth:`Param.sample`), or "" (also where a call raises: what cannot be tried is not refused; the run names
    the law if it raises there). Short: the import's error quotes it (scene.user_laws)."""
    k, b = _TRIED_KB
    p = tuple(param.sample() for param in cls.params)
    try:
        K, B = map(float, cls.coefficients(k, b, p))
        tried = [(x, xdot, float(cls.force(k, b, p, x, xdot))) for x, xdot in _TRIED_AT]
    except Exception:  # noqa: BLE001 (a user's law: whatever it raises, the check gives up)
        return ""
    for x, xdot, F in tried:
        if departs(F, K * x + B * xdot, abs(K * x) + abs(B * xdot)):
            at = "".join(f", {q.name} = {v:g}" for q, v in zip(cls.params, p, strict=True))
            return (f"its force at x = {x:g} m, ẋ = {xdot:g} m/s is {F:g} N, not K x + B ẋ = {K * x + B * xdot:g} N "
                    f"(k = {k:g}, b = {b:g}{at})")
    return ""


def kelvin_voigt(law: str, k: float, b: float, p: tuple[float, ...]) -> tuple[float, float] | None:
    """(K [N/m], B [N·s/m]) of a stage under the registered law ``law`` when it is affine, F = K x + B ẋ; None
    otherwise."""
    cls = STAGE_LAWS[law]
    return cls.coefficients(k, b, p) if cls.affine else None


@register_stage_law
class Linear(StageLaw):
    name = "linear"
    affine = True

    @staticmethod
    def force(k: float, b: float, p: tuple[float, ...], x: float, xdot: float) -> float:
        return k * x + b * xdot

    @staticmethod
    def potential(k: float, p: tuple[float, ...], x: float) -> float:
        return 0.5 * k * x * x


@register_stage_law
class HuntCrossley(StageLaw):
    name = "hunt_crossley"
    params = (Param("exponent", "-", "n of the Hunt-Crossley law F = k x^n + b x^n x'", 1.5, lo=1.0, hi=3.0),)

    @staticmethod
    def force(k: float, b: float, p: tuple[float, ...], x: float, xdot: float) -> float:
        if x <= 0.0:  # acts only in compression and never pulls
            return 0.0
        xn = x ** p[0]
        return max(k * xn + b * xn * xdot, 0.0)

    @staticmethod
    def potential(k: float, p: tuple[float, ...], x: float) -> float:
        n = p[0]
        return k * x ** (n + 1.0) / (n + 1.0) if x > 0.0 else 0.0
