"""Black-box baselines in the same harness: CMA-ES and random search.

Both evaluate a whole generation of candidate gain vectors at once: the objective is vmapped
over candidates (and, inside, over the scenario batch) and jitted, so one generation of
``lambda`` candidates on ``B`` scenarios is one call costing ``lambda * B`` rollouts.

The incumbent (lowest training loss seen) is what each tuner returns, and what ``on_gen`` sees.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from tuning.cmaes import CMAES

__all__ = ["batch_objective", "BlackBoxResult", "run_cmaes", "run_random_search"]


def batch_objective(loss_fn: Callable, args: tuple = ()) -> Callable:
    """``f(X (lambda, n)) -> (lambda,)`` NumPy values of ``loss_fn(theta, *args)``, jitted+vmapped.

    Non-finite values come back as ``inf``.
    """
    g = jax.jit(jax.vmap(loss_fn, in_axes=(0,) + (None,) * len(args)))

    def f(X):
        v = np.asarray(jax.device_get(g(jnp.asarray(X), *args)), dtype=float)
        return np.where(np.isfinite(v), v, np.inf)

    return f


class BlackBoxResult(NamedTuple):
    """Outcome of a black-box tuner.

    Attributes:
        theta: (n,) incumbent (best training loss); loss: its value; evals: candidate
        evaluations used (each costs one batch of rollouts); history: per-generation dicts
        (``gen``, ``cum_evals``, ``best_loss``, ``wall_s`` + ``on_gen`` extras).
    """

    theta: Any
    loss: float
    evals: int
    history: list


def _loop(ask, tell, f, lam, theta0, max_evals, on_gen, progress):
    best_x, best_f = np.asarray(theta0, dtype=float), np.inf
    history, evals, wall, gen = [], 0, 0.0, 0
    total = max(1, max_evals // lam)
    while evals + lam <= max_evals:
        t0 = time.perf_counter()
        X = ask()
        vals = f(X)
        tell(X, vals)
        wall += time.perf_counter() - t0
        evals += lam
        i = int(np.argmin(vals))
        if vals[i] < best_f:
            best_x, best_f = X[i].copy(), float(vals[i])
        rec = {"gen": gen, "cum_evals": evals, "best_loss": best_f, "wall_s": wall}
        if on_gen is not None:
            extra = on_gen(gen, best_x, rec)
            if extra:
                rec.update(extra)
        history.append(rec)
        gen += 1
        if progress is not None:
            progress(gen, total, rec)
    return BlackBoxResult(theta=best_x, loss=best_f, evals=evals, history=history)


def run_cmaes(
    f: Callable,
    theta0,
    *,
    sigma0: float = 0.5,
    max_evals: int = 1000,
    popsize: int | None = None,
    seed: int = 0,
    on_gen: Callable | None = None,
    progress: Callable | None = None,
) -> BlackBoxResult:
    """CMA-ES from ``theta0`` with step ``sigma0`` (in ``theta`` units: log-gains) on the batch
    objective ``f`` (from :func:`batch_objective`), for at most ``max_evals`` candidates."""
    es = CMAES.create(theta0, sigma0, popsize, seed)
    return _loop(
        lambda: es.ask(),
        lambda X, v: es.tell(v),
        f,
        es.lam,
        theta0,
        max_evals,
        on_gen,
        progress,
    )


def run_random_search(
    f: Callable,
    theta0,
    *,
    radius: float = 0.5,
    max_evals: int = 1000,
    popsize: int = 16,
    seed: int = 0,
    on_gen: Callable | None = None,
    progress: Callable | None = None,
) -> BlackBoxResult:
    """Pure random search: candidates ``theta0 + radius * N(0, I)`` (batches of ``popsize``),
    the best one kept."""
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius: expected a finite value > 0, got {radius!r}")
    rng = np.random.default_rng(seed)
    theta0 = np.asarray(theta0, dtype=float)
    first = [True]

    def ask():
        X = theta0 + radius * rng.standard_normal((popsize, theta0.size))
        if first[0]:  # the starting point is a candidate too
            X[0] = theta0
            first[0] = False
        return X

    return _loop(ask, lambda X, v: None, f, popsize, theta0, max_evals, on_gen, progress)
