"""Analyses over many runs: the stability maps of the force laws and work-precision (speed against error)."""
