"""The scenario layer (vcjax.loops, vcjax.metrics): registry, the engine loop against the
closed-form constraint dynamics, start parameters, parameter overrides and model error, the one
metrics function against hand computations — and a loop defined entirely in this file (a point
mass held on a curve by the generic engine) swept and tuned through the public API."""

import dataclasses
import json
import math
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from planar_loops import PlanarPointMass, PointMassParams

from tuning.loss import TuningProblem, objective, problem_data
from tuning.optim import run_gradient_tuner
from tuning.params import GainSpace
from tuning.scenarios import sample_scenarios as tuning_batch
from vcjax import loops, paths
from vcjax.config import ConfigError
from vcjax.config.scenario import ScenarioChoice, parse_scenario
from vcjax.metrics import (
    metric_names,
    metrics_finalize,
    metrics_init,
    metrics_update,
    run_metrics,
    window_start,
)
from vcjax.rollout import RolloutConfig
from vcjax.sweep import ScenarioSpec, SweepSpec, nominal, perturb_params, run_sweep

# ------------------------------------------------------------------ a loop of our own


@dataclasses.dataclass(frozen=True)
class PointMassLoop(PlanarPointMass, loops.EngineLoop):
    """A planar point mass ``m q'' + b q' = f`` whose position follows a path."""

    vehicle: ClassVar[str] = "pointmass"
    initial_keys: ClassVar[dict[str, float]] = {"x": 6.0, "y": 0.0, "vx": 0.0, "vy": 0.0}
    defaults: ClassVar[tuple] = (2.0, 0.5, (20.0, 20.0))
    default_speed: ClassVar[float] = 1.0

    @classmethod
    def default_path(cls):
        return paths.circle(center=(0.0, 0.0), radius=5.0)


loops.register(PointMassLoop)


def test_registry_lists_vehicles_and_controllers_and_names_bad_ones():
    assert {"infante", "odin", "arm", "pointmass"} <= set(loops.vehicles())
    assert loops.controllers("infante")[:5] == (
        "vcm",
        "vcm_integral",
        "vcm_ilos",
        "ilos",
        "los_pid",
    )
    assert loops.controllers("odin") == ("vcm", "vcm_full")
    with pytest.raises(ValueError, match=r"vehicle: expected one of \[.*'infante'"):
        loops.make_loop("submarine", "vcm")
    with pytest.raises(ValueError, match=r"supports \['vcm', 'vcm_full'\]"):
        loops.make_loop("odin", "ilos")
    loop = loops.make_loop("infante", "ilos", path=paths.CIRCLE, edd="implied")
    assert loop.path is paths.CIRCLE and loop.edd == "implied"
    with pytest.raises(ValueError, match="options"):
        loops.make_loop("infante", "vcm", bogus=1)


# ------------------------------------------------------------------ the engine loop, exactly


def test_engine_loop_errors_follow_the_designed_second_order_dynamics():
    """Perfect model, no saturation: each row of G = [s, e] obeys
    G'' + (p_G + p_Phi) G' + p_G p_Phi G = 0 (14), so with Phi = G' + p_G G:
    Phi(t) = Phi0 exp(-p_Phi t) and G(t) = G0 exp(-p_G t) + Phi0 (exp(-p_Phi t) - exp(-p_G t))
    / (p_G - p_Phi). The particle moves with the errors (sigma s), so this also checks that the
    engine differentiates along the particle's flow."""
    loop = loops.make_loop("pointmass", "vcm")
    big = PointMassParams(jnp.asarray(2.0), jnp.asarray(0.5), jnp.asarray([1e6, 1e6]))
    sc = loops.make_scenario(loop, initial={"x": 6.0, "y": 1.0, "vx": 0.3}, plant=big)
    g = loops.engine_gains(P_G=(1.0, 2.0), P_Phi=(3.0, 1.5), sigma=0.7)
    dt, n = 1e-3, 3000
    tr = jax.jit(lambda g_: loops.simulate(loop, g_, sc, RolloutConfig(num_steps=n), dt))(g)
    assert np.all(tr.finite)
    t = np.asarray(tr.t[:-1])
    G = np.asarray(tr.aux.eps)
    Phi0 = np.asarray(tr.aux.Phi[0])
    pG, pPhi = np.asarray(g.P_G), np.asarray(g.P_Phi)
    expect = G[0] * np.exp(-pG * t[:, None]) + Phi0 * (
        np.exp(-pPhi * t[:, None]) - np.exp(-pG * t[:, None])
    ) / (pG - pPhi)
    np.testing.assert_allclose(G, expect, atol=1e-9 * np.abs(G[0]).max() + 1e-12)
    np.testing.assert_allclose(np.asarray(tr.aux.Phi), Phi0 * np.exp(-pPhi * t[:, None]), atol=1e-9)
    assert np.abs(G[:, 0]).max() > 0.05 and abs(G[0, 1]) > 0.5  # a real transient


