"""Numerics without physics: small linear solves (numba), the integrators' method table, and the compiled
DOP853 and LSODA cores."""
