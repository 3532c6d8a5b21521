"""Identify the environment from measurements: fit scene parameters to a logged run.

``contactdyn fit SCENE --data LOG.csv --params KEY[=LOW:HIGH],...`` (or
``contactdyn.fit(scene, data, params)``) adjusts numeric scene keys (stiffness, damping,
equivalent mass, friction, ...) so that full simulations of the scene reproduce the logged
channels, each weighted by its noise level, and reports what the data determine.

Modules: :mod:`.data` (the CSV log, noise levels), :mod:`.params` (keys, bounds, log
scale), :mod:`.model` (runs read at the data's times, on the process pool),
:mod:`.solver` (least squares, finite-difference Jacobian, starts), :mod:`.uncertainty`
(standard errors, intervals, correlations, warnings), :mod:`.fitting` (``fit``),
:mod:`.report` (text, JSON, Markdown, figure, fitted scene), :mod:`.command` (the CLI).
"""

from .command import fit_command
from .data import Column, Measurements, estimate_noise, measurements
from .fitting import FitResult, fit
from .params import Parameter, parse_params
from .report import save_scene, write_report

__all__ = ["fit", "FitResult", "fit_command", "measurements", "Measurements", "Column", "estimate_noise",
           "Parameter", "parse_params", "write_report", "save_scene"]
