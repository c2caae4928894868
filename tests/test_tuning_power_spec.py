"""Tests written for the survivors of the mutation run of ``tuning/spec.py``,
``tuning/blackbox.py`` and ``tuning/robust.py`` (issue 31, item 8; docs/development/testing.md,
"Mutation testing"), and for the last survivor of ``tuning/scenarios.py`` (``shard_scenarios``
with three devices). Each test names the bugs it kills; expected values are computed here
independently (numpy, the documented rules), not with the code under test.
"""

from __future__ import annotations

import time

import jax
import numpy as np
import pytest

from tuning.scenarios import SCENARIO_AXES, shard_scenarios
from vcjax import loops

# ------------------------------------------------------------------ shard_scenarios, 3 devices


def test_a_batch_is_sharded_over_three_devices_when_it_splits_evenly(monkeypatch):
    """Kills: ``shard_scenarios`` refusing any device count but 2 (``n != 2`` for ``n < 2``).
    A process has as many host devices as it started with (two in tests/test_tuning.py's
    subprocess), so three stand-in devices and a recording ``device_put`` here: a batch of six
    goes over all three, each batched field split along its scenario axis, ``path`` and
    ``design`` (shared) left alone; a batch of four (not a multiple of 3) stays put."""
    made = {}

    class Mesh:
        def __init__(self, devices, names):
            made["mesh"] = (list(devices), tuple(names))

    class NamedSharding:
        def __init__(self, mesh, spec):
            made["spec"] = spec

    monkeypatch.setattr(jax.sharding, "Mesh", Mesh)
    monkeypatch.setattr(jax.sharding, "NamedSharding", NamedSharding)
    monkeypatch.setattr(jax, "device_put", lambda a, sh: ("put", a, sh))
    devices = ["dev0", "dev1", "dev2"]
    fields = {f: np.arange(6.0) + i for i, f in enumerate(loops.Scenario._fields)}
    batch = loops.Scenario(**fields)
    out, n = shard_scenarios(batch, devices)
    assert n == 3
    assert made["mesh"] == (devices, ("scenarios",))
    assert made["spec"] == jax.sharding.PartitionSpec("scenarios")
    for f in loops.Scenario._fields:
        if getattr(SCENARIO_AXES, f) is None:
            assert getattr(out, f) is fields[f], f
        else:
            tag, a, sh = getattr(out, f)
            assert tag == "put" and a is fields[f] and isinstance(sh, NamedSharding), f
    four = loops.Scenario(**{f: v[:4] for f, v in fields.items()})
    same, n = shard_scenarios(four, devices)
    assert same is four and n == 1


# ------------------------------------------------------------------ blackbox: the generation loop


def _scripted(batches):
    """``(ask, f)``: ``ask`` hands out the given (lambda, n) batches in turn; ``f`` their first
    column as the values."""
    it = iter(batches)
    return (lambda: np.array(next(it), dtype=float)), (lambda X: X[:, 0].copy())


