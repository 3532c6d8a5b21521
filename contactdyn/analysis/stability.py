"""Stability of a contact phase: the simulator's own right-hand side linearised about its equilibrium.

A scene's last phase (the contact phase: a force set-point held on a surface) is started with
the tip on the surface at rest (:func:`contact_phase_scene`). At a time after every ramp has
ended the right-hand side ẋ = f(x) of that mode and phase (its pipeline's call, the same
function every run integrates) has an equilibrium x*: Newton's method on f finds it, and
central finite differences give A = ∂f/∂x there. The poles are A's eigenvalues, with three
kinds of state left out because they are not dynamics of the loop:

- accumulators (energy audit, impulse integrals): no rate depends on them (a zero column);
- the constraint-drift modes of bonds (model (b) while touching): Baumgarte stabilisation
  makes the violation obey ë + 2ω ė + ω² e = 0, a double pole at −ω; the linearisation runs
  with ω = ``BAUMGARTE`` [1/s], far from the loop's poles, and drops those two per bond row.

Gains can be changed on the bound controller without rebuilding the system
(:meth:`ContactLoop.set_gains`), which is what makes a map over a grid of gains cheap.

A run checks the poles: :func:`simulated_growth` fits the force error's growth rate from the
run's own modes (:func:`modal_poles`, the matrix pencil method); :func:`envelope_rate`, a fit of
its envelope, is kept for comparison (it mixes modes of close rates).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, replace

import numpy as np

from ..hybrid.pipeline_mode import PipelineMode
from ..model.pipeline.pipeline import Pipeline
from ..scene.scene_file import Scene, load_scene, parse_scene
from ..simulate import prepare, simulate

__all__ = ["BAUMGARTE", "Linearization", "ContactLoop", "contact_phase_scene", "growth_rate", "stability_map",
           "modal_poles", "modal_rate", "envelope_rate", "contact_force_error", "simulated_growth"]

BAUMGARTE = 1000.0  #: [1/s] constraint stabilisation rate during linearisation (its poles are dropped)
_FD_STEP = 1e-6  #: relative central-difference step
_NEWTON_TOL = 1e-10  #: residual ‖f(x*)‖∞ on the kept states, relative to the starting one
_NEWTON_FLOOR = 1e-8  #: and absolute (the round-off of ω² e with ω = BAUMGARTE is ~1e-9)


@dataclass(frozen=True)
class Linearization:
    """The loop linearised about its equilibrium."""

    x: np.ndarray  #: equilibrium state x*
    live: np.ndarray  #: indices of the states kept
    A: np.ndarray  #: ∂ẋ/∂x on the kept states
    poles: np.ndarray  #: eigenvalues of A without the constraint-drift ones [1/s]

    @property
    def dominant(self) -> complex:
        """The pole with the largest real part [1/s]."""
        return complex(self.poles[int(np.argmax(self.poles.real))])

    @property
    def stable(self) -> bool:
        return self.dominant.real < 0.0


def contact_phase_scene(scene: Scene | str, q0: list[float], overrides: dict | None = None) -> Scene:
    """The scene's last phase alone, started from joint positions ``q0`` (the tip on the surface, at rest)."""
    base = scene if isinstance(scene, Scene) else load_scene(scene)
    doc = copy.deepcopy(base.document)
    doc["phase"] = [doc["phase"][-1]]
    doc["robot"]["q0"] = list(q0)
    doc.get("robot", {}).pop("tip0", None)
    return parse_scene(doc, overrides, base.file)


