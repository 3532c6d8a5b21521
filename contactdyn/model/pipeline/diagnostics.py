"""The pipeline's diagnostics: what an output sample reads besides ẋ and the event values, and the samples' batch.

A call writes its diagnostics section of ``work`` (:func:`.pack.diag_starts`) when the section's switch is on: the
drives' applied forces τ [N·m or N] (the joints', then the bodies' servo forces [N]), the controller's command
[N·m or N], the tip's position [m], the reference x_d [m], the force set-points F_d [N] and the rows' forces λ
(normal forces [N], stick forces [N], limit torques [N·m or N], tangential bonds' interface forces [N]). Each
chain's interface force [N] is written by every call (:func:`.contacts.contact_terms`), and the chains' stage
states (x [m], ẋ [m/s], F [N]) are in ``work`` already. :func:`.pipeline.samples_at` runs many states with the
switch on in one compiled call and keeps, per state, ẋ, the event values and ``work``: the output samples of a
pipeline segment (:class:`~contactdyn.hybrid.pipeline_mode.PipelineMode`) without the readable model.
"""

from __future__ import annotations

from ...numerics.compile_cache import njit
from .actuation import reference, set_points
from .carried import carry
from .pack import D_CMD, D_FD, D_LAM, D_TAU, D_TIP, D_XD, REF_DIMS, diag_starts

__all__ = ["record"]


@njit(cache=True)
def record(t, x, ints, reals, work, applied, tau, p_tip, lam):
    """Write the diagnostics of a call at (t [s], x): applied forces, command, tip [m], x_d [m] (carried by its body,
    if one carries it), F_d [N], λ."""
    at = diag_starts(ints)
    work[at[D_TAU]:at[D_TAU] + applied.size] = applied
    work[at[D_CMD]:at[D_CMD] + tau.size] = tau
    work[at[D_TIP]:at[D_TIP] + 3] = p_tip
    if ints[REF_DIMS]:
        x_d, v_d, _ = reference(t, ints, reals)
        carry(x, ints, reals, x_d, v_d)
        work[at[D_XD]:at[D_FD]] = x_d
    work[at[D_FD]:at[D_LAM]] = set_points(t, ints, reals)[0]
    work[at[D_LAM]:at[D_LAM] + lam.size] = lam