def test_the_generation_loop_counts_whole_generations_and_keeps_the_first_best():
    """Kills: a generation run past ``max_evals`` or one short of it (``<=`` -> ``<``), the
    evaluations miscounted, a later candidate of equal loss replacing the incumbent (``<`` ->
    ``<=``), the record's fields, the wall time not a sum of the generations' durations from
    0, ``on_gen``'s extras dropped, the progress bar's total
    (``max_evals // lambda`` generations, at least 1) or count wrong."""
    from tuning.blackbox import GenerationHooks, generation_loop

    batches = [[[3.0, 0.0], [2.0, 1.0]], [[2.0, 5.0], [4.0, 0.0]], [[1.0, 7.0], [9.0, 0.0]]]
    ask, f = _scripted(batches)
    told, seen, bar = [], [], []
    hooks = GenerationHooks(
        on_gen=lambda g, x, rec: seen.append((g, x.tolist())) or ({"tag": g} if g else None),
        progress=lambda g, total, rec: bar.append((g, total)),
    )
    t0 = time.perf_counter()
    res = generation_loop(ask, lambda X, v: told.append(v.tolist()), f, 2, [0.0, 0.0], 5, hooks)
    elapsed = time.perf_counter() - t0
    assert res.evals == 4 and len(res.history) == 2  # a third generation would pass 5
    assert told == [[3.0, 2.0], [2.0, 4.0]]
    assert seen == [(0, [2.0, 1.0]), (1, [2.0, 1.0])]  # 2.0 again: the first one stays
    assert res.theta.tolist() == [2.0, 1.0] and res.loss == 2.0
    assert [(h["gen"], h["cum_evals"], h["best_loss"]) for h in res.history] == [
        (0, 2, 2.0),
        (1, 4, 2.0),
    ]
    assert "tag" not in res.history[0] and res.history[1]["tag"] == 1
    # the generations' own time, summed: within the call's, from 0
    assert 0.0 < res.history[0]["wall_s"] < res.history[1]["wall_s"] <= elapsed
    assert bar == [(1, 2), (2, 2)]
    ask, f = _scripted(batches)
    res = generation_loop(ask, lambda X, v: None, f, 2, [0.0, 0.0], 6)  # exactly 3 generations
    assert res.evals == 6 and res.loss == 1.0 and res.theta.tolist() == [1.0, 7.0]
    ask, f = _scripted(batches)
    bar.clear()
    res = generation_loop(
        ask,
        lambda X, v: None,
        f,
        2,
        [0.5, 0.5],
        3,
        GenerationHooks(progress=lambda *a: bar.append(a[:2])),
    )
    assert bar == [(1, 1)]  # 3 // 2 = 1 generation
    res = generation_loop(ask, lambda X, v: None, f, 4, [0.5, 0.5], 3)  # none fits
    assert res.evals == 0 and res.history == [] and res.loss == np.inf
    assert res.theta.tolist() == [0.5, 0.5]


def test_unknown_hooks_are_a_type_error_naming_the_first():
    from tuning.blackbox import hooks_from, run_cmaes, run_random_search

    with pytest.raises(TypeError, match=r"run_x\(\) got an unexpected keyword argument 'a_hook'"):
        hooks_from({"on_gen": None, "z_hook": 1, "a_hook": 2}, "run_x")
    assert hooks_from({"should_stop": len}, "run_x").should_stop is len
    for run in (run_cmaes, run_random_search):
        with pytest.raises(TypeError, match="on_generation"):
            run(lambda X: X[:, 0], np.zeros(2), on_generation=print)


# ------------------------------------------------------------------ blackbox: the drivers' arguments


def test_cma_strategy_checks_its_arguments_at_their_bounds():
    """Kills: an empty or non-finite start, a step of 0, inf or NaN, or a population of one
    let through (or a population of two, or a one-gain start, refused); the given population
    size ignored; the default seed not 0."""
    from tuning.blackbox import cma_strategy

    for bad in (np.zeros(0), np.array([0.0, np.nan]), np.array([np.inf])):
        with pytest.raises(ValueError, match="theta0: expected a non-empty finite vector"):
            cma_strategy(bad, 1.0)
    for bad in (0.0, -0.5, np.inf, np.nan):
        with pytest.raises(ValueError, match="sigma0: expected a finite value > 0"):
            cma_strategy(np.zeros(2), bad)
    with pytest.raises(ValueError, match="popsize: expected >= 2, got 1"):
        cma_strategy(np.zeros(2), 1.0, popsize=1)
    assert cma_strategy(np.zeros(2), 1.0, popsize=2).popsize == 2
    assert cma_strategy(np.zeros(3), 1.0, popsize=7).popsize == 7
    # one gain: 4 + floor(3 ln 1) (pycma 3.x refused 1-D problems: the floor is 4.0)
    assert cma_strategy(np.array([0.5]), 1.0).popsize == 4
    es = cma_strategy(np.array([[1.0, 2.0]]), 0.3)  # raveled
    np.testing.assert_array_equal(es.mean, [1.0, 2.0])
    assert es.sigma == 0.3
    # the default seed is 0: the same candidates as seed=0, others than seed=1
    first = lambda **kw: np.stack(cma_strategy(np.zeros(2), 1.0, **kw).ask())  # noqa: E731
    np.testing.assert_array_equal(first(), first(seed=0))
    assert not np.array_equal(first(), first(seed=1))


