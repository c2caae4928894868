"""The program store (vcjax.runtime.programs) through the command line: a second identical
``vcjax simulate`` / ``vcjax fit`` loads its programs (``run.json``'s ``programs`` says
``reused``) and gives the same numbers; a changed static input builds a new program;
``VCJAX_CACHE_DIR=off`` turns the store off.

The commands run in this process (``cli.main``) with a cache folder of their own; the fixture
puts the session's cache back afterwards."""

import json
import os

import numpy as np
import pytest

from vcjax import cli

pytest.importorskip("flatbuffers")  # jax.export's serialisation (the store stays off without it)


@pytest.fixture
def own_cache(tmp_path, monkeypatch):
    """``VCJAX_CACHE_DIR`` set to a fresh folder for the commands; the session's cache and
    store back afterwards (``tests/conftest.py``)."""
    from vcjax.runtime import cache

    if cache.unsafe_version() is not None:
        pytest.skip("this jaxlib's persistent cache stays off (vcjax.runtime.cache.SAFE_FROM)")
    folder = tmp_path / "cache"
    monkeypatch.setenv("VCJAX_CACHE_DIR", str(folder))
    try:
        yield folder / "programs"
    finally:
        cache.enable_compilation_cache({"VCJAX_CACHE_DIR": os.environ["VCJAX_TEST_CACHE_DIR"]})


@pytest.fixture
def own_store(tmp_path, monkeypatch):
    """A program store of its own in ``tmp_path`` while XLA's executables stay in the session's
    cache (cheap: the small programs every command compiles are read back)."""
    from vcjax.runtime import cache, programs

    if cache.unsafe_version() is not None:
        pytest.skip("this jaxlib's persistent cache stays off (vcjax.runtime.cache.SAFE_FROM)")
    folder = tmp_path / "programs"
    set_store = programs.set_store
    monkeypatch.setattr(programs, "set_store", lambda p: set_store(None if p is None else folder))
    try:
        yield folder
    finally:
        monkeypatch.undo()
        cache.enable_compilation_cache({"VCJAX_CACHE_DIR": os.environ["VCJAX_TEST_CACHE_DIR"]})


def _run(argv, out) -> dict:
    assert cli.main([*argv, "--out", str(out)]) == 0
    return json.loads((out / "run.json").read_text())["programs"]


def _keys(progs) -> dict:
    return {b["name"]: b["key"] for b in progs["built"]}


def test_an_experiments_rollout_is_stored_and_gives_the_jitted_runners_numbers(own_store):
    """What ``vcjax simulate`` builds (``Experiment.programs``): exported and stored, then
    loaded by a second build, both giving the trajectory of the jitted runner."""
    import jax

    from vcjax import experiments
    from vcjax.runtime import programs

    programs.set_store(own_store)
    arm = experiments.get("arm")
    setup = arm.setup(horizon=0.02)
    sc = {"vcm": arm.scenario("vcm", setup)}
    g = {"vcm": arm.default_gains("vcm")}
    calls = [arm.programs(setup, g, sc)["vcm"] for _ in range(2)]
    assert [b["reused"] for b in programs.report()] == [False, True]
    ref = jax.device_get(arm.simulate("vcm", setup, g["vcm"], sc["vcm"]))
    for call in calls:
        got = jax.device_get(call(g["vcm"], sc["vcm"], setup.dt))
        assert jax.tree_util.tree_structure(got) == jax.tree_util.tree_structure(ref)
        for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(ref), strict=True):
            np.testing.assert_array_equal(a, b)


@pytest.mark.slow  # two CLI runs drawing their figures (~6 s on 2 cores)
def test_a_second_identical_simulate_loads_its_programs(own_store, tmp_path, capsys):
    first = _run(["simulate", "arm", "--horizon", "0.1"], tmp_path / "o1")
    assert first["store"] == str(own_store)
    assert [(b["name"], b["reused"]) for b in first["built"]] == [("simulate:arm:vcm", False)]
    second = _run(["simulate", "arm", "--horizon", "0.1"], tmp_path / "o2")
    assert [b["reused"] for b in second["built"]] == [True]
    assert _keys(second) == _keys(first)
    m1, m2 = ((tmp_path / o / "metrics.json").read_text() for o in ("o1", "o2"))
    assert m1 == m2


def test_without_a_store_an_experiment_builds_nothing_itself():
    from vcjax import experiments
    from vcjax.runtime import programs

    arm = experiments.get("arm")
    setup = arm.setup(horizon=0.1)
    before = programs.store_dir()
    try:
        programs.set_store(None)
        assert arm.programs(setup, {"vcm": None}, {"vcm": arm.scenario("vcm", setup)}) == {}
    finally:
        programs.set_store(before)


