"""Batch simulation: a scene run over a grid of overrides, on a process pool or a Dask cluster.

A sweep is a base scene, fixed overrides (``--set``) and the cases: the Cartesian product
of the axes (``--grid key=v1,v2``, ``--range key=lo:hi:n[:log]``), optionally times a list
of explicit runs from a sweep file. Each case is one run whose id is a stable hash of its
overrides (fixed and varied), so the same case always lands in the same files:

- ``OUT/runs/<id>.npz`` + ``.json``: the run's :class:`~contactdyn.output.result.Result`
  (``<id>.failed.json`` instead, with the error, when the run failed);
- ``OUT/summary.parquet`` (and ``summary.csv`` on request): one row per run, sorted by the swept parameters:
  the varied parameters, status, error message, wall time [s] and the key metrics
  (:mod:`contactdyn.output.metrics`);
- ``OUT/sweep.json``: the base scene document, fixed overrides and the cases.

Every file is written atomically; each chunk's rows go to a part file of their own
(``OUT/summary.parts/``), merged into the summary when the sweep ends and in between every
30 s or more (:mod:`.summary`: a cost linear in the runs), so an interrupted sweep loses at
most the runs in progress, and re-running the same command skips the runs whose files exist.
A run that fails (a bad parameter combination, a solver failure, a blow-up) is a row with
status ``failed`` (a :class:`ContactdynError` or a numerical failure such as ``LinAlgError``,
or a process that died: the run is then run again alone and recorded with the signal) or
``crashed`` (any other exception, i.e. a bug) and its message; the other runs go on.
Workers end with the sweep however it ends, and one sweep at a time writes into an ``OUT``
(``OUT/.sweep.lock``).
Apart from the wall time (``wall_s`` in the summary, ``stats.wall_s`` and
``stats.real_time_factor`` in each ``<id>.json``) the outputs are bit-identical for the
same inputs.

Sweep file (TOML)::

    scene = "b1"                                   # a path (relative to this file) or a name in sims/
    [set]                                          # fixed overrides
    duration = 0.5
    [grid]                                         # one axis per key: a list of values
    "contact.tip.normal.k" = [1e4, 1e5, 1e6]
    [range]                                        # lo, hi, n (and log = true for log spacing)
    "controller.kp" = { lo = 100.0, hi = 1e4, n = 5, log = true }
    [[run]]                                        # explicit runs, each crossed with the axes
    "solver.method" = "RK45"

Modules: :mod:`.plan` (what runs: axes, sweep files, run ids, validation of every case),
:mod:`.execute` (where: this process, a process pool, Dask; chunks of runs), :mod:`.workers`
(the workers' lifetime, runs in processes of their own), :mod:`.store` (the files, the lock),
:mod:`.summary` (the summary table and its part files), :mod:`.report` (failures for the console, a metric
plotted over a parameter).
"""

from .execute import NUMERICAL, SweepReport, process_pool, run_chunk, run_sweep, stop_pool
from .plan import Sweep, check_sweep, load_sweep_file, make_sweep, parse_grid, parse_range, run_id
from .store import STATUSES, result_row

__all__ = ["Sweep", "SweepReport", "parse_grid", "parse_range", "load_sweep_file", "make_sweep", "check_sweep",
           "run_id", "run_sweep", "run_chunk", "result_row", "NUMERICAL", "STATUSES", "process_pool",
           "stop_pool"]
