"""A controller of my own, in my own file: an impedance law.

    τ = Jᵀ (K (x_d − x) − D ẋ) + g(q)

K [N/m] and D [N·s/m] are the scene's ``controller.stiffness`` and ``controller.damping``;
x_d the phase's task reference. A scene uses it with ``imports = ["my_laws"]`` (this file
beside the scene) and ``controller.kind = "impedance"``; ``contactdyn run`` and ``sweep``
then run it like a built-in law.
"""

from dataclasses import dataclass

from contactdyn.controllers import Controller, register


@dataclass(frozen=True)
class ImpedanceConfig:
    stiffness: float  #: K [N/m]
    damping: float  #: D [N·s/m]
    kind: str = "impedance"


@register
class Impedance(Controller):
    """Impedance: τ = Jᵀ(K (x_d − x) − D ẋ) + g(q) (examples/my_laws.py)."""

    name = "impedance"
    needs_gravity = True  # the system hands g(q) to command() in inp.gravity

    @staticmethod
    def read(r) -> ImpedanceConfig:  # r: the controller table's reader (it checks types and bounds)
        return ImpedanceConfig(stiffness=r.float("stiffness", 1000.0, lo=0.0, unit="N/m"),
                               damping=r.float("damping", 50.0, lo=0.0, unit="N·s/m"))

    def command(self, inp):
        c = self.config
        force = c.stiffness * (inp.x_d - inp.p_tip) - c.damping * inp.v_tip  # [N] at the tip
        return inp.J.T @ force + inp.gravity, None  # joint torques, no controller states