@pytest.mark.slow  # six closed loops compiled cold, then a fit's three programs (~1 min on 2 cores)
def test_simulate_sim1_and_fit_reuse_exactly_rebuild_on_a_static_change_and_off(
    own_cache, tmp_path, monkeypatch, capsys
):
    sim = ["simulate", "sim1", "--horizon", "2"]
    first = _run(sim, tmp_path / "s1")
    assert first["store"] == str(own_cache)
    assert not any(b["reused"] for b in first["built"]) and len(first["built"]) == 6
    second = _run(sim, tmp_path / "s2")
    assert all(b["reused"] for b in second["built"]) and _keys(second) == _keys(first)
    assert (tmp_path / "s1" / "metrics.json").read_text() == (
        tmp_path / "s2" / "metrics.json"
    ).read_text()
    # a static option (which e_ddot the loop uses): new programs for the loops it changes
    implied = _run([*sim, "--edd", "implied"], tmp_path / "s3")
    changed = [n for n, k in _keys(implied).items() if k != _keys(first)[n]]
    assert changed and all(not b["reused"] for b in implied["built"] if b["name"] in changed)
    # the horizon or dt: another number of steps, another program
    for i, flags in enumerate((["--horizon", "2.1"], ["--dt", "0.04"])):
        other = _run([*sim[:2], *flags], tmp_path / f"s4{i}")
        assert not any(b["reused"] for b in other["built"]), flags

    from tests.test_bad_inputs_cli import _fit_case

    cfg = _fit_case(tmp_path, lambda c: None, rows=101)
    fits = [_run(["fit", str(cfg), "--quiet"], tmp_path / f"f{i}") for i in (1, 2)]
    names = ["fit:residuals", "fit:linearize", "fit:free_run"]
    assert [(b["name"], b["reused"]) for b in fits[0]["built"]] == [(n, False) for n in names]
    assert [(b["name"], b["reused"]) for b in fits[1]["built"]] == [(n, True) for n in names]
    a, b = (json.loads((tmp_path / f"f{i}" / "fit.json").read_text()) for i in (1, 2))
    a.pop("wall_time_s"), b.pop("wall_time_s")
    assert a == b
    assert np.isfinite(a["estimates"]["CD_0"])

    # VCJAX_CACHE_DIR=off: no store, nothing built through it, nothing written to the old one
    stored = sorted(p.name for p in own_cache.iterdir())
    monkeypatch.setenv("VCJAX_CACHE_DIR", "off")
    off = _run(sim, tmp_path / "s5")
    assert off["store"] is None and off["built"] == []
    assert stored == sorted(p.name for p in own_cache.iterdir())
    assert (tmp_path / "s5" / "metrics.json").read_text() == (
        tmp_path / "s1" / "metrics.json"
    ).read_text()


TINY_TUNE = """
[scenario]
controller = "vcm_integral"
[simulation]
horizon = 2.0
dt = 0.1
[train]
size = 2
seed = 0
[heldout]
size = 2
seed = 1001
[optimizer]
name = "lbfgs"
steps = 2
[report]
plot_scenarios = 1
"""


@pytest.mark.slow  # a tune's three programs compiled cold (~1 min on 2 cores)
def test_a_second_identical_tune_loads_its_three_programs(own_cache, tmp_path, capsys):
    """The held-out evaluation, the figures' trajectories (built concurrently) and the training
    step's value-and-gradient: stored by the first tune, loaded by the second, same results."""
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY_TUNE)
    runs = [_run(["tune", str(cfg)], tmp_path / f"t{i}") for i in (1, 2)]
    names = {"tune:heldout", "tune:trajectories", "tune:value_and_grad"}  # in the order built
    assert {(b["name"], b["reused"]) for b in runs[0]["built"]} == {(n, False) for n in names}
    assert {(b["name"], b["reused"]) for b in runs[1]["built"]} == {(n, True) for n in names}
    assert len(runs[0]["built"]) == len(runs[1]["built"]) == 3
    a, b = (json.loads((tmp_path / f"t{i}" / "history.json").read_text()) for i in (1, 2))
    assert [h["loss"] for h in a["iterations"]] == [h["loss"] for h in b["iterations"]]
    assert [h["gains"] for h in a["iterations"]] == [h["gains"] for h in b["iterations"]]
