"""Dynamic control (the paper's Appendix): computed torque with a prescribed error transient.

``position_dynamic`` (A7): τ = H(q) q̈* + h(q, q̇) − τ_c, where τ_c = Σ J_cᵀ F_c is the
measured contact force on the joints and q̈* makes the tracking error η obey the desired
transient η̈ = P(η, η̇) = −K_p η − K_v η̇. Joint space: η = q − q_d, q̈* = q̈_d + P. Task
space: η = x − x_d (tip), a* = ẍ_d + P, q̈* = J⁺(a* − J̇q̇) − (I − J⁺J) k_null q̇. Cancelling
τ_c decouples the robot from its contacts: with an exact model the error obeys P whatever
the environment does. Option ``force_reference``: along a contact normal with a force
set-point the position reference becomes the depth the nominal environment needs for F_d,
s_d = F_d / k (the position-based way to press); along a tangent with a set-point (a
tangential chain, case 1's F1) it becomes F_d / k beyond the chain's anchor, the point
where that chain was undeformed at the latest touch.

``force_dynamic`` (A10): along each contact normal with a force set-point the nominal
environment F = m s̈ + b ṡ + k s (s the penetration [m]) turns the force target
F* = F_d + ∫Q(μ) dt, Q(μ) = −K_F μ, μ = F − F_d, into the penetration acceleration
s̈* = (F* − b ṡ − k s) / m, the tip acceleration −s̈* n; then computed torque
τ = H q̈* + h − Jᵀ n F* (the appendix's eq. A10 as written: the measured force enters only
through the integral of μ, "no explicit force feedback"). With exact models the robot then
moves as commanded only if F = F*; for model (b) that is algebraic (the bond's force is what
makes the tip follow s̈*), so F = F* and μ = ∫Q(μ) dt, i.e. μ̇ = −K_F μ. A massless nominal
(m = 0, b > 0) has relative degree one: s̈* = (Ḟ* − k ṡ) / b with Ḟ* = Ḟ_d − K_F μ; on a
massless true surface e = F − F* then obeys ė = −(b / m_r) e (m_r the robot's mass along n)
and μ = e + ∫Q(μ) dt. Option ``cancel = "measured"``: τ = H q̈* + h − τ_c cancels the
measured force instead (our earlier realisation): the robot then follows s̈* whatever F is,
and on the massless nominal μ̇ = −K_F μ exactly. The other task directions are damped
(a* = −K_v ẋ), and any measured force along them (friction) is cancelled as in A7. While a
contact does not touch, its normal is treated like the other directions and its integral is
frozen.

Option ``inertia`` (A7 and A10): the H the law multiplies by. ``"model"`` (default) is the
rigid model's, the link plus the rotor inertia a motor reflects through its gear (n_s n_t J);
``"link"`` is the link alone (eq. 49's m for case 3), the reading of A7/A10 that ignores the
drive. Through an elastic transmission the two differ by 88 kg on case 3's 50 kg axis.

``hybrid``: A7 along ``axes`` (default: every direction orthogonal to the force normals)
tracking a task-space reference, A10 along the normals: the position/force split of case 2.

Gains are physical: K_p [1/s²] and K_v [1/s] of the error transient (defaults 400 and 40:
ω = 20 rad/s, critically damped), K_F [1/s] the force error rate (default 20: time constant
50 ms), k_null [1/s] the null-space joint damping of redundant robots (default 10). The
``nominal`` table {k [N/m], b [N·s/m], m [kg]} is the environment the controller believes
(default: the scene's own contact model when it is (b) or (c); (a) and chains need one).

Measured forces the system cannot know before its linear solve (bonds) enter exactly: these
laws are affine in them (see :mod:`contactdyn.laws.controllers.base`). Forces of constraints that
hold the robot alone (a rigid contact on the fixed ground, sticking on it) are not in τ_c:
cancelling them would leave them undetermined.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import SceneError
from ...numerics.linalg import contiguous as _c
from ...numerics.twins import current
from ..elements import Mass, Stage
from . import computed_torque as compiled
from . import dynamic_law
from .base import BindContext, ControlInput, Controller, register

__all__ = ["NominalEnvironment", "PositionDynamic", "ForceDynamic", "Hybrid", "nominal_from_chain"]

KP, KV, KF, K_NULL = 400.0, 40.0, 20.0, 10.0  #: default gains [1/s², 1/s, 1/s, 1/s]


@dataclass(frozen=True)
class NominalEnvironment:
    """The environment model a controller believes, along a contact normal: F = m s̈ + b ṡ + k s."""

    k: float  #: [N/m]
    b: float = 0.0  #: [N·s/m]
    m: float = 0.0  #: equivalent mass riding with the tip [kg]


def nominal_from_chain(chain) -> tuple[NominalEnvironment | None, bool]:
    """The single-mass equivalent of a contact's normal chain and whether it is exact.

    Model (c) and (b) are exact; other linear chains give their static series stiffness
    only (exact for a position-based reference, not for A10); rigid or nonlinear: None.
    """
    env, rob = chain.environment, chain.robot
    stages = [e.kelvin_voigt() for e in (*env, *rob) if isinstance(e, Stage)]
    if not stages or any(kv is None for kv in stages):
        return None, False
    if not rob and len(env) == 1:
        return NominalEnvironment(*stages[0], 0.0), True
    if not rob and len(env) == 2 and isinstance(env[1], Mass):
        return NominalEnvironment(*stages[0], env[1].m), True
    return NominalEnvironment(1.0 / sum(1.0 / k for k, _ in stages)), False


# ---- reading ------------------------------------------------------------------------------
def _gain(r, name: str, default: float, unit: str) -> np.ndarray:
    if isinstance(r.raw(name, default), list):
        g = r.vector(name, unit=unit)
        if np.any(g < 0.0):
            raise r.error(name, f"gains >= 0 [{unit}]", g.tolist())
        return g
    return np.array([r.float(name, default, lo=0.0, unit=unit)])


def _nominal(r, need_dynamics: bool) -> NominalEnvironment | None:
    if not r.has("nominal"):
        return None
    n = r.sub("nominal")
    env = NominalEnvironment(n.float("k", lo=0.0, unit="N/m"), n.float("b", 0.0, lo=0.0, unit="N·s/m"),
                             n.float("m", 0.0, lo=0.0, unit="kg"))
    n.finish()
    if need_dynamics and env.m == 0.0 and env.b == 0.0:
        raise n.error("m", "m > 0 or b > 0 (A10 turns force into motion through the model's mass or damping)",
                      0.0)
    return env


def _axes(r) -> np.ndarray | None:
    if not r.has("axes"):
        return None
    raw = r.raw("axes")
    if not isinstance(raw, list) or not raw or not all(isinstance(a, list) for a in raw):
        raise r.error("axes", "a list of direction vectors", raw)
    from ...scene.reader import Reader

    axes = np.array([Reader({"a": a}, r.key("axes"), r.file).vector("a", size=3, unit_norm=True) for a in raw])
    if np.max(np.abs(axes @ axes.T - np.eye(len(axes)))) > 1e-9:
        raise r.error("axes", "mutually orthogonal directions", raw)
    return axes


def _inertia(r) -> str:
    return r.str("inertia", "model", choices=["model", "link"])


def _rotor_inertia(context: BindContext, inertia: str) -> np.ndarray:
    """Per joint, the reflected rotor inertia [kg·m²] to take out of the rigid model's H (``inertia = "link"``);
    empty for ``"model"`` (none taken out, as computed_torque reads it)."""
    if inertia == "model":
        return np.empty(0)
    names = context.joint_names
    specs = context.scene.robot.drive.expand(len(names), names)
    return np.array([s.reflected_inertia for s in specs])


# ---- shared task-space pieces ---------------------------------------------------------------
def _check_gain_size(g: np.ndarray, sizes: tuple[int, ...], key: str, file) -> None:
    if len(g) not in sizes:
        raise SceneError(key, f"one gain or {' or '.join(str(s) for s in sizes[1:])} (one per axis or joint)",
                         g.tolist(), file)


def pseudo_inverse(J: np.ndarray) -> np.ndarray:
    """J⁺ by linalg.pinv (a one-sided Jacobi SVD), singular values below 1e-10 of the largest
    dropped (numpy.linalg.pinv's rcond); one Jacobian (r, c) or a stack (N, r, c)."""
    J = _c(J)
    return current(compiled).pinv_stack(J) if J.ndim == 3 else current(compiled).pinv(J)


_NONE = np.empty(0)
#: (normals, touch, p_s, v_s, F_d, Ḟ_d, k) of no set-point (dynamic_law's arguments)
_NO_SET_POINTS = (np.zeros((0, 3)), _NONE, np.zeros((0, 3)), np.zeros((0, 3)), _NONE, _NONE, _NONE)


def _gains3(cfg) -> tuple[np.ndarray, np.ndarray]:
    """K_p, K_v per world axis (3) [1/s², 1/s]."""
    return (np.broadcast_to(np.asarray(cfg.kp, float), 3).copy(), np.broadcast_to(np.asarray(cfg.kv, float), 3).copy())


def _set_point_arrays(inp: ControlInput, keys: list[str], k: list[float]) -> tuple:
    """dynamic_law's per-set-point arrays (normals, touch, p_s, v_s, F_d, Ḟ_d, k) of the touching ``keys``."""
    n = len(keys)
    normals = np.array([inp.normals[key] for key in keys], dtype=float).reshape(n, 3)
    p_s = np.array([inp.surfaces[key][0] for key in keys], dtype=float).reshape(n, 3)
    v_s = np.array([inp.surfaces[key][1] for key in keys], dtype=float).reshape(n, 3)
    F_d = np.array([inp.force_d[key][0] for key in keys], dtype=float)
    dF_d = np.array([inp.force_d[key][1] for key in keys], dtype=float)
    return normals, np.ones(n), p_s, v_s, F_d, dF_d, np.array(k, dtype=float)


class _Pinv:
    """J⁺ of the last Jacobian (the command and its force columns read it at one state)."""

    def __init__(self):
        self.key: bytes = b""
        self.value = np.zeros((0, 0))

    def __call__(self, J: np.ndarray) -> np.ndarray:
        if J.ndim == 3:  # a stack of samples: not kept
            return pseudo_inverse(J)
        key = J.tobytes()
        if key != self.key:
            self.value = pseudo_inverse(J)
            self.key = key
        return self.value


def _contact_checks(context: BindContext, names: list[str], need_exact: bool, nominal, what: str
                    ) -> dict[str, NominalEnvironment]:
    """Resolve each force-controlled contact's nominal environment; the contact must be at the tip frame."""
    scene, key = context.scene, context.key
    out = {}
    for name in names:
        spec = scene.contacts[name]
        if spec.frame != scene.robot.tip:
            raise SceneError(f"contact.{name}.frame", f"the controlled tip frame {scene.robot.tip!r} ({what} "
                             "uses the tip Jacobian)", spec.frame, scene.file)
        if nominal is not None:
            out[name] = nominal
            continue
        env, exact = nominal_from_chain(spec.normal_chain)
        if env is None or (need_exact and not exact):
            raise SceneError(f"{key}.nominal", f"a nominal environment {{k, b, m}} for contact {name!r} ({what} "
                             "needs one: its normal model has no exact single-mass equivalent)", None, scene.file)
        out[name] = env
    return out


def _tangent_nominal(context: BindContext, force, nominal) -> NominalEnvironment:
    """The nominal stiffness along a tangential set-point: ``nominal``, or the tangential chain's series k."""
    scene, key = context.scene, context.key
    spec = scene.contacts[force.contact]  # (a tangential set-point has a chain: the scene reader asks for it)
    if nominal is not None:
        return nominal
    env, _ = nominal_from_chain(spec.tangent_chain)
    if env is None:
        raise SceneError(f"{key}.nominal", f"a nominal environment {{k}} for the tangential chain of contact "
                         f"{force.contact!r} (it has no linear series stiffness)", None, scene.file)
    return env


class _ComputedTorque(Controller):
    """The computed torque shared by A7 (task space), A10 and hybrid, around their tip targets.

    :meth:`tip_targets` gives (a*, f_swap, ż): the desired tip acceleration [m/s²], the tip force
    swapped into τ [N] (A10's cancel = "target") and the states' rates. They are affine in the
    tip's motion, the reference, the measured forces, the set-points, the surfaces and z (for a
    fixed contact mode): the solve folds the measured forces in. The targets are compiled once
    (:mod:`contactdyn.laws.controllers.dynamic_law`), here and in the one pipeline's call.
    """

    uses_forces = True
    reads_orientation = False

    def tip_targets(self, inp: ControlInput) -> tuple:
        raise NotImplementedError

    def computed_torque(self, inp: ControlInput, a: np.ndarray, f_swap: np.ndarray | None) -> np.ndarray:
        """τ = H q̈*(a) + h − τ_c (+ Jᵀ f_swap) [N·m or N] at ``inp``."""
        return self.torque(inp.H, inp.h, inp.tau_contact, inp.J, inp.drift, inp.v, a, f_swap)

    def torque(self, H: np.ndarray, h: np.ndarray, tau_c: np.ndarray, J: np.ndarray, drift: np.ndarray,
               v: np.ndarray, a: np.ndarray, f_swap: np.ndarray | None) -> np.ndarray:
        """τ = H q̈* + h − τ_c (+ Jᵀ f_swap) [N·m or N], q̈* = J⁺(a − J̇q̇) − (I − J⁺J) k_null q̇ for the tip
        acceleration a [m/s²], from the model's terms (J: the tip Jacobian (3, nv), drift: J̇q̇ [m/s²], v: q̇;
        :meth:`computed_torque` passes a ControlInput's: one sample, or a stack of the output's samples)."""
        rotor, k_null = self._rotor, float(self.config.k_null)
        stack = J.ndim == 3  # a stack of samples: one sample's arithmetic each
        Jp = self._pinv(J)
        if f_swap is None:
            f_swap = np.empty(a.shape[:-1] + (0,))
        args = (_c(H), rotor, _c(h), _c(tau_c), _c(J), Jp, _c(drift), _c(v), _c(a), _c(f_swap), k_null)
        return current(compiled).torque_stack(*args) if stack else current(compiled).torque(*args)


# ---- A7 -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PositionDynamicConfig:
    space: str  #: "joint" or "task"
    kp: np.ndarray  #: [1/s²], one, or per joint / per world axis
    kv: np.ndarray  #: [1/s]
    k_null: float  #: [1/s]
    force_reference: bool
    nominal: NominalEnvironment | None
    inertia: str = "model"  #: "model" (link + reflected rotor) or "link" (link only)
    kind: str = "position_dynamic"


@register
class PositionDynamic(_ComputedTorque):
    """A7: tau = H q" + h - tau_c with error dynamics eta" = -kp eta - kv eta', in joint or task space."""

    name = "position_dynamic"

    @staticmethod
    def applies_force_setpoints(config: PositionDynamicConfig) -> bool:
        return config.force_reference  # the reference becomes the depth that gives F_d

    @staticmethod
    def read(r) -> PositionDynamicConfig:
        return PositionDynamicConfig(
            space=r.str("space", "task", choices=["joint", "task"]),
            kp=_gain(r, "kp", KP, "1/s²"), kv=_gain(r, "kv", KV, "1/s"),
            k_null=r.float("k_null", K_NULL, lo=0.0, unit="1/s"),
            force_reference=r.bool("force_reference", False),
            nominal=_nominal(r, need_dynamics=False), inertia=_inertia(r))

    def bind(self, context: BindContext) -> None:
        self._pinv = _Pinv()
        self._rotor = _rotor_inertia(context, self.config.inertia)
        cfg, key, file = self.config, context.key, context.scene.file
        dims = self.nv if cfg.space == "joint" else 3
        for name in ("kp", "kv"):
            _check_gain_size(getattr(cfg, name), (1, dims), f"{key}.{name}", file)
        self._gains3 = _gains3(cfg) if cfg.space == "task" else None  # (after the check: its SceneError first)
        #: K_p [1/s²], K_v [1/s] per joint (joint space; dynamic_law.joint_targets')
        self.joint_gains = tuple(np.broadcast_to(np.asarray(g, float), self.nv).copy() for g in (cfg.kp, cfg.kv)) \
            if cfg.space == "joint" else None
        ref = context.phase.reference
        if ref is not None and ref.space != cfg.space:
            raise SceneError(f"phase[{context.index}].reference.space", f"{cfg.space!r} (the controller's space)",
                             ref.space, file)
        self.envs: dict[str, NominalEnvironment] = {}
        if cfg.force_reference:
            if cfg.space != "task":
                raise SceneError(f"{key}.force_reference", "task space (the reference moves along contact normals)",
                                 "joint space", file)
            forces = context.phase.forces
            normals = _contact_checks(context, [f.contact for f in forces if f.direction == "n"], False,
                                      cfg.nominal, "force_reference")
            self.envs = {f.key: normals[f.contact] if f.direction == "n" else
                         _tangent_nominal(context, f, cfg.nominal) for f in forces}

    def command(self, inp: ControlInput) -> tuple[np.ndarray, None]:
        cfg = self.config
        if cfg.space == "task":
            return self.computed_torque(inp, *self.tip_targets(inp)[:2]), None
        ref = (_c(inp.x_d), _c(inp.v_d), _c(inp.a_d)) if inp.x_d is not None else (_NONE, _NONE, _NONE)
        qdd = current(dynamic_law).joint_targets(_c(inp.q), _c(inp.v), *ref, *self.joint_gains)
        return current(compiled).joint_torque(_c(inp.H), self._rotor, _c(inp.h), _c(inp.tau_contact), qdd), None

    def tip_targets(self, inp: ControlInput) -> tuple[np.ndarray, None, None]:
        """(a*, no force swap, no states): the desired tip acceleration [m/s²] of the task-space law
        (:func:`~.dynamic_law.position_targets`). With ``force_reference``, along each touching contact's set-point
        direction n (normal or tangent) the reference is F_d/k beyond the undeformed surface or tangential anchor,
        along −n; the surface's acceleration along n and F̈_d/k are left out (a_d's component along n is 0)."""
        kp, kv = self._gains3
        targets = current(dynamic_law).position_targets
        if inp.x_d is None:
            a = targets(_c(inp.p_tip), _c(inp.v_tip), _NONE, _NONE, _NONE, kp, kv, False, *_NO_SET_POINTS)
            return a, None, None
        keys = [name for name in self.envs if inp.touching.get(name.partition(".")[0]) and name in inp.force_d]
        set_points = _set_point_arrays(inp, keys, [self.envs[k].k for k in keys]) if keys else _NO_SET_POINTS
        return targets(_c(inp.p_tip), _c(inp.v_tip), _c(inp.x_d), _c(inp.v_d), _c(inp.a_d), kp, kv, bool(keys),
                       *set_points), None, None


# ---- A10 and hybrid ---------------------------------------------------------------------------
@dataclass(frozen=True)
class ForceDynamicConfig:
    kp: np.ndarray  #: [1/s²] position transient (hybrid) — one, or per world axis
    kv: np.ndarray  #: [1/s] position transient / damping of the free directions
    kf: float  #: [1/s] force error rate, Q(μ) = −K_F μ
    k_null: float  #: [1/s]
    axes: np.ndarray | None  #: (k, 3) position-controlled directions (hybrid), None: complement of the normals
    nominal: NominalEnvironment | None
    cancel: str = "target"  #: along the normals τ −= Jᵀ n F*, F* = F_d + ∫Q ("target", A10) or Jᵀ n F ("measured")
    inertia: str = "model"  #: "model" (link + reflected rotor) or "link" (link only)
    kind: str = "force_dynamic"


@register
class ForceDynamic(_ComputedTorque):
    """A10: the force set-point F* = F_d + integral of -kf (F - F_d) along the normals, via the nominal surface."""

    name = "force_dynamic"
    tracks_position = False

    @staticmethod
    def applies_force_setpoints(config: ForceDynamicConfig) -> bool:
        return True

    @classmethod
    def read(cls, r) -> ForceDynamicConfig:
        return ForceDynamicConfig(
            kp=_gain(r, "kp", KP, "1/s²") if cls.tracks_position else np.array([KP]),
            kv=_gain(r, "kv", KV, "1/s"),
            kf=r.float("kf", KF, lo=0.0, lo_open=True, unit="1/s"),
            k_null=r.float("k_null", K_NULL, lo=0.0, unit="1/s"),
            axes=_axes(r) if cls.tracks_position else None,
            nominal=_nominal(r, need_dynamics=True),
            cancel=r.str("cancel", "target", choices=["target", "measured"]), inertia=_inertia(r), kind=cls.name)

    def bind(self, context: BindContext) -> None:
        self._pinv = _Pinv()
        self._rotor = _rotor_inertia(context, self.config.inertia)
        cfg, key, file, phase = self.config, context.key, context.scene.file, context.phase
        for name in ("kp", "kv"):
            _check_gain_size(getattr(cfg, name), (1, 3), f"{key}.{name}", file)
        names = [f.contact for f in phase.forces]
        if not names:
            raise SceneError(f"phase[{context.index}].force", f"a force set-point ({self.name} controls force "
                             "along contact normals)", [], file)
        ref = phase.reference
        if self.tracks_position and (ref is None or ref.space != "task"):
            raise SceneError(f"phase[{context.index}].reference", "a task-space reference (hybrid tracks "
                             "position along its axes)", None if ref is None else ref.space, file)
        if not self.tracks_position and ref is not None:
            raise SceneError(f"phase[{context.index}].reference", "no reference (force_dynamic is a pure force "
                             "law; use hybrid to track position along other directions)", ref.space, file)
        self.envs = _contact_checks(context, names, True, cfg.nominal, self.name)
        self.names = names
        self.n_states = len(names)  # ∫Q(μ) dt per force-controlled contact [N]
        normals = np.array([context.scene.contacts[n].normal for n in names])
        if cfg.axes is not None:
            if np.max(np.abs(cfg.axes @ normals.T)) > 1e-9:
                raise SceneError(f"{key}.axes", "directions orthogonal to the force-controlled normals "
                                 f"{normals.tolist()}", cfg.axes.tolist(), file)
            axes = cfg.axes
        else:  # the orthogonal complement of the normals
            _, sv, vt = np.linalg.svd(normals)
            axes = vt[int(np.sum(sv > 1e-9)):]
        self.P = _c(axes.T @ axes)  #: projector on the position-controlled directions
        self._gains3 = _gains3(cfg)
        self._env = np.array([[self.envs[n].k, self.envs[n].b, self.envs[n].m] for n in names]).reshape(-1, 3)

    def command(self, inp: ControlInput) -> tuple[np.ndarray, np.ndarray]:
        a, f_swap, zdot = self.tip_targets(inp)
        return self.computed_torque(inp, a, f_swap), zdot

    def tip_targets(self, inp: ControlInput) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """(a* [m/s²], the tip force swapped into τ [N] (cancel = "target"; else None), ż [N/s]):
        :func:`~.dynamic_law.force_targets` on the set-points' arrays (a contact not touching reads no force)."""
        cfg = self.config
        touch = np.array([1.0 if inp.touching.get(name) else 0.0 for name in self.names])
        ns = len(self.names)
        normals = np.array([inp.normals[name] for name in self.names], dtype=float).reshape(ns, 3)
        p_s, v_s, F = np.zeros((ns, 3)), np.zeros((ns, 3)), np.zeros(ns)
        F_d, dF_d = np.zeros(ns), np.zeros(ns)
        for i, name in enumerate(self.names):
            if touch[i]:
                p_s[i], v_s[i] = inp.surfaces[name]
                F_d[i], dF_d[i] = inp.force_d[name]
                F[i] = inp.forces[name]
        ref = (_c(inp.x_d), _c(inp.v_d), _c(inp.a_d)) if self.tracks_position else (_NONE, _NONE, _NONE)
        kp, kv = self._gains3
        targets = current(dynamic_law).force_targets
        a, f_swap, zdot = targets(self.P, _c(inp.p_tip), _c(inp.v_tip), *ref, kp, kv, float(cfg.kf), normals, touch,
                                  p_s, v_s, F_d, dF_d, F, _c(inp.z), self._env, self.tracks_position)
        return a, (f_swap if cfg.cancel == "target" else None), zdot


@register
class Hybrid(ForceDynamic):
    """A7 along the position axes and A10 along the force normals (the paper's case 2)."""

    name = "hybrid"
    tracks_position = True
