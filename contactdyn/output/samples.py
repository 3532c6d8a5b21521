"""A run's diagnostics at its output samples, as arrays: :class:`Samples` (what the Result's channels are made of).

The integrator needs only derivatives; a Result needs, at every output sample, the forces, torques, gaps, slip
velocities and stage deformations. A mode's pipeline computes them for all samples of a segment in one
compiled batch (:meth:`~contactdyn.hybrid.pipeline_mode.PipelineMode.samples`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["Samples"]

_ARRAYS = ("tau", "tau_cmd", "u", "limit_torque", "joint_friction", "tip", "x_d", "body_force")  #: per-sample arrays
_DICTS = ("F_n", "gap", "F_d", "F_f", "v_slip", "iface", "stages")  #: per-sample arrays by name


class Samples:
    """Per-sample diagnostics of one segment, as arrays (what Result channels are made of)."""

    def __init__(self, n: int, system):
        nv, nb = system.nv, len(system.body_channels)  # (one per body coordinate)
        self.tau = np.zeros((n, nv))  #: the drives' applied joint torques [N·m or N]
        self.tau_cmd = np.zeros((n, nv))  #: the controller's command [N·m or N; V for voltage controllers]
        self.u = np.full((n, len(system.drives.specs)), np.nan)  #: voltage per drive [V], NaN for ideal drives
        self.limit_torque = np.zeros((n, nv))  #: per joint [N·m or N], 0 unless pressing on a limit
        self.joint_friction = np.zeros((n, nv))  #: per joint: damping and dry friction [N·m or N]
        self.tip = np.zeros((n, 3))  #: the controlled tip's position [m]
        self.x_d = np.full((n, 3), np.nan)  #: the tip's reference [m], NaN where the law has none
        self.has_x_d = False  #: some sample has a reference
        self.body_force = np.zeros((n, nb))  #: the drive force on each body coordinate [N]
        self.F_n = {c.name: np.zeros(n) for c in system.contacts}  #: normal force [N], > 0 pressing
        self.gap = {c.name: np.zeros(n) for c in system.contacts}  #: normal gap [m], 0 while touching
        self.F_d = {key: np.full(n, np.nan) for key in system.force_directions}  #: set-point force [N] (NaN: none)
        self.has_F_d = {key: False for key in system.force_directions}
        self.F_f = {c.name: np.zeros((n, len(c.tangents))) for c in system.contacts}  #: friction [N], tangent coords
        self.v_slip = {c.name: np.zeros((n, len(c.tangents))) for c in system.contacts}  #: slip [m/s], tangent coords
        #: a tangential chain's interface force [N], per "contact.t1"
        self.iface = {f"{c.name}.{dc.label}": np.zeros(n) for c in system.contacts for dc in c.tangent_chains}
        self.stages = {label: np.zeros((n, 3)) for label in system.stage_labels}  #: (x [m], ẋ [m/s], F [N])

    @classmethod
    def concatenate(cls, parts: list[Samples], system) -> Samples:
        """One Samples of the parts' rows, one part after the other."""
        if len(parts) == 1:
            return parts[0]
        edges = np.cumsum([0, *(p.tau.shape[0] for p in parts)])
        return cls.scattered(parts, [np.arange(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True)], system)

    @classmethod
    def scattered(cls, parts: list[Samples], rows: list[np.ndarray], system) -> Samples:
        """One Samples whose rows ``rows[k]`` are those of ``parts[k]`` (all the rows 0 … n − 1, each once)."""
        out = cls(sum(len(r) for r in rows), system)
        for name in _ARRAYS:
            whole = getattr(out, name)
            for part, at in zip(parts, rows, strict=True):
                whole[at] = getattr(part, name)
        out.has_x_d = any(p.has_x_d for p in parts)
        out.has_F_d = {key: any(p.has_F_d[key] for p in parts) for key in out.has_F_d}
        for name in _DICTS:
            for key, whole in getattr(out, name).items():
                for part, at in zip(parts, rows, strict=True):
                    whole[at] = getattr(part, name)[key]
        return out

    def fill_nan(self, first: int) -> None:
        """Rows first … n − 1 NaN (states where the call had no answer)."""
        for name in _ARRAYS:
            getattr(self, name)[first:] = np.nan
        for name in _DICTS:
            for values in getattr(self, name).values():
                values[first:] = np.nan
