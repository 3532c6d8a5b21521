"""What a run may cost, checked before it starts: samples, steps, duration, reference moves, memory.

Every bound is a named constant, generous for real tasks (the paper's runs are seconds long
at 1 kHz output) and small enough that a typo (``duration = 1e308``, ``max_step = 1e-300``,
``output_rate = 1e7``) is a :class:`~contactdyn.errors.SceneError` naming the key, not a run
that never ends or fills the memory.
"""

from __future__ import annotations

import math

from ..errors import SceneError

__all__ = ["MAX_DURATION", "MAX_SAMPLES", "MAX_STEPS", "MAX_MOVES", "MAX_PHASES", "MAX_RUN_MEMORY", "STEPS_BASE",
           "STEPS_PER_SAMPLE", "check_budget", "available_memory", "step_budget", "sample_rate"]

STEPS_BASE = 20_000  #: integration steps every run may take, besides solver.steps_per_second × duration
#: integration steps a sampled law's sample adds to the budget: each sample instant is a step boundary, so a period
#: takes a step at least, two where the step that reaches the instant is clipped (contactdyn.numerics.held_steps)
STEPS_PER_SAMPLE = 2

MAX_DURATION = 1e4  #: [s] simulated at most
MAX_SAMPLES = 10**7  #: output samples (duration × output_rate) at most
MAX_STEPS = 10**7  #: integration steps implied by duration / max_step at most
MAX_MOVES = 64  #: moves of one reference (each adds a kink and a term to every evaluation: cost ~ moves²)
MAX_PHASES = 1000  #: phases of a scene (each builds its own controller and pipelines)
#: [B] a run's peak memory per output sample (states, channels, their saved copy): 1325 B measured for B1 at
#: 2e6 samples (output_rate = 1e7 over 0.2 s peaked at 2.65 GB), with a margin
BYTES_PER_SAMPLE = 1536
MAX_RUN_MEMORY = 2 * 2**30  #: [B] a run's samples may need at most this (and at most the free memory)


def check_budget(scene) -> None:
    """Raise SceneError when the scene would cost more than the bounds (or the free memory) allow."""
    file = scene.file
    if scene.duration > MAX_DURATION:
        raise SceneError("duration", f"a number <= {MAX_DURATION:g} [s] (a run's length is bounded)",
                         scene.duration, file)
    solver = scene.solver
    samples = scene.duration * solver.output_rate + 1
    if samples > MAX_SAMPLES:
        raise SceneError("solver.output_rate", f"at most {MAX_SAMPLES:.0e} samples over the run "
                         f"(duration × output_rate; this is {samples:.3g})", solver.output_rate, file)
    steps = scene.duration / solver.max_step
    if steps > MAX_STEPS:
        raise SceneError("solver.max_step", f"at most {MAX_STEPS:.0e} steps over the run (duration / max_step; "
                         f"this is {steps:.3g}): a larger step or a shorter run", solver.max_step, file)
    for i, phase in enumerate(scene.phases):
        instants = scene.duration * (phase.sampling.rate if phase.sampling is not None else 0.0)
        if instants > MAX_STEPS:
            raise SceneError(f"{phase.controller_key}.sample_rate", f"at most {MAX_STEPS:.0e} samples over the run "
                             f"(duration × sample_rate, each a step at least; this is {instants:.3g}): a lower rate "
                             "or a shorter run", phase.sampling.rate, file)
        moves = len(phase.reference.moves) if phase.reference is not None else 0
        if moves > MAX_MOVES:
            raise SceneError(f"phase[{i}].reference.moves", f"at most {MAX_MOVES} moves", f"{moves} moves", file)
    if len(scene.phases) > MAX_PHASES:
        raise SceneError("phase", f"at most {MAX_PHASES} phases", f"{len(scene.phases)} phases", file)
    need = samples * BYTES_PER_SAMPLE
    free = min(available_memory(), MAX_RUN_MEMORY)
    if need > free:
        raise SceneError("solver.output_rate", f"a run that fits in memory: {samples:.3g} samples would need "
                         f"about {need / 2**30:.2g} GiB, at most {free / 2**30:.2g} GiB are allowed (a run's bound "
                         f"is {MAX_RUN_MEMORY / 2**30:g} GiB, or the free memory if less)", solver.output_rate, file)


def available_memory() -> float:
    """[B] memory this process may still use: MemAvailable, or the address-space limit if lower."""
    import resource

    free = math.inf
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    free = int(line.split()[1]) * 1024
    except (OSError, ValueError):
        pass
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        free = min(free, soft / 2)  # about half the address space is already libraries and the heap
    return free


def step_budget(solver, duration: float, rate: float = 0.0) -> int:
    """The run's integration steps at most: STEPS_BASE + (solver.steps_per_second + STEPS_PER_SAMPLE × rate) ×
    duration [s]; ``rate`` [Hz]: the scene's highest sample rate (:func:`sample_rate`; 0: none sampled)."""
    return int(STEPS_BASE + (solver.steps_per_second + STEPS_PER_SAMPLE * rate) * duration)


def sample_rate(scene) -> float:
    """[Hz] The highest sample rate of the scene's phases' controllers (0: all continuous)."""
    return max((p.sampling.rate for p in scene.phases if p.sampling is not None), default=0.0)