class ContactLoop:
    """The last phase of a scene (see :func:`contact_phase_scene`) as a map x -> ẋ at a fixed time."""

    def __init__(self, scene: Scene, t_eq: float = 10.0):
        scene = parse_scene(scene.document, {"solver.stabilization": BAUMGARTE}, scene.file)
        self.system, modes, self.phase, self.x0 = prepare(scene)
        self.modes = [replace(m, touching=True) for m in modes]  # the contact phase's mode, whatever t = 0 says
        self.t_eq = t_eq  #: [s] a time after every ramp of the phase
        self._mode: PipelineMode | None = None  #: the mode's pipeline (packed at first use, again after set_gains)
        self.n_bond_rows = sum(1 for c, m in zip(self.system.contacts, self.modes, strict=True)
                               if m.touching and c.normal.chain.bonded_when_touching)

    @property
    def controller(self):
        return self.phase.controller

    def set_gains(self, **gains: float) -> None:
        """Replace controller gains (kp, kv: [1/s², 1/s]; kf: [1/s]) on the bound controller."""
        cfg = self.controller.config
        values = {k: (np.array([float(v)]) if isinstance(getattr(cfg, k), np.ndarray) else float(v))
                  for k, v in gains.items()}
        self.controller.config = replace(cfg, **values)
        self._mode = None  # (the pipeline packs the gains)

    @property
    def mode(self) -> PipelineMode:
        """The contact phase's mode on its pipeline (what a run integrates)."""
        if self._mode is None:
            self._mode = PipelineMode(Pipeline(self.system, self.modes, self.phase))
        return self._mode

    def rate(self, x: np.ndarray, t: float | None = None) -> np.ndarray:
        """ẋ at x [SI] and t [s] (the equilibrium's time by default): the mode's pipeline call."""
        return self.mode.rhs(self.t_eq if t is None else t, np.array(x, float))

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        n = len(x)
        A = np.empty((n, n))
        for j in range(n):
            h = _FD_STEP * max(1.0, abs(x[j]))
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            A[:, j] = (self.rate(xp) - self.rate(xm)) / (2.0 * h)
        return A

    def linearize(self, x_guess: np.ndarray | None = None) -> Linearization:
        x = (self.x0 if x_guess is None else x_guess).copy()
        A = self.jacobian(x)
        live = np.flatnonzero(np.any(A != 0.0, axis=0))  # accumulators: nothing depends on them
        res0 = max(1.0, float(np.max(np.abs(self.rate(x)[live]))))
        for _ in range(8):
            res = self.rate(x)[live]
            if np.max(np.abs(res)) < max(_NEWTON_TOL * res0, _NEWTON_FLOOR):
                break
            step = np.linalg.lstsq(A[np.ix_(live, live)], res, rcond=None)[0]
            x[live] -= step
            A = self.jacobian(x)
            if np.max(np.abs(step)) < 1e-13 * max(1.0, float(np.max(np.abs(x[live])))):
                break  # at round-off: the step no longer moves x
        else:
            raise RuntimeError(f"contact equilibrium not found: residual {np.max(np.abs(self.rate(x)[live])):.3g}")
        Al = A[np.ix_(live, live)]
        poles = np.linalg.eigvals(Al)
        drift = np.argsort(np.abs(poles + BAUMGARTE))[: 2 * self.n_bond_rows]
        return Linearization(x, live, Al, np.delete(poles, drift))


def growth_rate(t: np.ndarray, error: np.ndarray, period: float, lo: float, hi: float) -> float:
    """Exponential rate [1/s] of |error|'s envelope (its maximum over each ``period``), fitted by least
    squares on log(envelope) over the windows whose envelope lies within [lo, hi]."""
    edges = np.arange(t[0], t[-1], period)
    mids, peaks = [], []
    for a in edges:
        sel = (t >= a) & (t < a + period)
        if np.count_nonzero(sel) < 3:
            continue
        peak = float(np.max(np.abs(error[sel])))
        if lo <= peak <= hi:
            mids.append(float(t[sel][np.argmax(np.abs(error[sel]))]))
            peaks.append(peak)
    if len(peaks) < 3:
        raise ValueError(f"growth_rate: {len(peaks)} windows with the envelope in [{lo}, {hi}] (need 3)")
    return float(np.polyfit(mids, np.log(peaks), 1)[0])


