"""Numerics without physics: small linear solves (numba), the integrators' method table, the compiled
DOP853 and LSODA cores, and where compiled code is cached (one directory per build) and announced."""
