"""The drives on the compiled path: their law as one matrix while no voltage clips.

Below its voltage limits the readable drive law (:meth:`~contactdyn.laws.drives.Drives.apply`)
is affine in the controller's joint command τ and the state x: a rigid gear delivers τ,
an elastic transmission puts τ/n_t plus back-EMF terms on its motor and the tube torque on
both sides, a body's servo is affine in its speed. The plan reads that map off the law
itself by unit probes (``apply(..., clip=False)``, :func:`~contactdyn.compiled.plan_probe.affine_map`),
together with each clipping drive's voltage divided by its limit:

    [f_drives; u / u_max] = L [τ, x, 1]

A call costs one product and, when a drive has a finite limit, one test max |u / u_max| ≤ 1.
Where a voltage clips, that call goes through the readable model as it is (the controller's
command, then the law), so the clip acts exactly where it does there (case 1's cart clips and
unclips within one mode).
"""

from __future__ import annotations

import numpy as np

from ..laws.drives import DriveOutput
from ..model.dynamics import drive_command
from .plan_probe import affine_map

__all__ = ["CompiledDrives", "drive_forces"]


class CompiledDrives:
    """The drives of one plan: :meth:`fast` by the matrix L, :meth:`readable` by the law itself."""

    def __init__(self, plan):
        s = plan.system
        self.system, self.nQ, self.nv = s, s.nQ, s.nv
        self.vmask = s._joint_motors if plan.phase.controller.outputs == "voltage" else None
        self.limited = [int(i) for i in np.flatnonzero(s.drives.has_voltage & np.isfinite(s.drives.u_max))]
        self.u_max = s.drives.u_max[self.limited]
        nv, n = s.nv, s.n
        LV = affine_map(lambda e: self._probe(e[nv:nv + n], e[:nv]), nv + n + 1)  # one read of the law for L and V
        k = self.nQ + len(self.limited)
        self.L = LV[:k]  #: [f; u/u_max] = L [τ, x, 1]
        self.V = LV[k:]  #: u = V [τ, x, 1]: the voltages of the drives with one [V], unclipped (the output's)
        self.L_tau = np.ascontiguousarray(self.L[:, :nv])  #: ∂[f; u/u_max]/∂τ
        self._one = np.ones(1)

    def _probe(self, x: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """[f; u/u_max of the limited drives; u of those with a voltage] at (x, τ), unclipped."""
        f, out = self.output(x, tau, clip=False)
        return np.concatenate((f, out.u[self.limited] / self.u_max, out.u[self.system.drives.has_voltage]))

    def _law(self, x: np.ndarray, tau: np.ndarray, clip: bool = True) -> tuple[np.ndarray, np.ndarray]:
        f, out = self.output(x, tau, clip)
        return f, out.u[self.limited]

    def output(self, x: np.ndarray, tau: np.ndarray, clip: bool = True) -> tuple[np.ndarray, DriveOutput]:
        """(the drives' generalized forces [N·m or N], the law's DriveOutput) at the joint command τ."""
        s = self.system
        f = np.zeros(self.nQ)
        return f, s.drives.apply(drive_command(s, tau, x), x, self.nQ, f, voltage=self.vmask, clip=clip)

    def unclipped(self, y: np.ndarray) -> bool:
        """No voltage beyond its limit in y = L [τ, x, 1]."""
        return not self.limited or np.abs(y[self.nQ:]).max() <= 1.0

    def values(self, x: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """y = L [τ, x, 1]: the drives' forces [N·m or N] and the limited voltages over their limits, unclipped."""
        return self.L.dot(np.concatenate((tau, x, self._one)))

    def fast(self, x: np.ndarray, tau: np.ndarray) -> np.ndarray | None:
        """The drives' generalized forces [N·m or N] at the joint command τ; None where a voltage clips."""
        y = self.values(x, tau)
        if not self.limited:  # y is the forces alone
            return y
        return y[:self.nQ] if self.unclipped(y) else None

    def readable(self, x: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """The same by the readable law, clipping included."""
        return self._law(x, tau)[0]


def drive_forces(plan) -> CompiledDrives | None:
    """The plan's compiled drives, or None unless ``plan.drives_per_call`` (motors, or a force-reading
    controller whose command the servos join)."""
    return CompiledDrives(plan) if plan.drives_per_call else None
