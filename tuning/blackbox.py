"""Black-box baselines in the same harness: CMA-ES (Hansen's pycma, ``cma`` on PyPI, installed
by ``pip install "vcjax[tuning]"``) and random search (Bayesian optimisation:
[`tuning.bayes`][tuning.bayes]).

Both evaluate a whole generation of candidate gain vectors at once: the objective is vmapped
over candidates (and, inside, over the scenario batch) and jitted, so one generation of
``lambda`` candidates on ``B`` scenarios is one call costing ``lambda * B`` rollouts.

The incumbent (lowest training loss seen) is what each tuner returns, and what ``on_gen`` sees.
pycma is driven through its ask/tell interface with its default parameters; its random numbers
come from a NumPy ``Generator`` seeded by ``seed`` (pycma's global-``np.random`` seeding is not
used), so a run is reproducible and leaves the global random state alone.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax.runtime import compiler

__all__ = [
    "batch_objective",
    "BlackBoxResult",
    "cma_strategy",
    "cmaes_popsize",
    "GenerationHooks",
    "run_cmaes",
    "run_random_search",
    "generation_loop",
]

#: what a non-finite objective value is told to pycma as (ranks last; finite arithmetic)
_WORST = 1e300


def batch_objective(loss_fn: Callable, args: tuple = (), static=None) -> Callable:
    """``f(X (lambda, n)) -> (lambda,)`` NumPy values of ``loss_fn(theta, *args)``, jitted+vmapped.

    Non-finite values come back as ``inf``. ``static``: a plain description of everything that
    fixes ``loss_fn`` (e.g. the tuning config); with it, and the program store on
    (`vcjax.runtime.programs`), the batch program is keyed in the
    store, so a warm run loads it instead of tracing (as the gradient tuner's step does).
    """
    from vcjax.runtime import programs

    vf = jax.vmap(loss_fn, in_axes=(0,) + (None,) * len(args))
    g = compiler.jit(vf)
    built: dict = {}

    def f(X):
        X = jnp.asarray(X)
        if static is not None and programs.store_dir() is not None:
            if X.shape not in built:
                built[X.shape], _ = programs.build("tune:batch_loss", vf, static, (X, *args))
            v = built[X.shape](X, *args)
        else:
            v = g(X, *args)
        v = np.asarray(jax.device_get(v), dtype=float)
        return np.where(np.isfinite(v), v, np.inf)

    return f


class BlackBoxResult(NamedTuple):
    """Outcome of a black-box tuner.

    Attributes:
        theta: (n,) incumbent (best training loss).
        loss: its value.
        evals: candidate evaluations used (each costs one batch of rollouts).
        history: per-generation dicts (``gen``, ``cum_evals``, ``best_loss``, ``wall_s`` +
            ``on_gen`` extras).
    """

    theta: Any
    loss: float
    evals: int
    history: list


class GenerationHooks(NamedTuple):
    """Callbacks of the black-box tuners.

    Attributes:
        on_gen: ``on_gen(gen, incumbent, record) -> dict | None`` after each generation; a
            returned dict is merged into the history record.
        progress: ``progress(gen, total, record)`` for a progress bar.
        should_stop: polled before each generation; True ends the run (e.g. a wall-clock
            budget).
    """

    on_gen: Callable | None = None
    progress: Callable | None = None
    should_stop: Callable[[], bool] | None = None


def hooks_from(kwargs: dict, fn: str) -> GenerationHooks:
    """The [`GenerationHooks`][tuning.blackbox.GenerationHooks] a tuner was given by name
    (``TypeError`` for any other name, as Python's)."""
    unknown = sorted(set(kwargs) - set(GenerationHooks._fields))
    if unknown:
        raise TypeError(f"{fn}() got an unexpected keyword argument {unknown[0]!r}")
    return GenerationHooks(**kwargs)


def generation_loop(ask, tell, f, lam, theta0, max_evals, hooks: GenerationHooks | None = None):
    """The loop every black-box tuner runs ([`tuning.bayes`][tuning.bayes] too): ``X = ask()``
    (lambda, n),
    ``vals = f(X)`` (one batch), ``tell(X, vals)``, until ``max_evals`` candidates or
    ``hooks.should_stop()``; keeps the incumbent, times the generations (``wall_s``: ask + f +
    tell, without ``hooks.on_gen``)."""
    on_gen, progress, should_stop = hooks or GenerationHooks()
    stop = should_stop or (lambda: False)
    best_x, best_f = np.asarray(theta0, dtype=float), np.inf
    history, evals, wall, gen = [], 0, 0.0, 0
    total = max(1, max_evals // lam)
    while evals + lam <= max_evals and not stop():
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


def _cma():
    try:
        import cma
    except ImportError:  # pragma: no cover - cma is declared by the "tuning" and "test" extras
        raise ImportError(
            'CMA-ES needs pycma: pip install "vcjax[tuning]" (or pip install cma)'
        ) from None
    return cma


def cma_strategy(theta0, sigma0: float, popsize: int | None = None, seed: int = 0):
    """A pycma ``CMAEvolutionStrategy`` at ``theta0`` (n,) with step ``sigma0`` > 0, pycma's
    default parameters (``popsize`` ``4 + floor(3 ln n)`` unless given), silent (no output
    files), its normal samples drawn from ``numpy.random.default_rng(seed)``."""
    x0 = np.asarray(theta0, dtype=float).ravel()
    if x0.size < 1 or not np.all(np.isfinite(x0)):
        raise ValueError("theta0: expected a non-empty finite vector")
    if not (np.isfinite(sigma0) and sigma0 > 0):
        raise ValueError(f"sigma0: expected a finite value > 0, got {sigma0!r}")
    if popsize is not None and int(popsize) < 2:
        raise ValueError(f"popsize: expected >= 2, got {popsize!r}")
    rng = np.random.default_rng(seed)
    opts = {"verbose": -9, "seed": np.nan, "randn": lambda *shape: rng.standard_normal(shape)}
    if popsize is not None:
        opts["popsize"] = int(popsize)
    return _cma().CMAEvolutionStrategy(x0, float(sigma0), opts)


def cmaes_popsize(n: int) -> int:
    """pycma's default population size ``lambda`` in dimension ``n``."""
    return int(cma_strategy(np.zeros(n), 1.0).popsize)


def run_cmaes(
    f: Callable,
    theta0,
    *,
    sigma0: float = 0.5,
    max_evals: int = 1000,
    popsize: int | None = None,
    seed: int = 0,
    **hooks,
) -> BlackBoxResult:
    """pycma CMA-ES from ``theta0`` with step ``sigma0`` (in ``theta`` units: log-gains) on the
    batch objective ``f`` (from [`batch_objective`][tuning.blackbox.batch_objective]), for at most
    ``max_evals`` candidates
    (whole generations; fewer if pycma's own termination criteria fire first). Each generation
    is one call ``f(X)`` with ``X`` (lambda, n): one vmapped, jitted batch. ``hooks``:
    ``on_gen``, ``progress``, ``should_stop`` ([`GenerationHooks`][tuning.blackbox.GenerationHooks];
    ``should_stop()``, polled before each generation, ends the run early)."""
    on_gen, progress, should_stop = hooks_from(hooks, "run_cmaes")
    es = cma_strategy(theta0, sigma0, popsize, seed)
    asked = []

    def ask():
        asked[:] = es.ask()
        return np.stack(asked)

    def tell(X, v):
        v = np.where(np.isfinite(v), np.asarray(v, dtype=float), _WORST)
        es.tell(asked, v.tolist())

    stop = lambda: bool(es.stop()) or bool(should_stop and should_stop())
    return generation_loop(
        ask, tell, f, int(es.popsize), theta0, max_evals, GenerationHooks(on_gen, progress, stop)
    )


def run_random_search(
    f: Callable,
    theta0,
    *,
    radius: float = 0.5,
    max_evals: int = 1000,
    popsize: int = 16,
    seed: int = 0,
    **hooks,
) -> BlackBoxResult:
    """Pure random search: candidates ``theta0 + radius * N(0, I)`` (batches of ``popsize``),
    the best one kept; ``hooks`` as in [`run_cmaes`][tuning.blackbox.run_cmaes]."""
    hooks = hooks_from(hooks, "run_random_search")
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

    return generation_loop(ask, lambda X, v: None, f, popsize, theta0, max_evals, hooks)
