"""Automatic gain tuning of any closed loop of [`vcjax.loops`][vcjax.loops] by gradient descent
through it.

Modules: [`tuning.params`][tuning.params] (unconstrained parametrisation of a loop's gain groups),
[`tuning.scenarios`][tuning.scenarios] (random batches of a loop's scenarios, drawn like a sweep's),
[`tuning.loss`][tuning.loss] (tracking/saturation loss, mean or CVaR over a batch),
[`tuning.optim`][tuning.optim]
(optax L-BFGS/Adam, guarded, one jit per step), [`tuning.blackbox`][tuning.blackbox] (CMA-ES with
pycma, and
random search, as baselines), [`tuning.config`][tuning.config] (TOML), [`tuning.run`][tuning.run]
([`run_tune_config`][tuning.run.run_tune_config], what ``vcjax tune`` runs: the one command line
of the tuner).
"""

from tuning.loss import TuningProblem, loss_weights, objective, problem_data
from tuning.optim import TunerHooks, TunerOptions, run_gradient_tuner
from tuning.params import GainSpace
from tuning.run import run_tune_config
from tuning.scenarios import sample_scenarios

__all__ = [
    "GainSpace",
    "TunerHooks",
    "TunerOptions",
    "TuningProblem",
    "loss_weights",
    "objective",
    "problem_data",
    "run_gradient_tuner",
    "run_tune_config",
    "sample_scenarios",
]