def test_random_search_draws_theta0_plus_radius_normals_from_its_seed():
    """Kills: the first candidate not the start, the radius or the seed not used as
    documented (candidates ``theta0 + radius N(0, I)``, ``numpy.random.default_rng(seed)``),
    the radius check's bound moved."""
    from tuning.blackbox import run_random_search

    seen = []

    def f(X):
        seen.append(X.copy())
        return np.sum(X**2, axis=1)

    theta0 = np.array([1.0, -2.0])
    res = run_random_search(f, theta0, radius=0.25, max_evals=8, popsize=4, seed=5)
    rng = np.random.default_rng(5)
    want = [theta0 + 0.25 * rng.standard_normal((4, 2)) for _ in range(2)]
    want[0][0] = theta0
    np.testing.assert_array_equal(seen[0], want[0])
    np.testing.assert_array_equal(seen[1], want[1])
    best = np.concatenate(want)[np.argmin(np.sum(np.concatenate(want) ** 2, axis=1))]
    np.testing.assert_array_equal(res.theta, best)
    for bad in (0.0, -1.0, np.inf, np.nan):
        with pytest.raises(ValueError, match="radius: expected a finite value > 0"):
            run_random_search(f, theta0, radius=bad)


# ------------------------------------------------------------------ spec: the default config


def test_a_default_tune_config_is_what_an_empty_config_parses_to():
    """Kills: ``TuneConfig``'s default current (the ``[scenarios] current_max`` shorthand, 1
    m/s, written out: speed U(0, 1) m/s in any direction) changed. An empty config parses to
    the default object, less what the vehicle resolves (its controller)."""
    import dataclasses

    from tuning.config import validate_config
    from tuning.spec import TuneConfig
    from vcjax.config.schema import Current

    a, b = TuneConfig(), validate_config({})
    assert a.current == b.current == Current(speed=(0.0, 1.0), direction_deg=(0.0, 360.0))
    assert a["current"]["speed"] == [0.0, 1.0] and a["current"]["direction_deg"] == [0.0, 360.0]
    resolved = dataclasses.replace(
        a, problem=dataclasses.replace(a.problem, variant=b.problem.variant), scenario=b.scenario
    )
    assert resolved == b


def test_cmaes_is_silent_and_writes_no_files(tmp_path, monkeypatch, capsys):
    """Kills: pycma's verbosity raised to where it prints (``verbose`` -9 -> +9: its banner
    and progress lines on stdout; ``outcmaes/`` log files would come from pycma's logger,
    which the ask/tell loop never calls)."""
    from tuning.blackbox import run_cmaes

    monkeypatch.chdir(tmp_path)
    res = run_cmaes(lambda X: np.sum(X**2, axis=1), np.ones(2), max_evals=30, popsize=6)
    assert res.evals == 30
    assert list(tmp_path.iterdir()) == []
    out = capsys.readouterr()
    assert out.out == "" and out.err == ""


def test_the_drivers_defaults_are_their_documented_ones_and_keyword_only():
    """Kills: a default of ``run_cmaes`` (sigma0 0.5, max_evals 1000, seed 0) or of
    ``run_random_search`` (radius 0.5, max_evals 1000, popsize 16, seed 0) changed, the
    settings made positional (``*`` -> ``/`` in the signature)."""
    from tuning.blackbox import run_cmaes, run_random_search

    def recorder():
        seen = []

        def f(X):
            seen.append(X.copy())
            return np.sum((X - 3.0) ** 2, axis=1)

        return seen, f

    x0 = np.array([0.2, -0.4])
    a, fa = recorder()
    b, fb = recorder()
    run_cmaes(fa, x0, max_evals=6, popsize=6)
    run_cmaes(fb, x0, sigma0=0.5, seed=0, max_evals=6, popsize=6)
    np.testing.assert_array_equal(a[0], b[0])
    # max_evals: whole generations up to 1000 (143 a generation: 6, 7 with 1001; 1000: one)
    for run in (run_cmaes, run_random_search):
        for lam, gens in ((143, 6), (1000, 1)):
            a, fa = recorder()
            assert run(fa, x0, popsize=lam).evals == gens * lam and len(a) == gens
    a, fa = recorder()
    res = run_random_search(fa, x0)
    assert res.evals == 992 and len(a) == 62 and a[0].shape == (16, 2)  # 62 x 16 <= 1000
    rng = np.random.default_rng(0)
    want = x0 + 0.5 * rng.standard_normal((16, 2))
    np.testing.assert_array_equal(a[0][1:], want[1:])
    for run in (run_cmaes, run_random_search):
        with pytest.raises(TypeError):
            run(fa, x0, 0.5)  # the settings are keyword-only
        assert run(f=fa, theta0=x0, max_evals=16).evals <= 16  # f and theta0 by name too
