"""A deformation chain: Kelvin–Voigt stages and equivalent masses along one direction.

The chain runs along a unit direction u from the environment body (the *anchor*) to the
robot's tip. Elements listed for the environment side start at the anchor; those for the
robot side start at the tip; the two sides meet at the contact *interface*. Nodes:

- ``TIP`` and ``ANCHOR`` move with the robot and the environment body (kinematic);
- ``MASS`` is an equivalent mass, a second-order coordinate of its own;
- ``FREE`` is a massless node: between two stages it is a junction (a first-order state
  when the stages have damping, an algebraic point when they have none or the same time
  constant b/k, see :func:`balanced`); at a free end it follows its stage's other node (a
  massless stage carries no force unloaded).

At the interface, touching merges the two surface nodes: two *solid* nodes (tip, anchor
or mass) make a bond, a constraint row with an unknown force and a plastic impact at
touch; a free end merges with what it touches; two free ends make a junction. All
positions are scalars along u [m]; zero rest lengths (deformation zero at first touch).
A stage's compression is x = s_lower − s_upper (lower = nearer the anchor) and its force
F = k x + b ẋ pushes its upper node along +u.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from ..errors import SceneError
from ..laws.elements import ChainSpec, Mass, Stage
from ..laws.stage_laws import STAGE_LAWS, kelvin_voigt

__all__ = ["NodeKind", "ChainNode", "ChainStage", "Chain", "build_chain", "balanced"]


class NodeKind(IntEnum):
    TIP = 0
    ANCHOR = 1
    MASS = 2
    FREE = 3


@dataclass
class ChainNode:
    kind: NodeKind
    mass: float = 0.0  #: [kg], MASS only
    coord: int = -1  #: index of the generalized coordinate (MASS), set by the system
    state: int = -1  #: index of the first-order state (FREE junctions), set by the system
    side: str = "environment"


@dataclass
class ChainStage:
    lower: int  #: node index nearer the anchor
    upper: int  #: node index nearer the tip
    k: float  #: [N/m]
    b: float  #: [N·s/m]
    law: str = "linear"  #: a name in contactdyn.laws.stage_laws.STAGE_LAWS
    params: tuple[float, ...] = ()  #: the law's own parameters (its declared order)
    side: str = "environment"
    label: str = ""  #: e.g. "env1" (from the anchor) or "rob1" (from the tip)

    def __post_init__(self) -> None:
        self._law = STAGE_LAWS[self.law]
        #: (K [N/m], B [N·s/m]) of an affine law, F = K x + B ẋ; None for another
        self.kelvin_voigt = kelvin_voigt(self.law, self.k, self.b, self.params)

    @property
    def law_class(self) -> type:
        """The stage's law (a :class:`~contactdyn.laws.stage_laws.StageLaw` subclass)."""
        return self._law

    def force(self, x: float, xdot: float) -> float:
        """Compressive force [N] at compression x [m] and rate ẋ [m/s] (the stage's law)."""
        return self._law.force(self.k, self.b, self.params, x, xdot)

    def potential(self, x: float) -> float | None:
        """Energy [J] stored at compression x [m], None if the law does not say (see StageLaw.potential)."""
        return self._law.potential(self.k, self.params, x)


@dataclass
class Chain:
    """A compiled chain: nodes, stages and the two interface nodes."""

    nodes: list[ChainNode]
    stages: list[ChainStage]
    env_surface: int  #: node index of the environment's surface node
    robot_surface: int  #: node index of the robot's surface node
    tip: int
    anchor: int

    @property
    def bonded_when_touching(self) -> bool:
        """Touching makes a constraint row (and an impact): both surface nodes are solid."""
        nodes = self.nodes
        return nodes[self.env_surface].kind != NodeKind.FREE and nodes[self.robot_surface].kind != NodeKind.FREE

    @property
    def junction_when_touching(self) -> bool:
        nodes = self.nodes
        return nodes[self.env_surface].kind == NodeKind.FREE and nodes[self.robot_surface].kind == NodeKind.FREE

    def stages_of(self, node: int) -> list[int]:
        return [i for i, s in enumerate(self.stages) if node in (s.lower, s.upper)]


def balanced(stages: list[ChainStage]) -> bool:
    """A junction between these linear stages stays where their springs balance (no state needed).

    Its imbalance g = Σ ± k x (the stages' spring forces on it) obeys g + τ ġ = 0 when every
    stage has the same time constant τ = b / k [s] (their dampers balance as their springs do),
    so g stays zero from a balanced start: chains start undeformed, a touch starts the junction
    balanced and, after a separation, ends with the same τ relax keeping g = 0. Then the junction
    is the algebraic point of an undamped one (b = 0 is τ = 0), not a mode decaying at 1/τ that
    holds an explicit integrator's step to |h / τ| ≲ 6.
    """
    if any(s.kelvin_voigt is None or s.kelvin_voigt[0] <= 0.0 for s in stages):
        return False
    tau = [s.kelvin_voigt[1] / s.kelvin_voigt[0] for s in stages]
    return all(math.isclose(t, tau[0], rel_tol=1e-12, abs_tol=0.0) for t in tau)


def build_chain(spec: ChainSpec, where: str) -> Chain:
    """Compile a chain spec; ``where`` names it in errors (e.g. ``contact.tip.normal``)."""
    nodes: list[ChainNode] = [ChainNode(NodeKind.ANCHOR), ChainNode(NodeKind.TIP, side="robot")]
    stages: list[ChainStage] = []

    def walk(elements: tuple, start: int, side: str) -> int:
        current = start
        n_stages = 0
        for i, element in enumerate(elements):
            if isinstance(element, Mass):
                if nodes[current].kind != NodeKind.FREE:
                    raise SceneError(f"{where}.{side}[{i}]", "a stage {k, b} between a mass and the body, tip or "
                                     "another mass", f"mass {element.m} kg right after a solid node")
                nodes[current].kind = NodeKind.MASS
                nodes[current].mass = element.m
            elif isinstance(element, Stage):
                nodes.append(ChainNode(NodeKind.FREE, side=side))
                new = len(nodes) - 1
                lower, upper = (current, new) if side == "environment" else (new, current)
                n_stages += 1
                label = f"{side[:3]}{n_stages}"  # env1, env2 ... from the body; rob1 ... from the tip
                stages.append(ChainStage(lower, upper, element.k, element.b, element.law, element.params, side,
                                         label))
                current = new
        return current

    env_surface = walk(spec.environment, 0, "environment")
    robot_surface = walk(spec.robot, 1, "robot")
    chain = Chain(nodes, stages, env_surface, robot_surface, tip=1, anchor=0)
    _check(chain, where)
    return chain


def _check(chain: Chain, where: str) -> None:
    for i, node in enumerate(chain.nodes):
        if node.kind != NodeKind.FREE:
            continue
        attached = chain.stages_of(i)
        interface = i in (chain.env_surface, chain.robot_surface)
        if len(attached) == 2 or (interface and chain.junction_when_touching):
            neighbours = [chain.stages[s] for s in attached]
            for s in neighbours:
                other = s.lower if s.upper == i else s.upper
                if chain.nodes[other].kind == NodeKind.FREE and len(chain.stages_of(other)) == 2:
                    raise SceneError(where, "a mass between every two junctions (three stages in a row)",
                                     "adjacent massless junctions")
                if s.kelvin_voigt is None:
                    raise SceneError(where, "affine stage laws at massless junctions (a law like Hunt–Crossley "
                                     "needs the tip, a mass or the body on both ends)", s.law)
