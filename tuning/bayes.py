"""Bayesian optimisation baseline: optuna's tree-structured Parzen estimator (TPE), driven in
batches through the same harness as CMA-ES ([`generation_loop`][tuning.blackbox.generation_loop]).

Why optuna's TPE: optuna is actively maintained, installs from PyPI without a deep-learning
framework (its GP sampler needs PyTorch; TPE needs only NumPy and SciPy), and its ask/tell
interface takes a whole batch of candidates at a time, so a generation is one vmapped, jitted
call of the batch objective -- the same hardware advantage CMA-ES and the gradient get. With
``multivariate=True`` TPE models the gains jointly (not one gain at a time) and with
``constant_liar=True`` the candidates asked together spread out instead of repeating the same
guess. Installed by ``pip install "vcjax[tuning]"``.

The search space is the box ``theta0 +- box`` (log-gain units; by default the tuning problem's
``log_box``, beyond which its loss adds a penalty): TPE needs bounds, CMA-ES and gradients do
not. The first candidate is ``theta0`` itself (optuna's ``enqueue_trial``), so the incumbent
never starts worse than the initial gains.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from tuning.blackbox import BlackBoxResult, generation_loop, hooks_from

__all__ = ["run_bayes"]

#: what a non-finite objective value is told to optuna as (ranks last)
_WORST = 1e300


def _optuna():
    try:
        import optuna
    except ImportError:  # pragma: no cover - optuna is declared by the "tuning" extra
        raise ImportError(
            'Bayesian optimisation needs optuna: pip install "vcjax[tuning]" '
            "(or pip install optuna)"
        ) from None
    return optuna


def run_bayes(
    f: Callable,
    theta0,
    *,
    box: float = 3.0,
    max_evals: int = 1000,
    popsize: int = 8,
    seed: int = 0,
    n_startup: int = 10,
    **hooks,
) -> BlackBoxResult:
    """optuna TPE on the batch objective ``f`` (from
    [`batch_objective`][tuning.blackbox.batch_objective])
    over ``theta0 +- box`` (n,), ``popsize`` candidates per call of ``f`` (one vmapped batch),
    at most ``max_evals`` candidates; ``n_startup`` random candidates before TPE models the
    loss; ``hooks``: ``on_gen``, ``progress``, ``should_stop`` (polled before each batch), as
    in [`run_cmaes`][tuning.blackbox.run_cmaes]."""
    hooks = hooks_from(hooks, "run_bayes")
    optuna = _optuna()
    x0 = np.asarray(theta0, dtype=float).ravel()
    if x0.size < 1 or not np.all(np.isfinite(x0)):
        raise ValueError("theta0: expected a non-empty finite vector")
    if not (np.isfinite(box) and box > 0):
        raise ValueError(f"box: expected a finite value > 0, got {box!r}")
    if int(popsize) < 1:
        raise ValueError(f"popsize: expected >= 1, got {popsize!r}")
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sampler = optuna.samplers.TPESampler(
        seed=seed, multivariate=True, constant_liar=True, n_startup_trials=n_startup
    )
    study = optuna.create_study(direction="minimize", sampler=sampler)
    names = [f"x{i}" for i in range(x0.size)]
    dists = {
        k: optuna.distributions.FloatDistribution(float(c - box), float(c + box))
        for k, c in zip(names, x0, strict=True)
    }
    study.enqueue_trial(dict(zip(names, x0.tolist(), strict=True)))
    asked = []

    def ask():
        asked[:] = [study.ask(dists) for _ in range(int(popsize))]
        return np.array([[t.params[k] for k in names] for t in asked])

    def tell(X, v):
        for t, val in zip(asked, np.asarray(v, dtype=float), strict=True):
            study.tell(t, float(val) if np.isfinite(val) else _WORST)

    return generation_loop(ask, tell, f, int(popsize), x0, max_evals, hooks)
