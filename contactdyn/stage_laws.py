"""Stage laws: the force of one deformation stage at its compression and compression rate.

A stage of a deformation chain (:mod:`contactdyn.chain`) between a lower node (nearer the
environment) and an upper node (nearer the tip) has compression x = s_lower − s_upper [m]
and rate ẋ [m/s]; its force F [N] pushes the upper node along the chain's direction +u.
The laws (``law = "<name>"`` on a stage in a scene):

- ``linear`` — Kelvin–Voigt, Part I's stage: F = k x + b ẋ (k [N/m], b [N·s/m]). Affine.
- ``hunt_crossley`` — F = max(k xⁿ + b xⁿ ẋ, 0) in compression (x > 0), else 0
  (k [N/mⁿ], b [N·s/mⁿ⁺¹], n = ``exponent``): never pulls, no force jump at touch.

Adding a law: subclass :class:`StageLaw` (``name``, ``affine``, ``uses_exponent``, a
``force``) and decorate it with :func:`register_stage_law`; the scene then accepts its
name. An ``affine`` law runs on the compiled right-hand side by construction (its force is
read off by unit probes, :mod:`contactdyn.plan_probe`); another declares so at load
(:mod:`contactdyn.fastpath`) and its touching modes run on the readable model. A law
other than ``linear`` needs a solid node (tip, mass or body) at both ends of its stage.
See ``docs/architecture.md`` for a worked example.
"""

from __future__ import annotations

from typing import ClassVar

__all__ = ["StageLaw", "STAGE_LAWS", "register_stage_law", "Linear", "HuntCrossley"]


class StageLaw:
    """A stage's force law F(x, ẋ) [N]; parameters k, b and the exponent n come from the scene."""

    name: ClassVar[str] = ""
    affine: ClassVar[bool] = False  #: F is affine in (x, ẋ): the compiled plan reads it off by probes
    uses_exponent: ClassVar[bool] = False  #: the scene reads ``exponent`` (1 ≤ n ≤ 3) for this law

    @staticmethod
    def force(k: float, b: float, n: float, x: float, xdot: float) -> float:
        """Compressive force [N] at compression x [m] and rate ẋ [m/s]."""
        raise NotImplementedError

    @staticmethod
    def potential(k: float, n: float, x: float) -> float | None:
        """Energy [J] stored at compression x [m] (the integral of the law's elastic part), None if not known
        (the run's energy check then says so: :mod:`contactdyn.physics_checks`)."""
        return None


STAGE_LAWS: dict[str, type[StageLaw]] = {}  #: name -> law, the ``law`` values a scene accepts


def register_stage_law(cls: type[StageLaw]) -> type[StageLaw]:
    """Make ``cls`` a law scenes can name (``law = cls.name``)."""
    STAGE_LAWS[cls.name] = cls
    return cls


@register_stage_law
class Linear(StageLaw):
    name = "linear"
    affine = True

    @staticmethod
    def force(k: float, b: float, n: float, x: float, xdot: float) -> float:
        return k * x + b * xdot

    @staticmethod
    def potential(k: float, n: float, x: float) -> float:
        return 0.5 * k * x * x


@register_stage_law
class HuntCrossley(StageLaw):
    name = "hunt_crossley"
    uses_exponent = True

    @staticmethod
    def force(k: float, b: float, n: float, x: float, xdot: float) -> float:
        if x <= 0.0:  # acts only in compression and never pulls
            return 0.0
        xn = x**n
        return max(k * xn + b * xn * xdot, 0.0)

    @staticmethod
    def potential(k: float, n: float, x: float) -> float:
        return k * x ** (n + 1.0) / (n + 1.0) if x > 0.0 else 0.0
