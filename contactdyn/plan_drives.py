"""The drives on the compiled path: their law as one matrix while no voltage clips.

Below its voltage limits the readable drive law (:meth:`~contactdyn.drives.Drives.apply`)
is affine in the controller's joint command τ and the state x: a rigid gear delivers τ,
an elastic transmission puts τ/n_t plus back-EMF terms on its motor and the tube torque on
both sides, a body's servo is affine in its speed. The plan reads that map off the law
itself by unit probes (``apply(..., clip=False)``, :func:`~contactdyn.plan_probe.affine_map`),
together with each clipping drive's voltage divided by its limit:

    [f_drives; u / u_max] = L [τ, x, 1]

A call costs one product and, when a drive has a finite limit, one test max |u / u_max| ≤ 1.
Where a voltage clips, that call goes through the readable model as it is (the controller's
command, then the law), so the clip acts exactly where it does there (case 1's cart clips and
unclips within one mode).
"""

from __future__ import annotations

import numpy as np

from .dynamics import drive_command
from .plan_probe import affine_map

__all__ = ["drive_forces"]


def drive_forces(plan):
    """(fast, readable) or None unless ``plan.drives_per_call`` (motors, or a force-reading controller
    whose command the servos join): the drives' generalized forces [N·m or N] at the joint command τ,
    fast(x, τ) by the matrix (None where a voltage clips), readable(x, τ) by the law itself."""
    if not plan.drives_per_call:
        return None
    s = plan.system
    drives, nQ, nv, n = s.drives, s.nQ, s.nv, s.n
    vmask = s._joint_motors if plan.phase.controller.outputs == "voltage" else None
    limited = [i for i, spec in enumerate(drives.specs) if spec.motorized and np.isfinite(spec.u_max)]
    u_max = np.array([drives.specs[i].u_max for i in limited])

    def law(x, tau, clip=True):
        f = np.zeros(nQ)
        out = drives.apply(drive_command(s, tau, x), x, nQ, f, voltage=vmask, clip=clip)
        return f, out.u[limited]

    def probe(e):
        f, u = law(e[nv:nv + n], e[:nv], clip=False)
        return np.concatenate((f, u / u_max))

    L = affine_map(probe, nv + n + 1)
    cat = np.concatenate
    one = np.ones(1)

    def fast(x, tau):
        y = L.dot(cat((tau, x, one)))
        if limited and np.abs(y[nQ:]).max() > 1.0:  # a voltage clips
            return None
        return y[:nQ]

    def readable(x, tau):
        return law(x, tau)[0]

    return fast, readable
