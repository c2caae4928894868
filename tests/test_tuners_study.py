"""The tuner comparison (benchmarks/studies/tuners.py, issue 34): the start point every tuner
shares, the Bayesian-optimisation baseline (optuna TPE), the early stop of the black-box tuners,
and the time-to-target arithmetic (``tuning.report.time_to_target``), each against an
independent value; the study's bad arguments, run as a user runs it
(``python -m benchmarks tuners ...``)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tuning.blackbox import run_cmaes, run_random_search
from tuning.params import GainSpace
from tuning.report import time_to_target
from vcjax import loops

ROOT = Path(__file__).resolve().parents[1]


def _sim1_gains():
    """Simulation 1's default gains (the loop ``vcjax tune`` tunes by default)."""
    return loops.make_loop("infante", "vcm_integral").default_gains()


def test_start_is_the_encoded_gains_plus_the_symmetry_break():
    space = GainSpace()
    full = _sim1_gains()
    want = np.asarray(space.encode(full)) + space.symmetry_break(full)
    np.testing.assert_allclose(np.asarray(space.start(full)), want, rtol=0, atol=0)
    # P_G[1] = P_Phi[3] = 0.5 in Simulation 1's gains: split by exp(+-0.1) around log(0.5)
    labels = space.labels()
    th = np.asarray(space.start(full))
    assert th[labels.index("P_G[1]")] == pytest.approx(np.log(0.5) + 0.1, abs=1e-12)
    assert th[labels.index("P_Phi[3]")] == pytest.approx(np.log(0.5) - 0.1, abs=1e-12)


def test_part_of_the_gains_is_refused_with_the_expected_type():
    """The study's old bug: Simulation 1's ``gains.vcm`` (PMGains) passed where the loop's whole
    gains are expected ended in an AttributeError deep in the field lookup."""
    space = GainSpace()
    part = _sim1_gains().vcm
    for fn in (space.symmetry_break, space.encode, space.start):
        with pytest.raises(ValueError, match="expected the whole gains of .*got PMGains"):
            fn(part)


def _quadratic(c):
    return lambda X: np.sum((np.asarray(X) - c) ** 2, axis=1)


def test_bayes_tpe_improves_on_a_quadratic_starts_at_theta0_and_is_reproducible():
    pytest.importorskip("optuna")
    from tuning.bayes import run_bayes

    c = np.array([1.0, -0.5, 0.25])
    f = _quadratic(c)
    theta0 = np.zeros(3)
    seen = []

    def f_seen(X):
        seen.append(np.array(X))
        return f(X)

    a = run_bayes(f_seen, theta0, box=2.0, max_evals=96, popsize=8, seed=3)
    np.testing.assert_array_equal(seen[0][0], theta0)  # the start is the first candidate
    assert np.all(np.abs(np.concatenate(seen) - theta0) <= 2.0)  # inside the box
    assert a.evals == 96 and len(a.history) == 12
    assert a.loss == pytest.approx(float(f(a.theta[None])[0]))
    assert a.loss < 0.1 * float(f(theta0[None])[0])  # 1.3125 at the start
    best = [h["best_loss"] for h in a.history]
    assert all(x >= y for x, y in zip(best, best[1:], strict=False))
    b = run_bayes(f, theta0, box=2.0, max_evals=96, popsize=8, seed=3)
    np.testing.assert_array_equal(a.theta, b.theta)


@pytest.mark.parametrize("tuner", ["cmaes", "random", "bayes"])
def test_should_stop_ends_a_black_box_tuner_after_the_polled_generation(tuner):
    if tuner == "bayes":
        pytest.importorskip("optuna")
        from tuning.bayes import run_bayes as run
    else:
        run = run_cmaes if tuner == "cmaes" else run_random_search
    calls = []
    res = run(
        _quadratic(np.ones(4)),
        np.zeros(4),
        max_evals=10_000,
        should_stop=lambda: len(calls) >= 3,
        on_gen=lambda g, th, rec: calls.append(g),
    )
    assert len(res.history) == 3 and calls == [0, 1, 2]


def _run(points):
    return {
        "best_heldout": min(h for _, _, h in points),
        "first_step_s": points[1][0],
        "curve": [
            {"wall_s": t, "rollouts": n, "heldout_best": min(h for _, _, h in points[: i + 1])}
            for i, (t, n, _) in enumerate(points)
        ],
    }


def test_time_to_target_is_the_first_time_within_each_tolerance_of_the_best_of_any_run():
    runs = {
        "cold": {
            "lbfgs": _run([(0, 0, 10.0), (2.0, 8, 1.04), (3.0, 16, 1.005), (4.0, 24, 1.0)]),
            "cmaes": _run([(0, 0, 10.0), (1.0, 40, 1.2), (5.0, 80, 1.03), (9.0, 120, 1.02)]),
        },
        "warm": {"lbfgs": _run([(0, 0, 10.0), (0.5, 8, 1.04), (1.0, 16, 1.005)])},
    }
    s = time_to_target(runs)
    assert s["target"] == 1.0
    lb, cm = s["table"]["cold"]["lbfgs"], s["table"]["cold"]["cmaes"]
    assert (lb["wall_s_to_1%"], lb["rollouts_to_1%"]) == (3.0, 16)
    assert (lb["wall_s_to_5%"], lb["rollouts_to_5%"]) == (2.0, 8)
    assert (cm["wall_s_to_1%"], cm["wall_s_to_5%"]) == (None, 5.0)  # 1.02 > 1.01: not reached
    assert s["table"]["warm"]["lbfgs"]["wall_s_to_1%"] == 1.0
    assert s["ratios_wall_s_to_1%"]["cold: lbfgs/cmaes at 1%"] is None