def test_arm_loop_holds_the_end_effector_on_its_circle():
    """The registered arm: from the demo's start the end effector converges to the circle at
    0.3 m/s (errors at round-off after 6 s; the designed poles are 4 and 6 1/s)."""
    loop = loops.make_loop("arm", "vcm")
    sc = loops.make_scenario(loop)
    n, dt = 1500, 4e-3
    tr = jax.jit(lambda g: loops.simulate(loop, g, sc, RolloutConfig(num_steps=n), dt))(
        loop.default_gains()
    )
    m = run_metrics(loop.signals(tr, sc), tr.finite, dt, 0.8)
    assert float(m["ss_abs_e"]) < 1e-6 and float(m["ss_abs_u_err"]) < 1e-5
    assert float(m["max_abs_e"]) > 0.05  # it did start off the circle
    # the end effector really is on the circle (independent of the controller's own errors)
    ee = np.asarray(loop.signals(tr, sc).pos[-1, :2])
    assert np.hypot(ee[0] - 1.0, ee[1] - 0.6) == pytest.approx(0.35, abs=1e-6)


def test_start_parameter_is_the_nearest_point():
    # circle: the nearest point is along the ray from the centre; w is arc length from phase 0
    path, c = paths.circle(center=(1.0, 2.0), radius=3.0)
    for ang in (0.3, 2.0, 4.0, 6.0):
        pt = jnp.asarray([1.0 + 5.0 * math.cos(ang), 2.0 + 5.0 * math.sin(ang), 0.0])
        w = float(loops.start_parameter(path, c, pt))
        assert (w / 3.0) % (2 * math.pi) == pytest.approx(ang, abs=1e-8)
    # line: the projection
    path, c = paths.line(origin=(10.0, 0.0), direction=(1.0, 1.0))
    w = float(loops.start_parameter(path, c, jnp.asarray([12.0, 4.0, 0.0])))
    assert w == pytest.approx((2.0 + 4.0) / math.sqrt(2.0), rel=1e-12)
    # waypoints: a point beside the second leg
    path, c = paths.waypoints([[0.0, 0.0], [0.0, 50.0], [20.0, 50.0]])
    w = float(loops.start_parameter(path, c, jnp.asarray([10.0, 52.0, 0.0])))
    p = np.asarray(paths.path_point(path, c, w))
    dp = np.asarray(jax.jacfwd(lambda v: paths.path_point(path, c, v))(jnp.asarray(w)))
    assert abs(np.dot(p - [10.0, 52.0, 0.0], dp)) < 1e-8  # normal to the path there


# ------------------------------------------------------------------ parameters


def test_param_files_overrides_and_model_error(tmp_path):
    loop = loops.make_loop("odin", "vcm")
    nom = loop.default_params()
    flat = tmp_path / "p.json"
    flat.write_text(json.dumps({"drag_coeff": 50.0, "body.W": 1800.0}))
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({"estimates": {"T_thrust": 0.3}, "std": {"T_thrust": 0.01}}))
    cfg = tmp_path / "c.toml"
    choice = parse_scenario(
        {"vehicle": "odin", "params": "p.json", "plant_params": "fit.json"}, "c.toml", cfg
    )
    plant, design = choice.nominal(loop)
    assert float(design.drag_coeff) == 50.0 and float(plant.drag_coeff) == 50.0
    assert float(design.body.W) == 1800.0 and float(plant.body.W) == 1800.0
    assert float(plant.T_thrust) == 0.3 and float(design.T_thrust) == float(nom.T_thrust)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"drag": 1.0}))
    with pytest.raises(
        ConfigError, match=r"unknown odin parameters \['drag'\].*valid:.*drag_coeff"
    ):
        parse_scenario({"vehicle": "odin", "params": "bad.json"}, "c.toml", cfg)
    with pytest.raises(ConfigError, match="no such file"):
        parse_scenario({"vehicle": "odin", "params": "none.json"}, "c.toml", cfg)
    # model error: dotted names reach into nested parameters, nothing else changes
    p = perturb_params(nom, ("body.D", "drag_coeff"), jnp.asarray([1.5, 0.5]))
    np.testing.assert_allclose(p.body.D, 1.5 * np.asarray(nom.body.D))
    assert float(p.drag_coeff) == pytest.approx(0.5 * float(nom.drag_coeff))
    np.testing.assert_array_equal(p.body.M_A, nom.body.M_A)


