"""System identification: fit a vehicle's plant parameters to logged runs (``vcjax fit``).

* [`data`][vcjax.identify.data]: CSV / npz logs, checked eagerly (file, column and line named).
* [`models`][vcjax.identify.models]: per-vehicle channels and one discrete step (PVS or integrator).
* [`lm`][vcjax.identify.lm]: Levenberg–Marquardt for the block-arrow multiple-shooting problem.
* [`shooting`][vcjax.identify.shooting]: the multiple-shooting problem (segments, scaling,
residuals).
* [`fit`][vcjax.identify.fit]: the fit (two weighted fits), standard errors, correlations and
  identifiability warnings, [`FitResult`][vcjax.identify.fit.FitResult].
* [`config`][vcjax.identify.config]: the TOML schema and the runner writing ``fit.json`` and
figures.
"""

from vcjax.identify.config import load_fit_config, run_fit_config
from vcjax.identify.data import Log, load_log, save_log_csv
from vcjax.identify.fit import FitResult, FitSettings, fit_logs
from vcjax.identify.lm import LMOptions, levenberg_marquardt, schur_information
from vcjax.identify.models import FIT_MODELS, FitModel, current_vector, get_fit_model
from vcjax.identify.shooting import ShootingProblem, make_segments

__all__ = [
    "FIT_MODELS",
    "FitModel",
    "FitSettings",
    "FitResult",
    "LMOptions",
    "Log",
    "ShootingProblem",
    "current_vector",
    "fit_logs",
    "get_fit_model",
    "levenberg_marquardt",
    "load_fit_config",
    "load_log",
    "make_segments",
    "run_fit_config",
    "save_log_csv",
    "schur_information",
]
