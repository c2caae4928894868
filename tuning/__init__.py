"""Automatic gain tuning of the VCM controller by gradient descent through the closed loop.

Modules: :mod:`tuning.params` (unconstrained parametrisation), :mod:`tuning.scenarios` (random
Simulation 1 batches), :mod:`tuning.loss` (tracking/saturation loss, mean or CVaR over a batch),
:mod:`tuning.optim` (optax L-BFGS/Adam, guarded, one jit per step), :mod:`tuning.blackbox`
(CMA-ES with pycma, and random search, as baselines), :mod:`tuning.config` (TOML),
:mod:`tuning.cli` (:func:`run_tune_config`, what ``vcjax tune`` runs).
"""

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
    "sample_scenarios",
]
