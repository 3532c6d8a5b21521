"""The compiled plan: one mode of the model made fast (today read off the readable model by unit probes,
with numba kernels); the notice printed while it compiles."""