def test_scenario_section_errors_name_the_key(tmp_path):
    cfg = tmp_path / "c.toml"
    with pytest.raises(ConfigError, match=r"\[scenario\] controller: vehicle 'arm' supports"):
        parse_scenario({"vehicle": "arm", "controller": "ilos"}, "c.toml", cfg)
    with pytest.raises(ConfigError, match=r"\[scenario.path\] kind"):
        parse_scenario({"path": {"kind": "spiral"}}, "c.toml", cfg)
    with pytest.raises(ConfigError, match=r"\[scenario.path\] radius: unknown key for kind"):
        parse_scenario({"path": {"kind": "line", "radius": 3.0}}, "c.toml", cfg)
    with pytest.raises(ConfigError, match=r"\[scenario.path\].*radius"):
        parse_scenario({"path": {"kind": "circle", "radius": -3.0}}, "c.toml", cfg)
    c = parse_scenario({"path": {"kind": "circle", "radius": 40.0}}, "c.toml", cfg)
    assert ScenarioChoice.from_dict(json.loads(json.dumps(c.to_dict()))) == c


# ------------------------------------------------------------------ the one metrics function


def test_metrics_against_hand_computation():
    n, dt = 1000, 0.01
    t = np.arange(n) * dt
    e = np.sin(2 * np.pi * t)  # 10 whole periods, 100 samples each
    s = np.full(n, 0.3)
    sig = loops.Signals(
        eps=jnp.asarray(np.stack([s, e], axis=1)),
        pos=jnp.zeros((n, 3)),
        p_err=jnp.asarray(np.stack([s, e, np.full(n, 0.4)], axis=1)),
        u_err=jnp.asarray(-0.2 * np.ones(n)),
        psi_err=jnp.zeros(n),
        depth_err=jnp.asarray(np.full(n, 0.4)),
        cmd_ratio=jnp.zeros((n, 1)),
        sat=jnp.asarray(t < 2.5),
        act={"thrust": jnp.asarray(np.linspace(0.0, 7.0, n + 1))},
    )
    m = run_metrics(sig, jnp.ones(n, bool), dt, start=0.5, diverge_e=0.9)
    assert set(m) == set(metric_names(("thrust",))) | {"nonfinite", "diverged"}
    # mean |sin| over whole periods is 2/pi (100 samples: within 4e-4); integral over 10 s 20/pi
    assert float(m["ss_abs_e"]) == pytest.approx(2 / np.pi, rel=1e-3)
    assert float(m["iae_e"]) == pytest.approx(20 / np.pi, rel=1e-3)
    assert float(m["rms_cross_track_e"]) == pytest.approx(np.sqrt(0.5), rel=1e-4)
    assert float(m["ss_abs_s"]) == pytest.approx(0.3)
    assert float(m["ss_abs_u_err"]) == pytest.approx(0.2)
    # 3-D distance: sqrt(0.09 + sin^2 + 0.16); its RMS over whole periods is sqrt(0.75)
    assert float(m["rms_dist_3d"]) == pytest.approx(np.sqrt(0.25 + 0.5), rel=1e-4)
    assert float(m["max_dist_3d"]) == pytest.approx(np.sqrt(1.25), rel=1e-4)
    assert float(m["rms_depth_err"]) == pytest.approx(0.4)
    assert float(m["sat_fraction"]) == pytest.approx(0.25)
    assert float(m["max_abs_thrust"]) == 7.0
    assert bool(m["diverged"]) and not bool(m["nonfinite"])  # max |e| = 1 > 0.9
    # streamed in uneven segments (as a sweep folds its rollout), the same numbers
    sig = sig._replace(act={"thrust": sig.act["thrust"][:n]})  # n samples, as a rollout's
    m = run_metrics(sig, jnp.ones(n, bool), dt, start=0.5, diverge_e=0.9)
    k0 = window_start(n, 0.5)
    acc = metrics_init(("thrust",), sig.eps.dtype)
    for a, b in [(0, 1), (1, 333), (333, 500), (500, 501), (501, 1000)]:
        part = jax.tree_util.tree_map(lambda x, a=a, b=b: x[a:b], sig)
        acc = metrics_update(acc, part, jnp.ones(b - a, bool), jnp.arange(a, b), k0)
    streamed = metrics_finalize(acc, n, k0, dt, 0.9)
    for key in m:
        np.testing.assert_allclose(streamed[key], m[key], rtol=1e-13, err_msg=key)


