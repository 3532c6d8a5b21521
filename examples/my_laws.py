"""A controller of my own, in my own file: an impedance law.

    τ = Jᵀ (K (x_d − x) − D ẋ) + g(q)

K [N/m] and D [N·s/m] are the scene's ``controller.stiffness`` and ``controller.damping``,
declared once below (unit, default, bounds, meaning): the scene reads and checks them from
there and ``contactdyn list keys`` documents them. x_d is the phase's task reference. A scene
uses it with ``imports = ["my_laws"]`` (this file beside the scene) and
``controller.kind = "impedance"``; ``contactdyn run`` and ``sweep`` then run it like a
built-in law.
"""

from contactdyn.laws import Controller, Param, register


@register
class Impedance(Controller):
    """Impedance: τ = Jᵀ(K (x_d − x) − D ẋ) + g(q) (examples/my_laws.py)."""

    name = "impedance"
    needs_gravity = True  # the system hands g(q) to command() in inp.gravity
    params = (Param("stiffness", "N/m", "K of the impedance law tau = J^T (K (x_d - x) - D x') + g", 1000.0),
              Param("damping", "N·s/m", "D of the impedance law", 50.0))

    def command(self, inp):
        c = self.config  # c.stiffness, c.damping: the declared parameters' values
        force = c.stiffness * (inp.x_d - inp.p_tip) - c.damping * inp.v_tip  # [N] at the tip
        return inp.J.T @ force + inp.gravity, None  # joint torques, no controller states
