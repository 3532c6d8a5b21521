"""Contact-zone elements as a scene names them: deformation stages and equivalent masses.

Part I's models of the contact zone are chains of these along one direction
(:mod:`contactdyn.model.chain` compiles them). A stage is Kelvin–Voigt, F = k x + b ẋ [N] at
compression x [m] (linear), or Hunt–Crossley, F = k xⁿ + b xⁿ ẋ; a mass is an equivalent
mass of the zone [kg]. Plain frozen data: the scene reads them, the chain and the
controllers that need a contact's equivalent model (:mod:`contactdyn.laws.controllers.dynamic`)
use them, and this module imports neither. The laws are in :mod:`contactdyn.laws.stage_laws`.
"""

from __future__ import annotations

from dataclasses import dataclass

from .stage_laws import STAGE_LAWS, kelvin_voigt

__all__ = ["STAGE_LAWS", "Stage", "Mass", "Element", "ChainSpec"]


@dataclass(frozen=True)
class Stage:
    """A deformation stage: F = k x + b ẋ (linear), k xⁿ + b xⁿ ẋ (Hunt–Crossley), or another registered law."""

    k: float  #: stiffness [N/m] (Hunt–Crossley: [N/mⁿ])
    b: float  #: damping [N·s/m] (Hunt–Crossley: [N·s/mⁿ⁺¹])
    law: str = "linear"  #: a name in STAGE_LAWS (contactdyn.laws.stage_laws)
    params: tuple[float, ...] = ()  #: the law's own parameters, in its declared order (Hunt–Crossley: n)

    def kelvin_voigt(self) -> tuple[float, float] | None:
        """(K [N/m], B [N·s/m]) when the law is affine, F = K x + B ẋ; None otherwise."""
        return kelvin_voigt(self.law, self.k, self.b, self.params)


@dataclass(frozen=True)
class Mass:
    """An equivalent mass of the contact zone [kg], moving along the chain's direction."""

    m: float


Element = Stage | Mass


@dataclass(frozen=True)
class ChainSpec:
    """Deformation chain along one direction.

    ``environment`` lists elements from the environment body out to the contact surface;
    ``robot`` lists them from the robot's tip frame out to the contact surface. Both empty
    is a rigid contact.
    """

    environment: tuple[Element, ...] = ()
    robot: tuple[Element, ...] = ()

    @property
    def rigid(self) -> bool:
        return not self.environment and not self.robot


