"""Gain tuning (issue 6): parametrisation, loss gradient vs finite differences, guarded optimiser,
CMA-ES, configuration validation, and the tuned-gains file format.

The closed-loop tests use a tiny problem (Euler, sampled controller, a few seconds, two
scenarios) so that compilation stays short; ``slow`` ones run the whole CLI.
"""

import dataclasses
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tuning.blackbox import batch_objective, cmaes_popsize, run_cmaes, run_random_search
from tuning.config import ConfigError, validate_config
from tuning.loss import TuningProblem, aggregate, objective, problem_data
from tuning.optim import forward_mode, run_gradient_tuner
from tuning.params import FRAC_MAX, GainSpace, rh_bound
from tuning.run import run_tune_config
from tuning.scenarios import Nominal, sample_scenarios
from vcjax import cli, loops
from vcjax.control.vcm import pm_gains

TINY = TuningProblem(num_steps=40, integrator="euler", timing="sampled")


def _infante(controller: str):
    """The INFANTE-class loop of ``controller`` on its default path (Simulation 1's line)."""
    return loops.make_loop("infante", controller)


@pytest.fixture(scope="module")
def tiny():
    data = problem_data(TINY, dt=0.1)
    scen = sample_scenarios(0, 2, current_max=1.0)
    return data, scen


#: the tiny problem's batch loss and gradient, compiled once for the tests that need it
tiny_value_and_grad = jax.jit(jax.value_and_grad(lambda th, d, s: objective(th, d, s, TINY)[0]))


# ------------------------------------------------------------------ parametrisation


def test_parametrisation_gives_valid_gains_and_inverts():
    space = GainSpace()
    assert space.size == 12 and len(space.labels()) == 12
    base = loops.infante_gains()
    rng = np.random.default_rng(0)
    for _ in range(20):
        theta = jnp.asarray(rng.normal(scale=3.0, size=space.size))
        g = space.decode(theta, base)
        pm = g.vcm
        pm_gains(**{k: np.asarray(v) for k, v in pm._asdict().items()})  # validates, incl. R-H
        bound = FRAC_MAX * np.asarray(rh_bound(pm.P_G, pm.P_Phi))
        assert np.all(np.asarray(pm.P_int) < bound + 1e-15)
        np.testing.assert_allclose(space.encode(g), theta, rtol=1e-9, atol=1e-9)
        for a, b in zip(g.baseline, base.baseline, strict=True):  # untouched
            np.testing.assert_array_equal(a, b)
    # the default gains (P_int[1] = 0) encode and decode back (the zero within 1e-6 of the bound)
    g0 = space.decode(space.encode(base), base)
    for a, b in zip(g0.vcm, base.vcm, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)


def test_parametrisation_subsets_and_variant():
    base = loops.infante_gains()
    s = GainSpace(loop=_infante("vcm"), tune=("sigma", "Delta"))
    assert s.tune == ("Delta", "sigma")  # canonical order
    g = s.decode(jnp.log(jnp.asarray([2.0, 3.0])), base)
    assert float(g.vcm.Delta) == pytest.approx(2.0) and float(g.vcm.sigma) == pytest.approx(3.0)
    np.testing.assert_array_equal(g.vcm.P_G, base.vcm.P_G)
    with pytest.raises(ValueError, match="unknown"):
        GainSpace(tune=("P_K",))
    with pytest.raises(ValueError, match=r"unknown gains \['P_int'\]"):  # "vcm": no integral
        GainSpace(loop=_infante("vcm"), tune=("P_int",))
    # a baseline's gains are tunable too (every loop exposes its gain groups)
    ilos = GainSpace(loop=_infante("ilos"))
    assert "sigma_i" in ilos.labels() and "k_ep" not in ilos.labels()
    g = ilos.decode(ilos.encode(base) + 0.1, base)
    assert float(g.baseline.Delta) == pytest.approx(float(base.baseline.Delta) * np.exp(0.1))


# ------------------------------------------------------------------ loss and gradients


def test_loss_gradient_matches_central_differences(tiny):
    data, scen = tiny
    f = jax.jit(lambda th: objective(th, data, scen, TINY)[0])
    theta = data.theta_ref + 0.1 * jnp.arange(12.0) / 12.0
    grad = np.asarray(tiny_value_and_grad(theta, data, scen)[1])
    h = 1e-5
    fd = np.array(
        [
            (float(f(theta.at[i].add(h))) - float(f(theta.at[i].add(-h)))) / (2 * h)
            for i in range(theta.size)
        ]
    )
    np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-6 * np.max(np.abs(fd)))
    assert np.max(np.abs(grad)) > 0


