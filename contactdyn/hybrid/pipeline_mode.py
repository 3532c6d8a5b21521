"""A mode on the one pipeline as the hybrid loop runs it: right-hand side, compiled steps, event values, samples.

:class:`PipelineMode` wraps a mode packed for the one pipeline (:class:`~contactdyn.model.pipeline.pipeline.Pipeline`)
for the loop, its event functions (:func:`~contactdyn.hybrid.events.segment_events`) and the output
(:func:`~contactdyn.output.channels.sample_states`):

- ``rhs(t, x)`` is the pipeline's call; ``rhs.step`` a whole DOP853 step in one compiled call
  (:func:`~contactdyn.hybrid.steps.attempt`), ``rhs.derivatives`` the dense output's extra stages
  in one (``rates_at``), and (compiled only) ``rhs.interpolant`` a located event's step interpolant in one
  (:func:`~contactdyn.hybrid.steps.interpolant`);
- the event functions read the event values of the call at that very state (a stuck contact's slip watch each
  stage's, :meth:`watched_step`; the last four calls' in ``ring``: a compiled step's FSAL call, with a slip watch
  its stages' too, and the right-hand side's own calls; an interpolant's stages enter none): gaps [m], normal
  forces [N], slip velocities [m/s], stick forces [N], limit torques [N·m or N];
- :meth:`samples` runs the output samples in one compiled call with the call's diagnostics on (τ, the command,
  the tip, x_d, F_d, λ, the stage states: :func:`contactdyn.model.pipeline.pipeline.record`);
  :meth:`measurement` reads what a sampled law measures at a sample instant off one such call.

A pipeline given twins (:mod:`contactdyn.numerics.twins`, a scene kind's first run) runs all of these, its steps and
samples too, as its twins (``pipe.of``): the same functions interpreted.

A call whose status is not 1 raises a law's own error there (a Python stage's, the controller's:
:meth:`~contactdyn.model.pipeline.pipeline.Pipeline.failed_call`), else its rates are NaN (a KKT system that is not
finite at an overflowed trial state: the step control rejects it); a singular KKT matrix is solved in the call by least
squares (:func:`contactdyn.model.pipeline.kkt.solve_linear`, an evaluation's ``regular`` False); ``singular`` counts
both.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from ..errors import SimulationError
from ..model.chain_forces import pack as pack_chain
from ..model.evaluation import Evaluation, Measurement
from ..model.paths import LivePipelines
from ..model.pipeline.drives import DW_U, DW_W
from ..model.pipeline.pack import (
    ANY_MOTOR,
    CH_MOTION,
    CH_NNODES,
    CH_STATE,
    CH_W,
    D_CMD,
    D_FD,
    D_LAM,
    D_TAU,
    D_TC,
    D_TIP,
    D_XD,
    EV_FF,
    EV_FN,
    EV_GAP,
    EV_VT,
    EV_W,
    I_CHAINS,
    N_DRIVES,
    REF_DIMS,
    W_DIAG,
    W_DRIVES,
    diag_starts,
)
from ..model.pipeline.pipeline import Pipeline, call, samples_at
from ..output.samples import Samples
from .steps import derivatives, interpolant_builder, stepper

__all__ = ["PipelineMode", "mode_runner"]

_NO_CALL = (None, None, None)  #: a ring entry before any call


class PipelineMode:
    """One (modes, phase) on the one pipeline, as the loop runs it (see the module docstring)."""

    def __init__(self, pipe: Pipeline):
        self.pipe, self.system, self.modes, self.phase = pipe, pipe.system, pipe.modes, pipe.phase
        self.interpreted = pipe.twins is not None  #: the pipeline's functions run as their twins
        of = pipe.of  # (the module's functions looked up at each use: a test replaces one)
        call_ = of(call)
        self.reason = "; ".join(pipe.python_stages)  #: its declared Python stages ("": none)
        self.ring: deque[tuple] = deque([_NO_CALL] * 4, maxlen=4)  #: the last four calls' (t, x, events)
        #: per joint_event_starts() section (the limits', the held joints'): [events it was read from, by joint]
        self._by_joint: list[list] = [[None, {}], [None, {}]]
        p = pipe.packed
        ints, reals, work, events = p.ints, p.reals, p.work, p.events
        ring = self.ring

        def rhs(t: float, x: np.ndarray) -> np.ndarray:
            xdot = call_(float(t), x, ints, reals, work, events)
            if events[-1] != 1.0:
                xdot = pipe.failed_call(t, x)
            ring.append((t, x, events.copy()))
            return xdot

        rhs.step = of(stepper)(p, ring)
        rhs.derivatives = of(derivatives)(p, rhs)
        if not self.interpreted:  # (an interpreted mode's event steps: build_interpolants, NumPy, nothing compiled)
            rhs.interpolant = interpolant_builder(p)
        self.rhs = rhs
        self.nt = [len(c.tangents) if c.friction is not None else 0 for c in self.system.contacts]
        self._stages = self._stage_table()
        self._ifaces = self._interface_table()
        self._nodes = self._node_table()

    def watched_step(self, on_stage, on_stages=None):
        """``rhs.step`` that calls ``on_stage(t, x)`` at each stage of each attempt, its values the ring's latest (the
        slip watch of a stuck contact, :func:`~contactdyn.hybrid.events.segment_events`), and
        ``on_stages(times, Ys, Es)`` once per attempt with all its stages (the watches of the state or of event
        values); either may be None."""
        return self.pipe.of(stepper)(self.pipe.packed, self.ring, on_stage, on_stages)

    @property
    def singular(self) -> int:
        """Calls solved by least squares (a singular KKT matrix: ``Pipeline.least_squares``) or with no answer (a KKT
        system that is not finite: ``Pipeline.failed_calls``): ``Result.stats["singular_solves"]``."""
        return self.pipe.least_squares + self.pipe.failed_calls

    @property
    def holds_split(self) -> int:
        """Of the calls solved by least squares, those whose redundant holds were split by their limits
        (``Pipeline.holds_split``): ``Result.stats["holds_split"]``."""
        return self.pipe.holds_split

    def use(self, modes) -> None:
        """Run with these modes from now on: a turn's new 2-D reference directions r, data of the same packed mode
        (the last calls' event values were for the old r: forgotten)."""
        if list(modes) != self.modes:
            self.pipe.use(modes)
            self.modes = self.pipe.modes
            self.ring.extend([_NO_CALL] * 4)

    # ---- values the event functions read ----------------------------------------------
    def values(self, t: float, x: np.ndarray) -> np.ndarray:
        """The event values at (t, x): the last call's when it was at this very state."""
        lt, lx, ev = self.ring[-1]  # (the newest first: a step end's, which every event function reads)
        if lx is x and lt == t:
            return ev
        for lt, lx, ev in reversed(self.ring):
            if lx is x and lt == t:
                return ev
        self.rhs(t, x)
        return self.ring[-1][2]

    def gap(self, ci: int, t: float, x: np.ndarray) -> float:
        """Normal gap of contact ci [m] (0 while touching)."""
        return float(self.values(t, x)[EV_W * ci + EV_GAP])

    def normal_force(self, ci: int, t: float, x: np.ndarray) -> float:
        """Normal force of contact ci [N]."""
        return float(self.values(t, x)[EV_W * ci + EV_FN])

    def slip(self, ci: int, t: float, x: np.ndarray) -> np.ndarray:
        """Slip velocity of contact ci in its tangent coordinates [m/s]."""
        at = EV_W * ci + EV_VT
        return self.values(t, x)[at:at + self.nt[ci]]

    def stick_force(self, ci: int, t: float, x: np.ndarray) -> np.ndarray:
        """Friction force of a sticking contact ci in tangent coordinates [N]."""
        at = EV_W * ci + EV_FF
        return self.values(t, x)[at:at + self.nt[ci]]

    def cone_margin(self, ci: int, mu_s: float, t: float, x: np.ndarray) -> float:
        """μ_s F − |F_f| [N] of a sticking contact ci: the ``slip`` event's function."""
        F_f = self.stick_force(ci, t, x).tolist()
        return mu_s * self.normal_force(ci, t, x) - math.sqrt(sum(v * v for v in F_f))

    def limit_torque(self, t: float, x: np.ndarray) -> dict[int, float]:
        """Torques [N·m or N] of the joints pressing on a limit, by joint coordinate (the ``release`` event's)."""
        return self._joint_torques(t, x, 0, self.pipe.packed.limits)

    def joint_hold(self, t: float, x: np.ndarray) -> dict[int, float]:
        """Holding torques [N·m or N] of the joints stuck by dry friction, by joint coordinate (after the limits')."""
        return self._joint_torques(t, x, 1, self.pipe.packed.held)

    def _joint_torques(self, t: float, x: np.ndarray, section: int, joints: list[int]) -> dict[int, float]:
        """{joint: torque} of a section of the event values at (t, x), read once per call (each of its joints'
        events asks at every stage: events.StageWatch)."""
        ev, memo = self.values(t, x), self._by_joint[section]
        if memo[0] is not ev:  # (each call's events are a copy of their own, in the ring)
            base = self.pipe.packed.joint_event_starts()[section]
            memo[:] = [ev, {i: float(ev[base + k]) for k, i in enumerate(joints)}]
        return memo[1]

    # ---- an instant's evaluation -------------------------------------------------------------------
    def evaluation(self, t: float, x: np.ndarray) -> Evaluation:
        """The model at (t [s], x), off one call with the diagnostics on (as an output sample's): ẋ, λ, the event
        values by name, τ, the command, the tip, the stage states, ``regular`` (False: the KKT matrix singular,
        solved by least squares). A call with no answer there raises (:meth:`_one_call`)."""
        p, system = self.pipe.packed, self.system
        X = np.ascontiguousarray(x, dtype=float)[None, :]
        least_squares_before = self.pipe.least_squares
        Xd, E, W = self._one_call(t, X)
        S = Samples(1, system)
        self._read_out(S, E, W, X)
        e, at = E[0], self.pipe.of(diag_starts)(p.ints)
        at_limit, at_held, _ = p.joint_event_starts()
        named = [(c.name, nt) for c, nt in zip(system.contacts, self.nt, strict=True)]
        return Evaluation(
            Xd[0], W[0, at[D_LAM]:at[D_TC]].copy(), p.row_meta, {k: float(v[0]) for k, v in S.F_n.items()},
            {name: S.F_f[name][0] for name, nt in named if nt}, {name: S.v_slip[name][0] for name, nt in named if nt},
            {k: float(v[0]) for k, v in S.gap.items()},
            {label: tuple(S.stages[label][0].tolist()) for label, state in self._stages if state is not None},
            {k: float(v[0]) for k, v in S.iface.items()}, S.tau[0], S.body_force[0], S.tip[0],
            W[0, at[D_XD]:at[D_FD]].copy() if p.ints[REF_DIMS] else None,
            {key: float(S.F_d[key][0]) for key in self.phase.forces}, tau_cmd=S.tau_cmd[0], u=S.u[0],
            limit_torque={i: float(e[at_limit + k]) for k, i in enumerate(p.limits)},
            joint_hold={i: float(e[at_held + k]) for k, i in enumerate(p.held)},
            joint_friction=S.joint_friction[0] if system.joint_friction.any else None,
            node_positions={key: W[0, at:at + n].copy() for key, at, n in self._nodes},
            regular=self.pipe.least_squares == least_squares_before)

    # ---- output samples ------------------------------------------------------------------------
    def samples(self, ts: np.ndarray, X: np.ndarray, modes=None, runs: list[int] | None = None) -> Samples:
        """Diagnostics at the states X[k] (times ts[k]) in one compiled call (NaN from a state with no answer on, a
        law's own error raised there). ``runs``: the rows' lengths of runs of segments, one batch; where a call has no
        answer each run is sampled on its own."""
        if modes is not None:
            self.use(modes)
        p, system = self.pipe.packed, self.system
        ts, X = np.ascontiguousarray(ts, dtype=float), np.ascontiguousarray(X, dtype=float)
        _, E, W, done = self.pipe.of(samples_at)(ts, X, p.ints, p.reals, p.work, p.events)
        if done < len(ts) and runs is not None and len(runs) > 1:
            ends = np.cumsum(runs)
            return Samples.concatenate([self.samples(ts[e - n:e], X[e - n:e]) for n, e in zip(runs, ends, strict=True)],
                                       system)
        S = Samples(len(ts), system)
        self._read_out(S, E[:done], W[:done], X[:done])
        if done < len(ts):
            self.pipe.failed_call(float(ts[done]), X[done])
            S.fill_nan(done)
        return S

    def _one_call(self, t: float, X: np.ndarray) -> tuple:
        """(ẋ, event values, work) of one call at (t [s], X[0]) with the diagnostics on, each with one row. Where the
        call has no answer, a law's own error is raised (:meth:`Pipeline.failed_call`), else that the model has
        none there."""
        p = self.pipe.packed
        Xd, E, W, done = self.pipe.of(samples_at)(np.array([float(t)]), X, p.ints, p.reals, p.work, p.events)
        if done == 0:
            self.pipe.failed_call(t, X[0], final=True)
            raise SimulationError(f"t = {t:.6g} s: the model has no finite answer at this state (its contact "
                                  "system is not finite there)")
        return Xd, E, W

    def measurement(self, t: float, x: np.ndarray) -> Measurement:
        """What a sampled law measures at (t [s], x) (:class:`~contactdyn.model.evaluation.Measurement`), off one
        compiled call with the diagnostics on (as an output sample's)."""
        p, system = self.pipe.packed, self.system
        Xd, E, W = self._one_call(t, np.ascontiguousarray(x, dtype=float)[None, :])
        e, w = E[0], W[0]
        at = self.pipe.of(diag_starts)(p.ints)[D_TC]
        i_b = self.phase.carrier[0] if self.phase.carrier is not None else -1
        return Measurement({c.name: float(e[EV_W * ci + EV_FN]) for ci, c in enumerate(system.contacts)},
                           {key: float(w[k]) for key, k in self._ifaces}, w[at:at + system.nv].copy(),
                           float(Xd[0, system.nQ + i_b]) if i_b >= 0 else 0.0)

    def _interface_table(self) -> list[tuple[str, int]]:
        """Per tangential chain ("contact.t1") where its interface force is in ``work``: its bond's λ while bonded,
        else the chain's own (pack's order)."""
        ints, at, k, out = self.pipe.packed.ints, self.pipe.of(diag_starts)(self.pipe.packed.ints), 0, []
        rows = {meta: r for r, meta in enumerate(self.pipe.packed.row_meta)}
        for c in self.system.contacts:
            for i, dc in enumerate(c.chains):
                if i > 0:  # (the normal chain first)
                    r = rows.get((c.name, dc.label, i - 1))
                    out.append((f"{c.name}.{dc.label}", int(at[D_LAM] + r if r is not None else ints[W_DIAG] + 1 + k)))
                k += 1
        return out

    def _node_table(self) -> list[tuple[str, int, int]]:
        """Per chain ("contact.label", pack's order): where its nodes' positions start in ``work``, how many."""
        ints, out, k = self.pipe.packed.ints, [], 0
        for c in self.system.contacts:
            for dc in c.chains:
                row = ints[ints[I_CHAINS] + CH_W * k:]
                out.append((f"{c.name}.{dc.label}", int(row[CH_MOTION]), int(row[CH_NNODES])))
                k += 1
        return out

    def _stage_table(self) -> list[tuple[str, int, int | None]]:
        """Per stage label of every chain (pack's order): (label, where its (x, ẋ, F) start in ``work``, or None
        while it carries no force)."""
        system, ints, out, k = self.system, self.pipe.packed.ints, [], 0
        for c, m in zip(system.contacts, self.modes, strict=True):
            for dc in c.chains:
                a = self.pipe.of(pack_chain)(system, c, dc, m.touching, m.relaxing and not m.touching)
                state = int(ints[ints[I_CHAINS] + CH_W * k + CH_STATE])
                out += [(label, state + 4 * s if s in a.active else None) for s, label in enumerate(a.labels)]
                k += 1
        return out

    def _read_out(self, S: Samples, E: np.ndarray, W: np.ndarray, X: np.ndarray) -> None:
        """Rows 0..len(E) of S from the calls' event values E and work W at the states X (one row per sample)."""
        system, p, n = self.system, self.pipe.packed, len(E)
        if n == 0:
            return
        ints, nv = p.ints, system.nv
        at = self.pipe.of(diag_starts)(ints)
        S.tau[:n] = W[:, at[D_TAU]:at[D_TAU] + nv]
        S.body_force[:n] = W[:, at[D_TAU] + nv:at[D_CMD]]
        S.tau_cmd[:n] = W[:, at[D_CMD]:at[D_CMD] + nv]
        S.tip[:n] = W[:, at[D_TIP]:at[D_TIP] + 3]
        if ints[ANY_MOTOR]:  # each drive's voltage [V] (NaN: an ideal source), as the drives wrote it
            w0 = ints[W_DRIVES]
            S.u[:n] = W[:, w0 + DW_U:w0 + DW_W * ints[N_DRIVES]:DW_W]
        if ints[REF_DIMS] == 3:
            S.x_d[:n], S.has_x_d = W[:, at[D_XD]:at[D_FD]], True
        for j, key in enumerate(self.phase.forces):
            S.F_d[key][:n], S.has_F_d[key] = W[:, at[D_FD] + j], True
        at_limit, at_held, _ = p.joint_event_starts()
        for k, i in enumerate(p.limits):
            S.limit_torque[:n, i] = E[:, at_limit + k]
        if system.joint_friction.any:  # damping and sliding friction at each state, the held joints' torques
            S.joint_friction[:n] = [system.joint_friction.torques(self.phase.joint_modes, xk, system.nQ, nv)
                                    for xk in X]
            for k, i in enumerate(p.held):
                S.joint_friction[:n, i] += E[:, at_held + k]
        for ci, c in enumerate(system.contacts):
            e, nt = EV_W * ci, self.nt[ci]
            S.F_n[c.name][:n], S.gap[c.name][:n] = E[:, e + EV_FN], E[:, e + EV_GAP]
            if nt:
                S.F_f[c.name][:n], S.v_slip[c.name][:n] = E[:, e + EV_FF:e + EV_FF + nt], E[:, e + EV_VT:e + EV_VT + nt]
        self._read_chains(S, W, n)

    def _read_chains(self, S: Samples, W: np.ndarray, n: int) -> None:
        """The tangential chains' interface forces (a bond's λ, else the chain's own) and the stage states."""
        for key, k in self._ifaces:
            S.iface[key][:n] = W[:, k]
        for label, state in self._stages:
            if state is not None:
                S.stages[label][:n] = W[:, state:state + 3]


def mode_runner(system, compiled: bool = True):
    """runner(modes, phase) -> PipelineMode: the modes of ``system`` on their pipelines, one per structure and phase
    (compiled; ``compiled=False``: interpreted), as a run's transitions and samples read the model: for the model at
    an instant outside a run (``runner(modes, phase).evaluation(t, x)``)."""
    pipes = LivePipelines(system, PipelineMode, use=compiled)

    def runner(modes, phase) -> PipelineMode:
        why = pipes.declined(modes, phase)
        if why:
            raise SimulationError(f"{system.scene.name}: the model cannot run this mode: {why}")
        return pipes.mode(modes, phase)

    return runner
