"""Automatic gain tuning of any closed loop of :mod:`vcjax.loops` by gradient descent through it.

Modules: :mod:`tuning.params` (unconstrained parametrisation of a loop's gain groups),
:mod:`tuning.scenarios` (random batches of a loop's scenarios, drawn like a sweep's),
:mod:`tuning.loss` (tracking/saturation loss, mean or CVaR over a batch), :mod:`tuning.optim`
(optax L-BFGS/Adam, guarded, one jit per step), :mod:`tuning.blackbox` (CMA-ES with pycma, and
random search, as baselines), :mod:`tuning.config` (TOML), :mod:`tuning.cli`
(:func:`run_tune_config`, what ``vcjax tune`` runs).
"""

from tuning.cli import run_tune_config
from tuning.loss import TuningProblem, loss_weights, objective, problem_data
from tuning.optim import run_gradient_tuner
from tuning.params import GainSpace
from tuning.scenarios import sample_scenarios

__all__ = [
    "GainSpace",
    "TuningProblem",
    "loss_weights",
    "objective",
    "problem_data",
    "run_gradient_tuner",
    "run_tune_config",
    "sample_scenarios",
]