def _report(runs, **over):
    rep = dict(
        config="p.toml", config_sha256="a" * 64, seconds=90.0, rollouts_budget=None,
        grad_ratio=1.0, grad_mode=None, x64=True, sigma0=0.5, random_radius=0.5, seed=0,
    )  # fmt: skip
    return {**rep, **over, "runs": runs}


def test_merge_keeps_the_earlier_tuners_replaces_a_rerun_one_and_refuses_another_problem():
    from tuning.report import merge_runs

    old = _report(
        {
            "cold": {
                "lbfgs": _run([(0, 0, 10.0), (2.0, 8, 1.0)]),
                "cmaes": _run([(0, 0, 10.0), (6.0, 80, 1.2)]),
            },
            "warm": {"lbfgs": _run([(0, 0, 10.0), (1.0, 8, 1.0)])},
        }
    )
    new = _report(
        {
            "cold": {
                "cmaes": _run([(0, 0, 10.0), (8.0, 90, 1.005)]),  # re-measured: replaces
                "bayes": _run([(0, 0, 10.0), (20.0, 300, 1.04)]),  # new: added
            }
        }
    )
    runs = merge_runs(old, new)
    assert sorted(runs["cold"]) == ["bayes", "cmaes", "lbfgs"]
    assert runs["cold"]["cmaes"] is new["runs"]["cold"]["cmaes"]
    assert runs["cold"]["lbfgs"] is old["runs"]["cold"]["lbfgs"]
    assert list(runs["warm"]) == ["lbfgs"]
    assert sorted(old["runs"]["cold"]) == ["cmaes", "lbfgs"]  # the earlier report untouched
    s = time_to_target(runs)  # the target and table of all of them
    assert s["target"] == 1.0
    assert s["table"]["cold"]["cmaes"]["wall_s_to_1%"] == 8.0
    assert s["table"]["cold"]["bayes"]["wall_s_to_5%"] == 20.0
    assert s["ratios_wall_s_to_1%"]["cold: lbfgs/cmaes at 1%"] == 2.0 / 8.0
    for key, value in (("seconds", 60.0), ("seed", 1), ("x64", False), ("config", "q.toml")):
        with pytest.raises(ValueError, match=f"--merge: the earlier report has {key} = "):
            merge_runs(old, _report({}, **{key: value}))
    for mine, theirs in (("a", "b"), ("b", "a")):  # either way round
        with pytest.raises(ValueError, match="changed since the earlier report"):
            merge_runs(_report({}, config_sha256=mine * 64), _report({}, config_sha256=theirs * 64))
    unknown = {k: v for k, v in old.items() if k != "config_sha256"}  # older reports: no hash
    assert sorted(merge_runs(unknown, new)["cold"]) == ["bayes", "cmaes", "lbfgs"]


def test_bad_arguments_exit_2_with_one_line_before_any_work(tmp_path):
    import json

    cfg = tmp_path / "bad.toml"
    cfg.write_text("[problem]\nhorizon = -1\n")
    out = tmp_path / "out"
    other = tmp_path / "other.json"  # a report of another problem
    other.write_text(json.dumps(_report({"cold": {}}, config=str(cfg) + ".old")))
    garbled = tmp_path / "garbled.json"
    garbled.write_text("{")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "VCJAX_CACHE_DIR": "off"}
    cases = (
        ([str(cfg), "--tuners", "lbfgs,nope"], "tuners: unknown ['nope']"),
        ([str(tmp_path / "none.toml")], "config: no such file"),
        ([str(cfg), "--seconds", "0"], "--seconds: expected > 0"),
        ([str(cfg), "--quick"], "[problem] horizon"),
        ([str(cfg), "--merge", str(other)], "--merge: the earlier report has config = "),
        ([str(cfg), "--merge", str(garbled)], f"--merge: cannot read {garbled}"),
        ([str(cfg), "--merge", str(tmp_path / "no.json")], "--merge: cannot read"),
    )
    procs = [  # side by side: each is a fresh process
        subprocess.Popen(
            [sys.executable, "-m", "benchmarks", "tuners", *argv, "--out", str(out)],
            cwd=ROOT,
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for argv, _ in cases
    ]
    for p, (_, msg) in zip(procs, cases, strict=True):
        err = p.communicate()[1].strip().splitlines()
        assert p.returncode == 2
        assert len(err) == 1 and msg in err[0], err
    assert not out.exists()