def stability_map(loop: ContactLoop, x_gain: tuple[str, np.ndarray], y_gain: tuple[str, np.ndarray]
                  ) -> np.ndarray:
    """Dominant pole [1/s] over a grid of two gains (names as :meth:`ContactLoop.set_gains` takes them):
    entry [i, j] at y_gain[1][i], x_gain[1][j]. Each point starts Newton from the previous equilibrium."""
    (xn, xs), (yn, ys) = x_gain, y_gain
    out = np.empty((len(ys), len(xs)), complex)
    x = None
    for i, yv in enumerate(ys):
        for j, xv in enumerate(xs):
            loop.set_gains(**{xn: xv, yn: yv})
            lin = loop.linearize(x)
            x = lin.x
            out[i, j] = lin.dominant
    return out


def modal_poles(t: np.ndarray, y: np.ndarray, rel: float = 1e-6, max_modes: int = 40) -> np.ndarray:
    """The exponents λ [1/s] of y(t) = Σ c_k e^(λ_k t) on a uniform grid, by the matrix pencil method: the
    signal's Hankel matrix keeps the singular values above ``rel`` times the largest (at most ``max_modes``),
    and the shift between its rows gives e^(λ Δt). Modes with close rates but different frequencies come
    apart, where an envelope fit mixes them."""
    dt = float(t[1] - t[0])
    if len(t) < 30 or not np.allclose(np.diff(t), dt, rtol=1e-6, atol=0.0):
        raise ValueError(f"modal_poles: need at least 30 uniformly spaced samples, got {len(t)}")
    n_cols = len(y) // 3
    hankel = np.lib.stride_tricks.sliding_window_view(np.asarray(y, float), n_cols + 1)
    _, sv, vt = np.linalg.svd(hankel, full_matrices=False)
    order = min(int(np.count_nonzero(sv > rel * sv[0])), max_modes)
    v = vt[:order].T
    shift = np.linalg.lstsq(v[:-1], v[1:], rcond=None)[0]
    return np.log(np.linalg.eigvals(shift).astype(complex)) / dt


def contact_force_error(scene: Scene, t_fit: float, hi: float = 95.0) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], F_n − F_d [N]) of a run of ``scene`` (see :func:`contact_phase_scene`) from ``t_fit``, up to
    the first sample where the error exceeds ``hi`` or the contact is lost (the loop is linear while touching)."""
    r = simulate(scene)
    name = next(iter(scene.contacts))
    err = r[f"contact.{name}.F_n"] - r[f"contact.{name}.F_d"]
    keep = (np.abs(err) <= hi) & (r[f"contact.{name}.touching"] > 0.5)
    end = int(np.argmin(keep)) if not np.all(keep) else len(err)
    sel = np.flatnonzero(r.t[:end] > t_fit)
    return r.t[sel], err[sel]


def simulated_growth(scene: Scene, t_fit: float, hi: float = 95.0) -> tuple[float, complex]:
    """The force error's growth rate [1/s] in a run of ``scene`` (see :func:`contact_phase_scene`) from ``t_fit``
    [s] while it stays in contact and below ``hi`` [N] (:func:`modal_rate`: the real part of the run's own mode
    whose frequency is nearest the pole's), and the dominant pole of the same scene's linearisation."""
    dom = ContactLoop(scene).linearize().dominant
    t, err = contact_force_error(scene, t_fit, hi)
    return modal_rate(t, err, dom), dom


def modal_rate(t: np.ndarray, err: np.ndarray, pole: complex) -> float:
    """Real part [1/s] of the mode of err(t) (:func:`modal_poles`) whose frequency is nearest ``pole``'s."""
    found = modal_poles(t, err)
    return float(found[int(np.argmin(np.abs(np.abs(found.imag) - abs(pole.imag))))].real)


def envelope_rate(t: np.ndarray, err: np.ndarray, pole: complex, hi: float = 95.0) -> float:
    """:func:`growth_rate` of err(t) over windows of ``pole``'s period."""
    period = 2.0 * np.pi / abs(pole.imag) if abs(pole.imag) > 1e-6 else 0.05
    return growth_rate(t, err, period, 1e-6, hi)
