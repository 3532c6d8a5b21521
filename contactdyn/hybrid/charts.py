"""A free body's chart switch: an event of the hybrid loop that changes coordinates, not motion.

A free body's angles are ZYX Euler angles in one of two charts (:mod:`contactdyn.robot.free_chart`), the one in
use a discrete state in x (constant between events, like a contact mode). Its ``chart`` event fires when |cos| of
the active chart's pitch falls through ``SWITCH_COS`` (the event function |cos a2| − SWITCH_COS, located like the
others; never zero at a segment's start: a switch lands at |cos| ≥ √0.75). The handler (:func:`on_chart`)
re-expresses the body's six coordinates in the other chart: the same position, rotation, angular velocity and
origin velocity; no impulse, the energy the same to rounding; the modes stay as they are.
"""

from __future__ import annotations

import math

import numpy as np

from ..model.system import System
from ..robot.free_chart import SWITCH_COS
from .events import terminal_event

__all__ = ["chart_events", "on_chart"]


def chart_events(system: System) -> list:
    """The ``chart`` event of each free body (its name the event's ``contact``)."""
    out = []
    for name, body in system.articulated.items():
        if body.free:
            i = body.first + body.pitch
            out.append(terminal_event(lambda t, x, i=i: abs(math.cos(float(x[i]))) - SWITCH_COS, "chart", name))
    return out


def on_chart(transitions, t: float, x: np.ndarray, modes, phase, event, after):
    """The body of a located ``chart`` event in its other chart (a Transitions handler: (x, phase, settle)); the
    event's log entry says which chart it is in now (``to``: "A" or "B")."""
    system = transitions.system
    body = system.articulated[event.contact]
    x = body.switched(x, system.nQ)
    transitions.log.events[-1]["to"] = "AB"[body.chart_of(x)]
    return x, phase, False