def test_alos_gains_are_tunable_with_exact_gradients():
    """Fossen's ALOS baseline: its look-ahead, adaptation gain and heading-loop gains are tuned
    like any loop's, and the loss gradient (through beta_hat's dynamics) matches central
    differences."""
    space = GainSpace(loop=_infante("alos"))
    assert {"Delta", "gamma", "k_psi_p", "k_psi_d"} <= set(space.labels())
    assert "sigma_i" not in space.labels() and "k_ei" not in space.labels()
    problem = TuningProblem(space=space, num_steps=40, integrator="euler", timing="sampled")
    data = problem_data(problem, dt=0.1)
    scen = sample_scenarios(0, 2, loop=space.loop, current_max=1.0)
    f = jax.jit(lambda th: objective(th, data, scen, problem)[0])
    grad = np.asarray(
        jax.jit(jax.grad(lambda th: objective(th, data, scen, problem)[0]))(data.theta_ref)
    )
    h = 1e-5
    fd = np.array(
        [
            (float(f(data.theta_ref.at[i].add(h))) - float(f(data.theta_ref.at[i].add(-h))))
            / (2 * h)
            for i in range(space.size)
        ]
    )
    np.testing.assert_allclose(grad, fd, rtol=1e-4, atol=1e-6 * np.max(np.abs(fd)))
    assert grad[space.labels().index("gamma")] != 0.0  # the adaptation is in the loop


@pytest.mark.slow  # 6 s
def test_checkpointed_loss_gradient_is_the_same(tiny):
    """Segment checkpointing (7 does not divide 40) changes memory, not the gradient."""
    data, scen = tiny
    ck = dataclasses.replace(TINY, checkpoint=True, checkpoint_every=7)
    theta = data.theta_ref + 0.05
    a = tiny_value_and_grad(theta, data, scen)
    b = jax.jit(jax.value_and_grad(lambda th: objective(th, data, scen, ck)[0]))(theta)
    np.testing.assert_allclose(a[0], b[0], rtol=1e-12)
    np.testing.assert_allclose(a[1], b[1], rtol=1e-9, atol=1e-12)


def test_symmetry_break_splits_equal_pairs_only():
    space = GainSpace()
    full = loops.infante_gains()
    base = full.vcm  # P_G[1:] == P_Phi[3:] == 0.5
    off = space.symmetry_break(full, eps=0.1)
    g = space.decode(space.encode(full) + off, full).vcm
    np.testing.assert_allclose(np.asarray(g.P_G[1:]) * np.asarray(g.P_Phi[3:]), 0.25, rtol=1e-12)
    assert float(g.P_G[1]) > float(g.P_Phi[3])
    assert float(g.P_G[0]) == pytest.approx(float(base.P_G[0]))  # heading row untouched
    uneven = full._replace(vcm=base._replace(P_G=jnp.asarray([1.0, 0.3, 0.5])))
    assert np.count_nonzero(space.symmetry_break(uneven)) == 2  # only the e row


def test_symmetry_break_skips_pairs_not_tuned_or_bounded_and_goes_on():
    """A loop with three pairs: one not tuned (Delta, sigma), one with a bounded gain (P_int[0]
    set equal to P_G[1]) and the Baumgarte pair P_G[1], P_Phi[3] (equal in Simulation 1's
    gains): only the last is split, by the default exp(+-0.1)."""
    base = GainSpace().loop

    @dataclasses.dataclass(frozen=True)
    class Pairs(type(base)):
        def symmetric_pairs(self):
            return (("Delta", 0, "sigma", 0), ("P_int", 0, "P_G", 1), ("P_G", 1, "P_Phi", 3))

    loop = Pairs(controller=base.controller, path=base.path)
    space = GainSpace(loop, tune=("P_G", "P_Phi", "P_int"))
    full = loops.infante_gains()
    full = full._replace(vcm=full.vcm._replace(P_int=jnp.asarray([0.5, 0.0])))
    off = space.symmetry_break(full)
    np.testing.assert_array_equal(off, [0.0, 0.1, 0.0, 0.0, 0.0, 0.0, -0.1, 0.0, 0.0, 0.0])


def test_gain_space_values_are_plain_json_numbers_and_lists():
    """Reports and histories: one-entry groups as numbers, the others as lists (Simulation 1's
    gains, typed in)."""
    v = GainSpace().values(loops.infante_gains())
    assert v == {
        "P_G": [1.0, 0.5, 0.5],
        "P_Phi": [1.0, 1.0, 2.0, 0.5, 0.5],
        "Delta": 5.0,
        "sigma": 0.5,
        "P_int": [0.05, 0.0],
    }
    assert type(v["Delta"]) is float and type(v["sigma"]) is float
    assert json.loads(json.dumps(v)) == v


