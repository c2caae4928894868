"""vcjax.search (``vcjax falsify``): the gradient of a metric with respect to the scenario
parameters against central finite differences, the projection onto the envelope, the replay of
what the search found, and refusals of bad envelopes."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import loops
from vcjax.search import Envelope, evaluate, falsify, make_setting
from vcjax.search.core import _metrics

jax.config.update("jax_enable_x64", True)


def _fd_check(loop, env, setting, metric, x0, rel=1e-5, h=1e-5, mode="forward"):
    """Gradient of ``metric`` (its surrogate for a max) at ``x0`` in ``mode`` (forward, the
    search's default for a few parameters, or reverse) vs central differences in every
    searched parameter, one step ``h`` relative to the box width."""
    gains = loop.default_gains()

    def f(x):
        return _metrics(x, 3, gains, env, setting, metric, 16.0)[0]

    x0 = jnp.asarray(x0, jnp.float64)
    g = np.asarray(jax.jit(jax.jacfwd(f) if mode == "forward" else jax.grad(f))(x0))
    idx = [env.names.index(n) for n in env.searched]
    steps = np.zeros((len(idx), x0.size))
    for j, i in enumerate(idx):
        steps[j, i] = h * (env.hi[i] - env.lo[i])
    xs = jnp.concatenate([x0 + steps, x0 - steps])
    v = np.asarray(jax.jit(jax.vmap(f))(xs))
    fd = (v[: len(idx)] - v[len(idx) :]) / (2 * steps[np.arange(len(idx)), idx])
    scale = np.max(np.abs(fd))
    assert scale > 0
    for j, i in enumerate(idx):
        err = abs(g[i] - fd[j])
        assert err <= rel * max(abs(fd[j]), 1e-2 * scale), (env.names[i], g[i], fd[j])
    return g, fd


def _infante():
    loop = loops.make_loop("infante", "vcm_integral")
    env = Envelope.build(
        loop,
        {
            "current_speed": (0.0, 0.5),
            "current_direction_deg": (0.0, 360.0),
            "initial.y": (-5.0, 5.0),
            "initial.heading_deg": (60.0, 120.0),
        },
    )
    return loop, env, make_setting(loop, env, horizon=2.0, dt=0.05, seed=1)


@pytest.mark.parametrize(
    "metric", ["rms_cross_track_e", pytest.param("max_abs_e", marks=pytest.mark.slow)]
)
def test_gradient_in_current_and_initial_state_matches_finite_differences(metric):
    loop, env, setting = _infante()
    x0 = np.asarray(env.lo) + 0.37 * (np.asarray(env.hi) - np.asarray(env.lo))
    _fd_check(loop, env, setting, metric, x0)


@pytest.mark.slow  # REMUS 100 in a sea: a minute or more to compile on a loaded machine
def test_gradient_in_sea_state_and_depth_matches_finite_differences():
    loop = loops.make_loop("remus100", "vcm3d")
    env = Envelope.build(
        loop,
        {
            "wave_hs": (0.5, 3.0),
            "wave_tp": (5.0, 12.0),
            "wave_direction_deg": (0.0, 360.0),
            "wave_spreading": 3.0,  # searchable; its gradient is JAX's approximate one
            "wave_origin_depth": (2.0, 10.0),
        },
        dt=0.05,
    )
    setting = make_setting(loop, env, horizon=1.5, dt=0.05, components=8, seed=2)
    x0 = np.asarray(env.lo) + 0.41 * (np.asarray(env.hi) - np.asarray(env.lo))
    _fd_check(loop, env, setting, "rms_depth_err", x0, mode="reverse")


@pytest.mark.slow  # 6 s: compiles the reverse pass; the default run checks forward mode vs FD
def test_forward_and_reverse_mode_give_the_same_ascent_gradient():
    """The search's two ways of differentiating (one tangent per searched parameter, or the
    reverse pass) agree, and leave the fixed parameters' entries at zero."""
    from vcjax.search.core import AscentSpec, _key, _value_and_grad, gradient_mode

    loop, env, setting = _infante()
    gains = loop.default_gains()
    rng = np.random.default_rng(0)
    width = (np.asarray(env.hi) > np.asarray(env.lo)).astype(float)
    z = jnp.asarray(rng.random((2, len(env.names))) * width)
    axes = tuple(int(i) for i in np.flatnonzero(width))
    kw = dict(env=env, setting=_key(setting))
    out = {
        mode: _value_and_grad(
            z,
            jnp.arange(2),
            gains,
            setting.nominal,
            how=AscentSpec("rms_cross_track_e", 16.0, axes, mode),
            **kw,
        )
        for mode in ("forward", "reverse")
    }
    (mf, gf), (mr, gr) = out["forward"], out["reverse"]
    np.testing.assert_allclose(np.asarray(gf), np.asarray(gr), rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(np.asarray(mf["rms_cross_track_e"]), mr["rms_cross_track_e"])
    assert np.all(np.asarray(gf)[:, width == 0] == 0) and np.all(np.abs(np.asarray(gf)).max(1) > 0)
    assert gradient_mode("auto", 4) == "forward" and gradient_mode("auto", 40) == "reverse"
    with pytest.raises(ValueError, match="gradient: expected"):
        gradient_mode("backward", 4)


def test_projection_onto_the_envelope():
    loop, env, _ = _infante()
    lo, hi = np.asarray(env.lo), np.asarray(env.hi)
    x = np.stack([lo - 1.0, hi + 1.0, 0.5 * (lo + hi)])
    p = np.asarray(env.project(jnp.asarray(x)))
    np.testing.assert_array_equal(p[0], lo)
    np.testing.assert_array_equal(p[1], hi)
    np.testing.assert_array_equal(p[2], 0.5 * (lo + hi))
    # unit coordinates: inverse maps, fixed parameters at their value
    z = env.to_unit(x[2])
    np.testing.assert_allclose(np.asarray(env.from_unit(jnp.asarray(z))), x[2])
    fixed = [i for i, n in enumerate(env.names) if n not in env.searched]
    assert fixed and np.all(z[fixed] == 0)


@pytest.mark.slow  # 11 s; the CLI test replays
def test_search_stays_in_the_envelope_beats_nothing_it_did_not_run_and_replays():
    loop, env, setting = _infante()
    gains = loop.default_gains()
    res = falsify(loop, gains, env, "max_cross_track", setting, starts=3, steps=3, step_size=0.2)
    assert res.metric == "max_abs_e"
    assert res.rollouts == 9 and res.random_rollouts == 9
    assert np.all(res.x >= np.asarray(env.lo)) and np.all(res.x <= np.asarray(env.hi))
    assert [c[0] for c in res.curve] == [3, 6, 9]
    assert np.all(np.diff([c[1] for c in res.curve]) >= 0)
    assert res.worst == max(res.value) and res.random_worst == max(res.random_value)
    rows = res.scenarios(keep=20)
    assert len(rows) == 12
    vals = [r["max_abs_e"] for r in rows]
    assert vals == sorted(vals, reverse=True)
    # replay: the recorded parameters and scenario numbers give the recorded metric
    x = np.stack([env.vector(r["params"]) for r in rows])
    m = evaluate(loop, gains, env, setting, "max_abs_e", x, [r["index"] for r in rows])
    np.testing.assert_allclose(m["max_abs_e"], vals, rtol=1e-12)


@pytest.mark.slow  # 7 s; the CLI test's --bound stays default
def test_bound_stops_the_search_as_soon_as_it_is_exceeded():
    loop, env, setting = _infante()  # the shapes of the test above: its programs are reused
    res = falsify(loop, loop.default_gains(), env, "max_abs_e", setting, starts=3, steps=5, bound=0)
    assert res.falsified and res.rollouts == 3 and res.random_falsified
    assert res.random_rollouts == 3
    # a stop request (Ctrl-C) ends the search at the next step and keeps what was found
    res = falsify(
        loop, loop.default_gains(), env, "max_abs_e", setting, starts=3, steps=5, stop=lambda: True
    )
    assert res.interrupted and res.rollouts == 3 and res.random_rollouts == 0
    assert np.isfinite(res.worst) and len(res.scenarios()) == 3


@pytest.mark.parametrize(
    ("ranges", "match"),
    [
        ({"current_speed": (0.5, 0.1)}, "current_speed: lo > hi"),
        ({"current_sped": (0.0, 0.5)}, "unknown parameters \\['current_sped'\\]"),
        ({"current_speed": (-0.1, 0.5)}, "current_speed: must be >= 0"),
        ({"u_d": (0.0, 2.0)}, "u_d: must be > 0"),
        ({"initial.y": (0.0, float("nan"))}, "initial.y: bounds must be finite"),
        ({"model.not_a_field": (0.9, 1.1)}, "unknown parameters"),
        ({"current_speed": "fast"}, "current_speed: expected a number or \\[lo, hi\\]"),
    ],
)
def test_bad_envelopes_are_refused(ranges, match):
    loop = loops.make_loop("infante", "vcm_integral")
    with pytest.raises(ValueError, match=match):
        Envelope.build(loop, ranges)


def test_bad_sea_envelopes_are_refused():
    remus = loops.make_loop("remus100", "vcm3d")
    with pytest.raises(ValueError, match="wave_tp: a sea needs wave_hs and wave_tp"):
        Envelope.build(remus, {"wave_hs": (0.5, 3.0)})
    with pytest.raises(ValueError, match="wave_hs: must be >= 0"):
        Envelope.build(remus, {"wave_hs": (-1.0, 3.0), "wave_tp": 8.0})
    with pytest.raises(ValueError, match="wave_tp"):
        Envelope.build(remus, {"wave_hs": 1.0, "wave_tp": (1.0, 8.0)}, dt=0.05)
    with pytest.raises(ValueError, match="searched spreading must stay > 0"):
        Envelope.build(remus, {"wave_hs": 1.0, "wave_tp": 8.0, "wave_spreading": (0.0, 5.0)})
    infante = loops.make_loop("infante", "vcm_integral")
    with pytest.raises(ValueError, match="waves"):
        Envelope.build(infante, {"wave_hs": 1.0, "wave_tp": 8.0})


#: the envelope, horizon, seed and batch sizes of _infante() and the search test above: run
#: in the same process, the command reuses their compiled programs
CLI_CONFIG = """
[scenario]
controller = "vcm_integral"
[falsify]
metric = "max_cross_track"
starts = 3
steps = 3
random_rollouts = 9
keep = 12
seed = 1
[simulation]
horizon = 2.0
dt = 0.05
[current]
speed = [0.0, 0.5]
direction_deg = [0.0, 360.0]
[initial]
y = [-5.0, 5.0]
heading_deg = [60.0, 120.0]
"""


def test_cli_writes_worst_summary_figures_and_replays_them(tmp_path, capsys):
    import json

    from vcjax import cli

    cfg = tmp_path / "f.toml"
    cfg.write_text(CLI_CONFIG)
    out = tmp_path / "out"
    assert cli.main(["falsify", str(cfg), "--out", str(out)]) == 0
    worst = json.loads((out / "worst.json").read_text())
    assert worst["metric"] == "max_abs_e" and len(worst["scenarios"]) == 12
    vals = [s["max_abs_e"] for s in worst["scenarios"]]
    assert vals == sorted(vals, reverse=True)
    assert set(worst["scenarios"][0]["params"]) >= {"current_speed", "initial.y"}
    summary = json.loads((out / "summary.json").read_text())
    for k in ("metric", "rollouts", "random_rollouts", "worst", "random_worst", "wall_s"):
        assert k in summary
    assert summary["rollouts"] == 9 and summary["random_rollouts"] == 9
    assert (
        summary["worst"] == max(summary["worst"], summary["random_worst"])
        or vals[0] == (summary["random_worst"])
    )
    assert vals[0] == max(summary["worst"], summary["random_worst"])
    # when the search first beat random sampling's worst: a step of its curve, or never
    curve = dict(summary["curve"])
    if summary["worst"] > summary["random_worst"]:
        n = summary["beat_random_rollouts"]
        assert (
            curve[n] > summary["random_worst"] and 0 < summary["beat_random_s"] <= summary["wall_s"]
        )
        assert all(w <= summary["random_worst"] for r, w in summary["curve"] if r < n)
    else:
        assert summary["beat_random_s"] is None and summary["beat_random_rollouts"] is None
    assert summary["gradient"] == "forward"
    # no sea: no surface to check
    assert summary["worst_above_surface_fraction"] is None and summary["warnings"] == []
    for f in ("falsify_worst.png", "falsify_curve.png", "run.json"):
        assert (out / f).is_file()
    # the replay runs the same scenarios again: the same metric
    rep = tmp_path / "rep"
    args = ["falsify", str(cfg), "--replay", str(out / "worst.json"), "--out", str(rep)]
    assert cli.main(args) == 0
    got = json.loads((rep / "replay.json").read_text())["scenarios"]
    np.testing.assert_allclose([s["max_abs_e"] for s in got], vals, rtol=1e-12)
    # an existing output folder is refused without --overwrite
    assert cli.main(["falsify", str(cfg), "--out", str(out)]) == 2
    assert "--overwrite" in capsys.readouterr().err
    # --bound: falsified at the first step that exceeds it
    args = ["falsify", str(cfg), "--out", str(out), "--overwrite", "--bound", "1"]
    assert cli.main(args) == 0
    assert "bound 1: FALSIFIED" in capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert summary["falsified"] and summary["rollouts"] == 3 and summary["bound"] == 1.0


@pytest.mark.parametrize(
    ("old", "new", "args", "match"),
    [
        ("starts = 3", "starts = 0", [], "[falsify] starts"),
        ("keep = 12", "bogus = 1", [], "[falsify] bogus: unknown key"),
        ("keep = 12", "gradient = 'backward'", [], "[falsify] gradient: expected one of"),
        ("", "", ["--metric", "max_speed"], "unknown metric 'max_speed'"),
        ("speed = [0.0, 0.5]", "speed = [0.5, 0.1]", [], "speed"),
        ("y = [-5.0, 5.0]", "bogus = [0.0, 1.0]", [], "bogus"),
        ("horizon = 2.0", "horizon = -1.0", [], "horizon"),
        ("", "", ["--bound", "nan"], "bound"),
    ],
)
def test_cli_refuses_bad_input_before_touching_out(tmp_path, capsys, old, new, args, match):
    from vcjax import cli

    cfg = tmp_path / "f.toml"
    cfg.write_text(CLI_CONFIG.replace(old, new) if old else CLI_CONFIG)
    out = tmp_path / "out"
    assert cli.main(["falsify", str(cfg), "--out", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert match in err and "Traceback" not in err
    assert not out.exists()


def test_vcjax_falsify_is_the_search():
    import vcjax
    import vcjax.search

    assert vcjax.falsify is vcjax.search.falsify


@pytest.mark.slow  # two more compiles (a sweep's batch and the search's forward)
def test_a_scenario_of_the_search_is_the_sweeps_scenario_of_the_same_number():
    """The envelope's scenario ``index`` with a sweep's sampled values of scenario ``index`` is
    that sweep's scenario: the same metrics (an independent path: the sweep's own sampler)."""
    from vcjax.search import envelope_from_spec, setting_from_spec
    from vcjax.sweep import ScenarioSpec, SweepSpec, run_sweep

    spec = SweepSpec(
        num_scenarios=3,
        scenario=ScenarioSpec(
            current_speed=(0.0, 0.5),
            current_direction_deg=(0.0, 360.0),
            initial=(("y", (-5.0, 5.0)), ("heading_deg", (60.0, 120.0))),
        ),
        variants=("vcm_integral",),
        horizon=2.0,
        dt=0.05,
        seed=7,
        record_points=0,
    )
    res = run_sweep(spec, progress=False)
    env = envelope_from_spec(spec)
    setting = setting_from_spec(spec, env)
    sc = res.scenarios
    eta0, nu0 = np.asarray(sc["eta0"]), np.asarray(sc["nu0"])
    params = {
        "current_speed": sc["current_speed"],
        "current_direction_deg": np.degrees(sc["current_direction"]),
        "u_d": sc["u_d"],
        "initial.x": eta0[:, 0],
        "initial.y": eta0[:, 1],
        "initial.heading_deg": np.degrees(eta0[:, 2]),
        "initial.speed": nu0[:, 0],
    }
    x = np.stack([np.asarray(params[n], float) for n in env.names], axis=1)
    loop = spec.loop("vcm_integral")
    m = evaluate(loop, loop.default_gains(), env, setting, "max_abs_e", x, res.index)
    for k in ("max_abs_e", "ss_abs_e", "rms_cross_track_e", "iae_e"):
        np.testing.assert_allclose(m[k], res.metrics["vcm_integral"][k], rtol=1e-10)


BROACH_CONFIG = """
[scenario]
vehicle = "remus100"
controller = "vcm3d_ilos"
[scenario.path]
kind = "line"
origin = [0.0, 0.0, 0.0]
direction = [1.0, 0.0, 0.0]

[falsify]
metric = "rms_depth_err"
starts = 2
steps = 1
random_rollouts = 2
seed = 0

[simulation]
horizon = 12.0
dt = 0.1
timing = "sampled"

[current]
speed = 0.0

[waves]
hs = 3.0
tp = [5.0, 6.0]
direction_deg = 180.0
components = 8
origin_depth = 0.6
"""


@pytest.mark.slow  # REMUS 100 in a sea: its search and forward programs compile (a minute loaded)
def test_a_worst_case_above_the_sea_surface_is_reported(tmp_path, capsys):
    """A leg 0.6 m under the mean surface in Hs 3 m seas: the troughs uncover the vehicle.
    The worst scenario's clearance below the local surface (depth below the mean surface plus
    the elevation above it) goes negative, and the command says so: summary.json's fraction of
    the run above the surface and least clearance, and a warning naming the submerged model."""
    import json

    from vcjax import cli

    cfg = tmp_path / "f.toml"
    cfg.write_text(BROACH_CONFIG)
    out = tmp_path / "out"
    assert cli.main(["falsify", str(cfg), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    summary = json.loads((out / "summary.json").read_text())
    frac, lowest = summary["worst_above_surface_fraction"], summary["worst_min_clearance_m"]
    assert 0.0 < frac <= 1.0 and lowest < 0.0
    assert summary["warnings"] and "above the local sea surface" in summary["warnings"][0]
    assert "vcjax: warning: falsify:" in err and "submerged model" in err