# ------------------------------------------------------------------ our loop: sweep and tune


@pytest.mark.slow  # 9 s; the how-to and new-disturbance tests sweep and tune loops of their own
def test_a_loop_defined_here_is_swept_and_tuned_through_the_public_api(tmp_path):
    """The point mass above, never mentioned in the library, on a circle: a Monte-Carlo sweep
    (random starts, model error, disturbance forces) and a gradient tuning run of its engine
    gains that lowers the loss; then the same through TOML configs and the CLI."""
    choice = ScenarioChoice(vehicle="pointmass", controller="vcm")
    spec = SweepSpec(
        num_scenarios=6,
        variants=("vcm",),
        horizon=6.0,
        dt=0.02,
        chunk_size=6,
        record_points=20,
        choice=choice,
        scenario=ScenarioSpec(
            initial=(("x", (4.0, 7.0)), ("y", (-1.0, 1.0))),
            model_error=0.2,
            disturbance=((-1.0, 1.0), (-1.0, 1.0)),
        ),
    )
    res = run_sweep(spec, progress=False)
    m = res.metrics["vcm"]
    assert res.index.tolist() == list(range(6)) and not m["diverged"].any()
    assert np.all(m["max_abs_e"] > 0.05)  # started off the circle
    assert set(res.metrics["vcm"]) >= set(metric_names(("torque",)))
    # the model factors really perturbed the plant (and only the listed fields)
    assert res.spec.mc_config().model_fields == ("m", "b", "tau_max")
    assert np.ptp(res.scenarios["model_factors"][:, 0]) > 0
    plant, design, _ = nominal(spec)
    assert float(plant.m) == float(design.m) == 2.0

    loop = spec.loop("vcm")
    problem = TuningProblem(space=GainSpace(loop=loop), num_steps=150, timing="sampled")
    data = problem_data(problem, dt=0.02)
    train = tuning_batch(0, 3, loop=loop, position_offset=2.0, current_max=0.0)
    loss = lambda th, d, s: objective(th, d, s, problem)[0]
    r = run_gradient_tuner(
        loss, data.theta_ref, (data, train), optimizer="adam", steps=4, learning_rate=0.2
    )
    assert r.n_bad == 0 and r.loss < r.history[0]["loss"]


@pytest.mark.slow
def test_a_loop_defined_here_runs_from_toml_configs_through_the_cli(tmp_path):
    """The same loop through ``vcjax sweep`` and ``vcjax tune`` configs ([scenario] vehicle =
    "pointmass", a circle of 4 m): the gains file written loads back."""
    loop = loops.make_loop("pointmass", "vcm")
    (tmp_path / "s.toml").write_text(
        '[scenario]\nvehicle = "pointmass"\n[scenario.path]\nkind = "circle"\nradius = 4.0\n'
        "[sweep]\nnum_scenarios = 3\n[simulation]\nhorizon = 2.0\ndt = 0.05\n"
        "[initial]\nx = [3.0, 5.0]\n[output]\nfigures = false\n"
    )
    from vcjax import cli

    assert cli.main(["sweep", str(tmp_path / "s.toml"), "--out", str(tmp_path / "sw")]) == 0
    summary = json.loads((tmp_path / "sw" / "summary.json").read_text())
    assert summary["variants"]["vcm"]["n"] == 3
    (tmp_path / "t.toml").write_text(
        '[scenario]\nvehicle = "pointmass"\n[problem]\nhorizon = 2.0\ndt = 0.05\n'
        'timing = "sampled"\n[scenarios]\ncurrent_max = 0.0\n[train]\nsize = 2\n'
        '[heldout]\nsize = 2\n[optimizer]\nname = "adam"\nsteps = 2\n[report]\n'
        "plot_scenarios = 1\n"
    )
    assert cli.main(["tune", str(tmp_path / "t.toml"), "--out", str(tmp_path / "tu")]) == 0
    g = json.loads((tmp_path / "tu" / "gains.json").read_text())
    assert set(g) == {"P_G", "P_Phi", "sigma", "vehicle", "controller"}  # what they are for
    assert (g["vehicle"], g["controller"]) == ("pointmass", "vcm")
    loop.gains_from_json(g)  # the tuned gains load back