def test_forward_mode_gradient_equals_reverse():
    def f(th, a):
        return jnp.sum(jnp.sin(th) * a) + jnp.sum(th**4)

    th = jnp.asarray([0.3, -1.2, 2.0])
    a = jnp.asarray([1.0, 2.0, 3.0])
    v1, g1 = jax.value_and_grad(f)(th, a)
    v2, g2 = jax.value_and_grad(forward_mode(f))(th, a)
    assert float(v1) == pytest.approx(float(v2))
    np.testing.assert_allclose(g1, g2, rtol=1e-12)


def test_cvar_aggregation():
    losses = jnp.asarray([1.0, 5.0, 2.0, 4.0, 3.0])
    assert float(aggregate(losses, TuningProblem(risk="mean"))) == pytest.approx(3.0)
    assert float(aggregate(losses, TuningProblem(risk="cvar", alpha=0.4))) == pytest.approx(4.5)
    assert float(aggregate(losses, TuningProblem(risk="cvar", alpha=0.01))) == pytest.approx(5.0)


# ------------------------------------------------------------------ optimiser and guard


def test_tiny_tuning_run_lowers_the_loss(tiny):
    data, scen = tiny
    loss = lambda th, d, s: objective(th, d, s, TINY)[0]
    res = run_gradient_tuner(
        loss, data.theta_ref, (data, scen), optimizer="adam", steps=4, learning_rate=0.1
    )
    assert res.n_bad == 0 and not res.aborted
    assert res.loss < res.history[0]["loss"]
    assert [h["iter"] for h in res.history] == [0, 1, 2, 3]
    gains = TINY.space.decode(jnp.asarray(res.theta), data.base)
    d = json.loads(json.dumps(loops.gains_to_json(gains)))
    back = _infante("vcm").gains_from_json(d)  # the file `vcjax simulate --gains` loads
    for a, b in zip(back.vcm, gains.vcm, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_lbfgs_on_a_quadratic():
    A = jnp.diag(jnp.asarray([1.0, 10.0, 100.0]))
    loss = lambda th: 0.5 * th @ A @ th - jnp.sum(th)
    res = run_gradient_tuner(loss, jnp.zeros(3), optimizer="lbfgs", steps=30)
    np.testing.assert_allclose(res.theta, 1.0 / jnp.diag(A), rtol=1e-6)
    assert res.evals >= len(res.history)


def test_tuner_options_object_or_keywords():
    """run_gradient_tuner takes its settings as a TunerOptions (and callbacks as TunerHooks) or,
    as before, by name: the same run; a name that is neither is refused."""
    from tuning.optim import TunerHooks, TunerOptions

    loss = lambda th: jnp.sum((th - jnp.asarray([1.0, -2.0])) ** 2)
    seen = []
    a = run_gradient_tuner(loss, jnp.zeros(2), optimizer="adam", steps=4, learning_rate=0.3)
    b = run_gradient_tuner(
        loss,
        jnp.zeros(2),
        (),
        TunerOptions(optimizer="adam", steps=4, learning_rate=0.3),
        hooks=TunerHooks(progress=lambda k, n, rec: seen.append((k, n))),
    )
    np.testing.assert_array_equal(a.theta, b.theta)
    assert a.history[-1]["loss"] == b.history[-1]["loss"] and seen[-1] == (4, 4)
    with pytest.raises(TypeError, match="learning_rat"):
        run_gradient_tuner(loss, jnp.zeros(2), learning_rat=0.3)
    with pytest.raises(ValueError, match="steps"):
        run_gradient_tuner(loss, jnp.zeros(2), options=TunerOptions(steps=0))
    with pytest.raises(TypeError, match="options"):
        run_gradient_tuner(loss, jnp.zeros(2), TunerOptions(steps=2))  # in args' place


def test_nan_guard_skips_reports_and_aborts():
    # NaN beyond theta = 0.5: Adam steps into it, the guard rejects and backtracks
    def loss(th):
        bad = th[0] > 0.5
        return jnp.where(bad, jnp.nan, jnp.sum((th - 1.0) ** 2))

    res = run_gradient_tuner(loss, jnp.zeros(2), optimizer="adam", steps=30, learning_rate=0.2)
    assert res.n_bad > 0 and not res.aborted
    assert any(not h["ok"] for h in res.history)
    assert all(np.isfinite(res.theta)) and float(res.theta[0]) <= 0.5
    assert res.loss < 2.0
    # NaN everywhere: aborts after max_bad_steps consecutive rejections, never "succeeds"
    res = run_gradient_tuner(
        lambda th: jnp.sum(th) * jnp.nan, jnp.zeros(2), optimizer="adam", steps=20, max_bad_steps=3
    )
    assert res.aborted and res.n_bad == 3 and len(res.history) == 3 and "abort" in res.reason


# ------------------------------------------------------------------ black-box baselines


def test_pycma_driver_minimises_rosenbrock_one_batch_per_generation():
    """pycma through run_cmaes: every generation is one (lambda, n) batch call; NaN candidates
    rank last; the run is reproducible from its seed and leaves np.random's global state alone."""
    calls = []

    def rosen(X):
        calls.append(X.shape)
        v = np.sum(100 * (X[:, 1:] - X[:, :-1] ** 2) ** 2 + (1 - X[:, :-1]) ** 2, axis=1)
        return np.where(X[:, 0] > 2.5, np.nan, v)  # an infeasible region

    lam = cmaes_popsize(4)
    assert lam == 4 + int(3 * np.log(4))  # Hansen's default
    state = np.random.get_state()[1].copy()  # noqa: NPY002 - checking the legacy global state
    res = run_cmaes(rosen, np.zeros(4), sigma0=0.5, max_evals=8000, seed=1)
    np.testing.assert_array_equal(np.random.get_state()[1], state)  # noqa: NPY002
    assert res.loss < 1e-8
    np.testing.assert_allclose(res.theta, 1.0, atol=1e-3)
    assert set(calls) == {(lam, 4)} and len(calls) == len(res.history) == res.evals // lam
    again = run_cmaes(rosen, np.zeros(4), sigma0=0.5, max_evals=8 * lam, seed=1)
    np.testing.assert_array_equal(
        again.theta, run_cmaes(rosen, np.zeros(4), sigma0=0.5, max_evals=8 * lam, seed=1).theta
    )
    other = run_cmaes(rosen, np.zeros(4), sigma0=0.5, max_evals=8 * lam, seed=2)
    assert not np.array_equal(again.theta, other.theta)
    with pytest.raises(ValueError, match="sigma0"):
        run_cmaes(rosen, np.zeros(4), sigma0=-1.0)


def test_blackbox_drivers_on_a_jax_objective():
    loss = lambda th, c: jnp.sum((th - c) ** 2)
    f = batch_objective(loss, (jnp.asarray([1.0, -2.0, 0.5]),))
    res = run_cmaes(f, np.zeros(3), sigma0=1.0, max_evals=1200)
    assert res.loss < 1e-6 and res.evals <= 1200
    res = run_random_search(f, np.zeros(3), radius=1.0, max_evals=400, popsize=20)
    assert res.loss < 1.0 and res.history[-1]["cum_evals"] == 400


# ------------------------------------------------------------------ configuration


@pytest.mark.parametrize(
    ("raw", "match"),
    [
        ({"problme": {}}, r"unknown section \[problme\] \(did you mean 'problem'\?\)"),
        ({"problem": {"horizn": 1.0}}, r"\[problem\] horizn: unknown key \(did you mean"),
        ({"problem": {"horizon": -1.0}}, r"\[problem\] horizon"),
        ({"problem": {"dt": "0.1"}}, r"\[problem\] dt: expected a finite number"),
        ({"problem": {"variant": "pid"}}, r"\[problem\] variant"),
        ({"problem": {"tune": ["P_K"]}}, r"\[problem\] tune: unknown gains"),
        ({"problem": {"alpha": 1.5}}, r"\[problem\] alpha"),
        ({"weights": {"eps": -1.0}}, r"\[weights\] eps"),
        ({"train": {"size": 0}}, r"\[train\] size"),
        ({"train": {"size": 2.5}}, r"\[train\] size: expected an integer"),
        ({"optimizer": {"name": "sgd"}}, r"\[optimizer\] name"),
        ({"optimizer": {"grad_mode": "both"}}, r"\[optimizer\] grad_mode"),
        ({"heldout": {"smooth": 1}}, r"\[heldout\] smooth"),
        ({"problem": {"horizon": 0.05, "dt": 0.1}}, "horizon"),
        ({"problem": 3}, "expected a table"),
    ],
)
def test_config_validation_errors(raw, match):
    with pytest.raises(ConfigError, match=match):
        validate_config(raw)


def test_config_defaults_and_file_errors(tmp_path):
    cfg = validate_config({"optimizer": {"steps": 3}, "weights": {"eps": 2}})
    assert cfg["optimizer"]["steps"] == 3 and cfg["weights"]["eps"] == 2.0
    assert cfg["optimizer"]["name"] == "lbfgs" and cfg["problem"]["variant"] == "vcm_integral"
    bad = tmp_path / "bad.toml"
    bad.write_text("[problem\nhorizon = 1")
    with pytest.raises(ConfigError, match="invalid TOML"):
        run_tune_config(bad, tmp_path / "out", progress=None)
    same = tmp_path / "same.toml"
    same.write_text("[train]\nseed = 3\n[heldout]\nseed = 3\n")
    with pytest.raises(ConfigError, match=r"\[heldout\] seed: must differ from \[train\] seed"):
        run_tune_config(same, tmp_path / "out", progress=None)
    with pytest.raises(ConfigError, match="cannot read"):
        run_tune_config(tmp_path / "missing.toml", tmp_path / "out", progress=None)


# ------------------------------------------------------------------ end to end (slow)

TINY_TOML = """
[problem]
horizon = 4.0
dt = 0.1
integrator = "euler"
timing = "sampled"
[train]
size = 2
[heldout]
size = 3
[optimizer]
name = "adam"
steps = 3
learning_rate = 0.1
[report]
plot_scenarios = 2
"""


def test_vcjax_tune_end_to_end(tmp_path, capsys):
    """``vcjax tune`` writes every artefact; the gains load into ``vcjax simulate --gains``."""
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY_TOML)
    out = tmp_path / "out"
    assert cli.main(["tune", str(cfg), "--out", str(out)]) == 0
    assert "held-out loss" in capsys.readouterr().out
    result = {"summary": json.loads((out / "summary.json").read_text())}
    for name in ("gains.json", "history.json", "summary.json", "loss_curve.png"):
        assert (out / name).exists()
    run = json.loads((out / "run.json").read_text())
    assert run["command"] == "tune" and run["seeds"] == {"train": 0, "heldout": 1001}
    assert run["config"]["optimizer"]["steps"] == 3
    assert (out / "before_after_paths.png").read_bytes()[:4] == b"\x89PNG"
    s = json.loads((out / "summary.json").read_text())
    assert s == json.loads(json.dumps(result["summary"]))
    assert np.isfinite(s["heldout_loss_before"]) and np.isfinite(s["heldout_loss_after"])
    h = json.loads((out / "history.json").read_text())
    assert len(h["iterations"]) == 3 and "gains" in h["iterations"][0]
    g = _infante("vcm").gains_from_json(json.loads((out / "gains.json").read_text()))
    np.testing.assert_allclose(g.vcm.Delta, s["tuned_gains"]["Delta"])


