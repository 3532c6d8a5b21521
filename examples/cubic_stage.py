"""A stage law of my own, in my own file: a hardening (cubic) spring with a damper.

    F = k x + k₃ x³ + b ẋ   [N]   at compression x [m] and rate ẋ [m/s]

k [N/m] and b [N·s/m] are every stage's; k₃ [N/m³] is this law's own parameter, declared
once below (unit, default, bounds, meaning): the scene reads and checks it from there, and
``contactdyn list keys`` documents it. A scene uses it with ``imports = ["cubic_stage"]``
(this file beside the scene) and ``law = "cubic"`` on a stage. numba compiles it like a built-in law, so its
touching modes run on the compiled call (the run's stats say so, per mode).
"""

from contactdyn.laws import Param, StageLaw, register_stage_law


@register_stage_law
class Cubic(StageLaw):
    """F = k x + k₃ x³ + b ẋ (examples/cubic_stage.py)."""

    name = "cubic"
    params = (Param("k3", "N/m^3", "cubic stiffness of the cubic law F = k x + k3 x^3 + b x'", 0.0, lo=0.0,
                    example=1e9),)

    @staticmethod
    def force(k, b, p, x, xdot):
        return k * x + p[0] * x**3 + b * xdot

    @staticmethod
    def potential(k, p, x):  # [J], for the run's energy audit
        return 0.5 * k * x**2 + 0.25 * p[0] * x**4
