"""A force-reading controller with a state, in my own file: a force PI law on one set-point.

    f = P (K (x_d − p) − D ṗ) − D_n (n·(ṗ − v_s)) n − (F_d + z) n,    τ = Jᵀ f − c τ_c
    ż = k_i (F_d − F) while the contact touches (0 before)

n the set-point's direction (``inp.force_dir``), P = I − n nᵀ, F the measured force of the set-point's contact
(``inp.force_read``), v_s its surface's velocity (``inp.surface_v``), τ_c the contacts' generalized force on the
joints (``inp.tau_contact``, a fraction c of it cancelled), z [N] the integral of the force error. The law reads
measured forces (``uses_forces``): the system folds them exactly (τ is affine in them). It reads the set-points'
arrays, not ControlInput's dictionaries, so numba compiles it: the one pipeline calls it by address. A scene uses
it with ``imports = ["force_law"]`` and ``controller.kind = "force_pi"`` (examples/force_pi_press.toml).
"""

import numpy as np

from contactdyn.errors import SceneError
from contactdyn.laws import Controller, Param, register


@register
class ForcePI(Controller):
    """Force PI on one set-point with a task impedance across it (examples/force_law.py)."""

    name = "force_pi"
    uses_forces = True  # reads inp.force_read and inp.tau_contact: folded into the solve
    n_states = 1  # z: the force error's integral [N]
    params = (Param("stiffness", "N/m", "K of the position law across the set-point's direction", 2000.0),
              Param("damping", "N·s/m", "D of the position law", 100.0),
              Param("damping_n", "N·s/m", "D_n: damping of the penetration rate along the set-point", 50.0),
              Param("ki", "1/s", "k_i: integral gain of the force error", 20.0),
              Param("cancel", "-", "c: fraction of the measured contact torque cancelled", 0.5, hi=1.0))

    def bind(self, context) -> None:
        if len(context.phase.forces) != 1:
            raise SceneError(f"phase[{context.index}].force", "one force set-point (force_pi)",
                             len(context.phase.forces), context.scene.file)

    def command(self, inp):
        c = self.config
        n = inp.force_dir[0]
        f = c.stiffness * (inp.x_d - inp.p_tip) - c.damping * inp.v_tip
        f = f - (f * n).sum() * n  # across n only
        rate_n = (n * (inp.v_tip - inp.surface_v[0])).sum()  # [m/s]
        f = f - (c.damping_n * rate_n + inp.force_set[0] + inp.z[0]) * n
        tau = inp.J.T @ f - c.cancel * inp.tau_contact
        zdot = np.array([inp.touch[0] * c.ki * (inp.force_set[0] - inp.force_read[0])])
        return tau, zdot