def test_vcjax_tune_rejects_a_bad_config(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[optimizer]\nname = 'sgd-with-magic'\n")
    assert cli.main(["tune", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "optimizer" in capsys.readouterr().err


# ------------------------------------------------------------------ any loop


def test_gain_space_of_the_odin_loop_keeps_the_depth_pid_stable():
    """Every theta decodes to gains that pass the ODIN loop's own validation (the depth PID's
    Routh–Hurwitz condition k_d k_p > k_i included: depth_i is a fraction of k_p k_d)."""
    from vcjax import loops

    loop = loops.make_loop("odin", "vcm")
    assert GainSpace(loop=loop).tune[-1] == "attitude"
    space = GainSpace(
        loop=loop, tune=("depth_i", "P_G", "P_Phi", "Delta", "sigma", "P_int", "depth_pd")
    )
    assert space.tune == ("P_G", "P_Phi", "Delta", "sigma", "P_int", "depth_pd", "depth_i")
    assert space.labels()[-3:] == ["depth_pd[0]", "depth_pd[1]", "depth_i"]
    base = loop.default_gains()
    rng = np.random.default_rng(1)
    for _ in range(10):
        theta = jnp.asarray(rng.normal(scale=2.0, size=space.size))
        g = space.decode(theta, base)
        loops.odin_gains(vcm=g.vcm, depth=np.asarray(g.depth), attitude=np.asarray(g.attitude))
        kp, kd, ki = np.asarray(g.depth)
        assert ki < FRAC_MAX * kp * kd * (1 + 1e-12)
        np.testing.assert_allclose(space.encode(g), theta, rtol=1e-9, atol=1e-9)
        np.testing.assert_array_equal(g.attitude, base.attitude)  # attitude not in tune
    with pytest.raises(ValueError, match=r"choose from \['P_G', 'P_Phi', 'sigma'\]"):
        GainSpace(loop=loops.make_loop("arm", "vcm"), tune=("Delta",))


def test_tuning_batch_is_the_sweeps_scenarios():
    """A tuning batch is what a sweep with the same distribution and seed runs."""
    from tuning.scenarios import scenario_at, scenario_spec
    from vcjax import loops, sweep

    loop = loops.make_loop("arm", "vcm")
    extra = {"initial": (("q1_deg", (0.0, 30.0)),), "disturbance": ((-1.0, 1.0), (0.0, 0.0))}
    batch = sample_scenarios(3, 5, loop=loop, current_max=0.0, extra=extra)
    spec = scenario_spec(loop, current_max=0.0, extra=extra)
    mc = sweep.sample_scenarios(spec, 3, np.arange(5), loop=loop)
    np.testing.assert_array_equal(batch.eta0, mc.eta0)
    np.testing.assert_array_equal(batch.disturbance, mc.disturbance)
    assert np.all(np.degrees(np.asarray(batch.eta0[:, 0])) >= 0.0)
    assert np.all(np.degrees(np.asarray(batch.eta0[:, 0])) <= 30.0)
    one = scenario_at(batch, 2)
    np.testing.assert_array_equal(one.eta0, batch.eta0[2])
    assert one.path is batch.path


@pytest.mark.parametrize(
    ("raw", "match"),
    [
        ({"scenario": {"vehicle": "arm"}, "problem": {"tune": ["Delta"]}}, r"\[problem\] tune"),
        ({"scenario": {"vehicle": "arm"}, "initial": {"x": 1.0}}, r"\[initial\] x: unknown key"),
        ({"scenario": {"vehicle": "odin"}, "model_error": {"fields": ["mass"]}}, "fields"),
        ({"scenario": {"vehicle": "odin"}, "problem": {"variant": "ilos"}}, r"\[problem\] variant"),
        ({"scenario": {"controller": "vcm"}, "problem": {"variant": "ilos"}}, "contradicts"),
        ({"model_error": {"relative": 1.0}}, r"\[model_error\] relative"),
        ({"disturbance": {"force": 3.0}}, r"\[disturbance\] force"),
    ],
)
def test_tune_config_scenario_errors(raw, match):
    with pytest.raises(ConfigError, match=match):
        validate_config(raw)


@pytest.mark.slow
def test_engine_loop_loss_gradient_matches_central_differences():
    """The arm's tuning loss (smooth torque limits that bind) differentiated through the
    engine's reaction force: reverse mode against central differences."""
    from vcjax import loops

    loop = loops.make_loop("arm", "vcm")
    problem = TuningProblem(space=GainSpace(loop=loop), num_steps=60, timing="sampled")
    data = problem_data(problem, dt=0.01)
    small = loops.arm_loop_params(tau_max=(20.0, 5.0))
    batch = sample_scenarios(0, 2, loop=loop, current_max=0.0, nominal=Nominal(small, small))
    f = jax.jit(lambda th: objective(th, data, batch, problem)[0])
    g = np.asarray(
        jax.jit(jax.grad(lambda th: objective(th, data, batch, problem)[0]))(data.theta_ref)
    )
    h = 1e-5
    th = data.theta_ref
    fd = np.array(
        [(float(f(th.at[i].add(h))) - float(f(th.at[i].add(-h)))) / (2 * h) for i in range(th.size)]
    )
    np.testing.assert_allclose(g, fd, rtol=1e-4, atol=1e-6 * np.max(np.abs(fd)))
    terms = objective(th, data, batch, problem)[1][1]
    assert float(np.max(terms["sat_time"])) > 0  # the limits do bind


def test_example_tuning_configs_are_valid():
    from pathlib import Path

    from tuning.config import load_config

    root = Path(__file__).parents[1]
    files = sorted((root / "examples" / "tuning").glob("*.toml"))
    assert {"sim2.toml", "arm.toml", "puck.toml", "quick.toml"} <= {f.name for f in files}
    study = sorted((root / "benchmarks" / "configs").glob("tuners_*.toml"))  # the tuner study's
    assert len(study) == 3
    for f in files + study:
        cfg = load_config(f)
        assert cfg.problem.variant and cfg.scenario.vehicle and cfg["scenario"]["vehicle"]


def _on_two_devices(script: str) -> dict:
    """Run ``script`` in a fresh process whose host CPU is split into two JAX devices (the count
    is fixed when JAX starts); return the JSON its last line prints."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    flags = os.environ.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=2"
    env = {**os.environ, "XLA_FLAGS": flags.strip()}
    env.pop("VCJAX_CPU_DEVICES", None)
    out = subprocess.run(
        [sys.executable, "-c", script],
        env=env,
        cwd=Path(__file__).parents[1],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


_SHARDED_TUNE = """
import json
import jax, jax.numpy as jnp, numpy as np
jax.config.update("jax_enable_x64", True)
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from tuning.optim import make_optimizer, make_step, run_gradient_tuner
assert jax.device_count() == 2
rng = np.random.default_rng(0)
A = jnp.asarray(rng.normal(size=(8, 3, 3)) + 3 * np.eye(3))
b = jnp.asarray(rng.normal(size=(8, 3)))
mesh = Mesh(np.asarray(jax.devices()), ("scenarios",))
A, b = (jax.device_put(x, NamedSharding(mesh, P("scenarios"))) for x in (A, b))
loss = lambda th, A, b: jnp.mean(jnp.sum((jnp.einsum("bij,j->bi", A, th) - b) ** 2, -1))
step = make_step(loss, make_optimizer("lbfgs", 0.05, 10, 15), "lbfgs")
res = run_gradient_tuner(loss, jnp.zeros(3), (A, b), steps=6, step_fn=step)
An, bn = np.asarray(A), np.asarray(b)
exact = np.linalg.solve(np.einsum("bki,bkj->ij", An, An), np.einsum("bki,bk->i", An, bn))
print(json.dumps({"compiles": step._cache_size(), "err": float(np.max(np.abs(res.theta - exact)))}))
"""


def test_tuner_compiles_its_step_once_when_the_batch_is_sharded():
    """With the training batch sharded over two devices, the step returns parameters and state
    replicated over both; the tuner starts from that placement, so ``jax.jit`` compiles the step
    once (it compiled twice before: the whole reverse-mode rollout again at step 2). Also: the
    minimum is that of the normal equations (NumPy)."""
    res = _on_two_devices(_SHARDED_TUNE)
    assert res["compiles"] == 1
    assert res["err"] < 1e-8


_SHARDED_GRAD = """
import dataclasses, json
import jax
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp, numpy as np
from tests.reference.hlo import loop_allreduces
from tuning.run import distribute
from tuning.loss import TuningProblem, objective, problem_data
from tuning.scenarios import sample_scenarios
assert jax.device_count() == 2
prob = TuningProblem(num_steps=40, integrator="euler", timing="sampled")
data = problem_data(prob, dt=0.1)
scen = sample_scenarios(0, 4, current_max=1.0)
theta = data.theta_ref + 0.1 * jnp.arange(12.0) / 12.0
scen_d, data_d, theta_d = distribute(scen, data, theta)
assert scen_d is not scen
from tuning.scenarios import shard_scenarios
sharded, n = shard_scenarios(scen)  # the held-out batch's placement: over the local devices
three = scen._replace(eta0=scen.eta0[:3])
out = {"shard": {
    "n": n, "devices": len(sharded.eta0.sharding.device_set),
    "shards": [list(x.data.shape) for x in sharded.eta0.addressable_shards],
    "equal": bool(np.array_equal(np.asarray(sharded.eta0), np.asarray(scen.eta0))),
    "path_same": all(a is c for a, c in zip(jax.tree.leaves(sharded.path), jax.tree.leaves(scen.path))),
    "uneven": shard_scenarios(three)[1] == 1 and shard_scenarios(three)[0] is three,
}}
for tile in (False, True):
    p = dataclasses.replace(prob, tile_gains=tile)
    f = jax.jit(jax.value_and_grad(lambda th, d, s: objective(th, d, s, p)[0]))
    compiled = f.lower(theta_d, data_d, scen_d).compile()  # compiled once: run and read
    v, g = compiled(theta_d, data_d, scen_d)
    text = compiled.as_text()
    in_loops = loop_allreduces(text)
    out[str(tile)] = {"v": float(v), "g": np.asarray(g).tolist(), "in_loops": in_loops}
v1, g1 = jax.jit(jax.value_and_grad(lambda th: objective(th, data, scen, prob)[0]))(theta)
out["single"] = {"v": float(v1), "g": np.asarray(g1).tolist()}
print(json.dumps(out))
"""


def test_tiled_gains_on_a_sharded_batch_reduce_once_with_the_same_gradient():
    """Training batch sharded over two devices: with the gains shared by the ``vmap``, XLA
    reduces their cotangent across devices at every step of the backward scan (all-reduce inside
    the loop: 18x slower measured); tiled per scenario (``tile_gains``, what ``vcjax tune`` uses
    when it shards) the loop bodies hold no all-reduce. Loss and gradient are those of one device
    with the gains shared (1e-12)."""
    res = _on_two_devices(_SHARDED_GRAD)
    # shard_scenarios: an even batch split along its scenarios, the shared fields left alone
    sh = res.pop("shard")
    assert sh["n"] == 2 and sh["devices"] == 2 and sh["shards"] == [[2, 3], [2, 3]]
    assert sh["equal"] and sh["path_same"] and sh["uneven"]
    assert res["False"]["in_loops"] >= 1  # the per-step reduction the tiling removes
    assert res["True"]["in_loops"] == 0
    for k in ("False", "True"):
        np.testing.assert_allclose(res[k]["v"], res["single"]["v"], rtol=1e-12)
        np.testing.assert_allclose(res[k]["g"], res["single"]["g"], rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(res["single"]["g"])) > 0


def test_tile_gains_must_be_a_bool():
    with pytest.raises(ValueError, match="tile_gains"):
        TuningProblem(tile_gains="yes")


def _rosenbrock(th, a):
    return jnp.sum(a * (th[1:] - th[:-1] ** 2) ** 2 + (1.0 - th[:-1]) ** 2)


def _barrier(th, a):  # NaN for th <= 0: the line search must stay inside
    return jnp.sum((th - 3.0) ** 2) - a[0] * jnp.sum(jnp.log(th))


@pytest.mark.parametrize(
    "loss, th0, a, max_ls",
    [
        (_rosenbrock, [-1.2, 1.0, -0.5, 0.8], [100.0, 80.0, 120.0], 12),
        (_barrier, [0.01, 0.02, 0.5], [1.0], 2),
    ],
    ids=["rosenbrock", "barrier-budget-2"],
)
def test_host_driven_lbfgs_takes_optax_steps(loss, th0, a, max_ls):
    """The L-BFGS step drives the zoom line search (``tuning.linesearch``) from the host around
    one compiled value_and_grad; its iterates, losses and evaluation counts are those of
    ``optax.lbfgs`` run in one jitted step (the line search in its while_loop): on a function
    whose line searches both extend and zoom (Rosenbrock's, from its classic start), and with a
    budget of 2 evaluations, on a barrier whose search runs out and takes its safe step."""
    import optax

    from tuning.optim import LBFGSStep, init_state, make_optimizer, make_step

    a, th0 = jnp.asarray(a), jnp.asarray(th0)
    opt = make_optimizer("lbfgs", memory_size=5, max_linesearch_steps=max_ls)
    step = make_step(loss, opt, "lbfgs")
    assert isinstance(step, LBFGSStep)

    @jax.jit
    def optax_step(theta, state):  # the jitted optax way
        f = lambda p: loss(p, a)
        with jax.numpy_dtype_promotion("standard"):  # optax's arithmetic, as in the tuner
            value, grad = optax.value_and_grad_from_state(f)(theta, state=state)
            upd, new = opt.update(grad, state, theta, value=value, grad=grad, value_fn=f)
        return theta + upd, new, value

    th_a, st_a = th0, init_state(opt, th0)
    th_b, st_b = th0, init_state(opt, th0)
    counts, ran_out = [], 0
    for _ in range(12):
        th_a, st_a, info = step(th_a, st_a, jnp.asarray(1.0), (a,))
        th_b, st_b, value_b = optax_step(th_b, st_b)
        assert bool(info.ok)
        assert float(info.loss) == pytest.approx(float(value_b), rel=1e-13, abs=1e-300)
        np.testing.assert_allclose(th_a, th_b, rtol=1e-12, atol=1e-14)
        ls = optax.tree.get(st_b, "info")
        counts.append(int(ls.num_linesearch_steps))
        ran_out += counts[-1] == max_ls and float(ls.curvature_error) > 0
        assert int(info.evals) == counts[-1] + (len(counts) == 1)
    assert max(counts) > 1  # some line searches took more than one evaluation
    assert float(loss(th_a, a)) < float(loss(th0, a)) - 0.9 * abs(float(loss(th0, a)))
    assert (ran_out > 0) == (max_ls == 2)  # the budget of 2 ran out: the safe step was taken
    assert step._cache_size() == 1  # the one value_and_grad compiled once


def test_change_text_never_calls_a_rise_lower():
    from tuning.report import change_text

    assert change_text(58.5788, 59.5437) == "1.6 % higher"
    assert change_text(10.0, 7.5) == "25.0 % lower"
    assert change_text(10.0, 10.0) == "unchanged"
    assert change_text(0.0, 1.0) == "not comparable"
