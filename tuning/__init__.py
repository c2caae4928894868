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
of the tuner), [`tuning.command`][tuning.command] (``vcjax tune`` itself, plugged into ``vcjax``'s
command line by an entry point: ``vcjax`` never imports ``tuning``).
"""

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the names below, imported on first use (``__getattr__``)
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

#: where each exported name lives: ``import tuning`` (and ``vcjax``'s CLI finding the ``tune``
#: command, [`tuning.command`][tuning.command]) imports none of them, so nothing is built before
#: ``vcjax tune`` has chosen the precision (the loops build constants at import)
_HOME = {
    "TuningProblem": "tuning.loss",
    "loss_weights": "tuning.loss",
    "objective": "tuning.loss",
    "problem_data": "tuning.loss",
    "TunerHooks": "tuning.optim",
    "TunerOptions": "tuning.optim",
    "run_gradient_tuner": "tuning.optim",
    "GainSpace": "tuning.params",
    "run_tune_config": "tuning.run",
    "sample_scenarios": "tuning.scenarios",
}


def __getattr__(name):
    """The names of ``__all__``, imported from their modules on first use."""
    if name in _HOME:
        import importlib

        return getattr(importlib.import_module(_HOME[name]), name)
    raise AttributeError(f"module 'tuning' has no attribute {name!r}")
