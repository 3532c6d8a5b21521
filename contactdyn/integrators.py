"""Integrators for the smooth phases: scipy's ``solve_ivp`` methods, by name."""

from __future__ import annotations

__all__ = ["METHODS", "IMPLICIT"]

#: explicit Runge–Kutta methods and the implicit ones for stiff scenes
METHODS = ("DOP853", "RK45", "RK23", "Radau", "BDF", "LSODA")
IMPLICIT = ("Radau", "BDF", "LSODA")
