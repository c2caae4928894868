"""Waves reach the loops (issue 23): the seam between :mod:`vcjax.environment.waves` and the closed loops
(:attr:`vcjax.loops.Scenario.sea`, :meth:`vcjax.loops.Loop.plant_in_sea`), the ``[waves]``
section of sweep and tune configs, the recorded wave columns, ``vcjax simulate --waves`` and the
refusals of loops whose plant cannot feel a sea.

Cheap by design: the plumbing (sweeps, tuning, gradients) on a loop defined here, a drifter (the
puck of ``examples/loops/puck.py`` whose drag sees the water's orbital motion: a loop of your own
that takes waves through the public API, compiled in seconds); ODIN-class's and REMUS 100's own
seams on a few steps or one plant evaluation; the rest in the slow tests.
"""

import dataclasses
import json
from pathlib import Path
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import loops, sweep
from vcjax.cli import main
from vcjax.config import ConfigError
from vcjax.config.scenario import ScenarioChoice, import_module_file
from vcjax.environment import WaterMotion, waves
from vcjax.linalg import Rzyx
from vcjax.plots.sweep import sweep_figures
from vcjax.rollout import RolloutConfig, rollout
from vcjax.vehicles import odin, remus100

ROOT = Path(__file__).resolve().parents[1]
KEY = jax.random.PRNGKey(7)
#: one jitted rollout shared by the tests (same loop, config and shapes: compiled once each)
_run = jax.jit(loops.simulate, static_argnames=("loop", "config", "dist"))
CFG = RolloutConfig(num_steps=20, timing="sampled")
DT = 0.1


import_module_file(ROOT / "examples" / "loops" / "puck.py")


@dataclasses.dataclass(frozen=True)
class DrifterLoop(loops.loop_class("puck")):
    """The puck as a drag-only body at depth ``origin_depth``: its drag sees the velocity
    relative to the water, the current plus the sea's orbital velocity at the puck (the
    horizontal part: the puck moves in a plane). No added mass or Froude–Krylov force: a loop
    for the plumbing, not a vehicle."""

    vehicle: ClassVar[str] = "test_wave_drifter"
    feels: ClassVar[dict] = {**loops.loop_class("puck").feels, "waves": True}

    def plant_in_sea(self, t, x, u, args, water):
        return self.plant(
            t, x, u, args._replace(water=water.at(t, self.position(x[0], args.params)))
        )


loops.register(DrifterLoop, replace=True)


def _drifter():
    return loops.make_loop("test_wave_drifter", "vcm")


def _sea(hs=1.5, tp=7.0, direction=0.4, spreading=0.0, components=24):
    return waves.sea_state(KEY, hs, tp, direction, spreading=spreading, components=components)


def _odin(polish=5):
    return loops.OdinLoop(controller="vcm", path=loops.OdinLoop.default_path()[0], polish=polish)


def _odin_scenario(loop, sea=None, depth=0.0, current=(0.1, -0.05, 0.0)):
    # the paper's start (z = -102, "as printed") put 4 m below the surface by origin_depth
    return loops.make_scenario(loop, current=current, sea=sea, origin_depth=106.0 + depth)


def _same(a, b):
    return all(
        np.array_equal(np.asarray(x), np.asarray(y), equal_nan=True)
        for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True)
    )


# ------------------------------------------------------------------------------------ the seam


@pytest.mark.slow  # 10 s; the REMUS 100 calm-sea cases stay default
def test_the_odin_loop_in_a_sea_is_the_plant_fed_the_water_and_a_calm_sea_changes_no_bit():
    """The rollout of ``loops.simulate`` with a sea against a rollout written here from the
    plant and :mod:`vcjax.environment.waves` directly: the water (current + orbital motion) evaluated at the
    vehicle's NED position shifted by ``origin_depth``, at each integrator stage's own time,
    through the plant's current door, plus the Froude–Krylov correction on the disturbance."""
    loop = _odin()
    sea = _sea()
    sc = _odin_scenario(loop, sea)
    gains = loop.default_gains()
    cfg, dt = CFG, DT
    got = _run(loop, gains, sc, cfg, dt)

    def plant(t, x, u, p):
        pos = x.eta[:3] + jnp.asarray([0.0, 0.0, 106.0])
        v_w, a_w = waves.water_kinematics(sea, t, pos, sc.current)
        b = p.body
        fk = waves.froude_krylov(Rzyx(*x.eta[3:]), a_w, b.B / b.W * b.M_RB[0, 0], b.r_bb)
        body = fk - b.M_RB[:, :3] @ (Rzyx(*x.eta[3:]).T @ a_w)
        args = odin.OdinArgs(p, sc.disturbance + body, WaterMotion(v_w, a_w))
        return odin.odin_plant(t, x, u, args)

    x0, z0 = loop.initial_state(sc)
    want = jax.jit(rollout, static_argnames=("plant", "controller", "config"))(
        plant, loop.control, cfg, sc.plant, loop.ctrl_params(gains, sc), x0, z0, dt
    )
    np.testing.assert_allclose(np.asarray(got.x.eta), np.asarray(want.x.eta), rtol=0, atol=1e-12)

    # hs = 0: every kinematic quantity is exactly 0, so the run in a calm sea (this program,
    # other data) equals the run without a sea (another program) to the bit, current included;
    # the sea above moved the vehicle by decimetres
    plain = _run(loop, gains, sc._replace(sea=None, origin_depth=None), cfg, dt)
    calm = _run(loop, gains, sc._replace(sea=_sea(hs=0.0)), cfg, dt)
    assert _same(plain, calm)
    assert np.max(np.abs(np.asarray(got.x.eta[:, :3] - plain.x.eta[:, :3]))) > 0.05


_REMUS = loops.make_loop("remus100", "vcm3d_ilos")


@jax.jit
def _remus_fields(x, u, t, sea, cur, sc):
    """``(loop's plant_in_sea, the plant given the whole water as its (3,) current)``."""
    args = _REMUS.plant_args(sc._replace(current=cur), cur, jnp.zeros(3))
    got = _REMUS.plant_in_sea(t, x, u, args, loops.Water.of_sea(sea, 2.0, cur, None))
    p = args.vehicle
    v_w, a_w = water = waves.water_kinematics(sea, t, x.eta[:3] + jnp.asarray([0, 0, 2.0]), cur)
    still = WaterMotion(jnp.zeros(3), jnp.zeros(3))  # no uniform share: the full rotation for all
    dx = remus100.remus100_plant(t, x, u, remus100.Remus100Args(p, water, uniform=still))
    b = p.body
    R = Rzyx(*x.eta[3:])
    corr = waves.current_door_correction(R, a_w, b.M_RB, b.M_RB[0, 0], b.r_bb)
    return got, dx._replace(nu=dx.nu + jnp.linalg.solve(remus100.mass_matrix(p), corr))


def test_remus100_in_a_sea_is_its_plant_with_the_water_as_its_3d_current():
    """REMUS 100 keeps PVS's yaw-only door for the current and takes the waves through the full
    rotation on top of it. Level (roll = pitch = 0, not rolling or pitching) the two doors
    agree, so the loop's plant in a sea must equal the plant given the whole water (current +
    orbital) as its (3,) current with the pendulum correction solved separately — the
    formulation ``tests/test_waves.py`` checks against particles. Tilted and rolling, without
    a current, likewise."""
    sea = _sea(hs=2.5, tp=6.0, direction=1.1)
    rng = np.random.default_rng(3)
    u = jnp.asarray([0.1, -0.1, 1200.0])
    sc = loops.make_scenario(_REMUS)
    for current, tilted in (((0.0, 0.0, 0.0), True), ((0.3, -0.2, 0.0), False)):
        att = rng.uniform(-0.3, 0.3, 3) if tilted else np.array([0.0, 0.0, 0.7])
        eta = jnp.asarray(np.concatenate([[3.0, -2.0, 4.0], att]))
        nu = rng.normal(0.0, 0.3, 6) + np.array([1.5, 0, 0, 0, 0, 0])
        if not tilted:  # PVS's door also drops the roll/pitch-rate term of nu_c_dot
            nu[3:5] = 0.0
        x = remus100.Remus100State(eta, jnp.asarray(nu), jnp.asarray([0.05, -0.03, 1000.0]))
        got, want = _remus_fields(x, u, 3.7, sea, jnp.asarray(current), sc)
        np.testing.assert_allclose(got.nu, want.nu, rtol=1e-11, atol=1e-12)
        np.testing.assert_array_equal(got.eta, want.eta)


@pytest.mark.slow
def test_a_calm_sea_is_bit_identical_with_gauss_markov_current_and_noise():
    """REMUS 100 (its own current door, a Gauss–Markov current through the exogenous hook) and
    ODIN-class with sensor noise: a calm sea changes no bit of ODIN-class's run. REMUS 100's
    (every added term exactly 0) is bit-identical under XLA's default CPU code generator; under
    the faster-compiling one the command line and the tests use (:mod:`vcjax.runtime.compiler`) a
    ``+ 0`` in the sea's program can stop LLVM from contracting ``a b + c`` into one fused
    multiply-add, so a few entries differ in the last bit or two: equal to 4 ulp of each
    signal's scale, no more."""
    cases = []
    loop = loops.make_loop("remus100", "vcm3d_ilos")
    sc = loops.make_scenario(loop, current=(0.2, -0.3, 0.0), initial={"pitch_deg": 8.0})
    gm = loops.gauss_markov_params(sc, 0.05, 30.0, 1.0)
    cases.append((loop, sc, loops.Disturbances(gauss_markov=True), gm, jnp.zeros(0), 2.0))
    loop = _odin()
    sc = _odin_scenario(loop)
    cases.append((loop, sc, loops.Disturbances(sensor_noise=True), None, jnp.full(12, 0.01), 0))
    for loop, sc, dist, gm, noise, depth in cases:
        dp = loops.DisturbanceParams(gm, noise, jax.random.PRNGKey(1))
        a = _run(loop, loop.default_gains(), sc, CFG, DT, dist, dp)
        calm = sc._replace(sea=_sea(hs=0.0), origin_depth=jnp.asarray(106.0 + depth))
        b = _run(loop, loop.default_gains(), calm, CFG, DT, dist, dp)
        if loop.vehicle != "remus100":
            assert _same(a, b)
            continue
        for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
            x, y = np.asarray(x), np.asarray(y)
            if x.dtype == bool:
                np.testing.assert_array_equal(x, y)
            else:
                scale = float(np.max(np.abs(x))) if x.size else 0.0
                np.testing.assert_allclose(y, x, rtol=0, atol=4 * np.finfo(x.dtype).eps * scale)


def _value_and_derivative(loss, mode):
    """One jitted program ``(k, sc) -> (loss, d loss / d k)`` (forward or reverse mode)."""
    if mode == "forward":
        return jax.jit(lambda k, sc: jax.jvp(lambda k_: loss(k_, sc), (k,), (jnp.ones_like(k),)))
    return jax.jit(jax.value_and_grad(loss))


def _check_gradient(vd, k, sc):
    """The derivative against central differences of the value (the same program)."""
    h = 1e-4
    fd = (vd(k + h, sc)[0] - vd(k - h, sc)[0]) / (2 * h)
    grad = vd(k, sc)[1]
    assert abs(float(grad)) > 1e-6
    np.testing.assert_allclose(float(grad), float(fd), rtol=1e-5)


def test_gradient_with_respect_to_a_gain_through_a_sea_matches_finite_differences():
    """d(loss)/d(P_G) of the drifter through a rollout in a sea, reverse mode against central
    differences (float64); the drifter's path error depends on the sea (checked)."""
    loop = _drifter()
    sc = loops.make_scenario(loop, current=(0.05, 0.0, 0.0), sea=_sea(hs=2.0, tp=5.0))
    g0 = loop.default_gains()
    cfg = RolloutConfig(num_steps=40)

    def loss(kp, sc):
        traj = loops.simulate(loop, g0._replace(P_G=g0.P_G.at[0].set(kp)), sc, cfg, 0.02)
        return jnp.mean(jnp.sum(loop.signals(traj, sc).eps ** 2, axis=1))

    vd = _value_and_derivative(loss, "reverse")
    _check_gradient(vd, g0.P_G[0], sc)
    calm = sc._replace(sea=_sea(hs=0.0))
    assert abs(float(vd(g0.P_G[0], sc)[0]) - float(vd(g0.P_G[0], calm)[0])) > 1e-6


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["forward", "reverse"])
def test_gradient_through_the_odin_loop_in_a_sea_matches_finite_differences(mode):
    """d(loss)/d(depth PID gain) through ODIN-class in a sea, both modes (float64)."""
    loop = _odin(polish=2)
    sc = _odin_scenario(loop, _sea(hs=2.0, tp=6.0, components=16), depth=-3.0)
    g0 = loop.default_gains()
    cfg = RolloutConfig(num_steps=12, timing="sampled")

    def loss(kp, sc):
        traj = loops.simulate(loop, g0._replace(depth=g0.depth.at[0].set(kp)), sc, cfg, DT)
        sig = loop.signals(traj, sc)
        return jnp.mean(sig.depth_err**2) + jnp.mean(jnp.sum(sig.p_err**2, axis=1))

    _check_gradient(_value_and_derivative(loss, mode), g0.depth[0], sc)


# --------------------------------------------------------------------------------- refusals


def test_loops_that_cannot_take_waves_refuse_them_with_a_reason():
    for vehicle, ctrl in (("infante", "vcm_integral"), ("arm", "vcm")):
        loop = loops.make_loop(vehicle, ctrl)
        with pytest.raises(ValueError, match=rf"^waves: the {vehicle} loop cannot take waves: "):
            loops.make_scenario(loop, sea=_sea())
        sc = loops.make_scenario(loop, current=(0.0, 0.0, 0.0))._replace(sea=_sea())
        with pytest.raises(ValueError, match="cannot take waves"):
            loops.simulate(loop, loop.default_gains(), sc, RolloutConfig(num_steps=2), 0.1)
        with pytest.raises(ValueError, match=r"waves: .* cannot take waves"):
            loops.check_disturbances(type(loop), False, False, waves=True)
    loops.check_disturbances(loops.Remus100Loop, False, False, waves=True)
    loops.check_disturbances(loops.OdinLoop, False, False, waves=True)


def _sweep_toml(tmp_path, vehicle="odin", waves_table=None, extra=""):
    f = tmp_path / "s.toml"
    text = f'[scenario]\nvehicle = "{vehicle}"\n[sweep]\nnum_scenarios = 3\nchunk_size = 2\n'
    text += '[simulation]\nhorizon = 0.5\ndt = 0.1\ntiming = "sampled"\n'
    text += "[current]\nspeed = 0.0\n" + extra
    if waves_table is not None:
        text += "[waves]\n" + waves_table
    f.write_text(text)
    return f


def test_sweep_and_tune_configs_with_waves_for_a_loop_without_them_are_refused(tmp_path):
    f = _sweep_toml(tmp_path, "infante", "hs = 1.0\ntp = 8.0\n")
    with pytest.raises(ConfigError, match=r"s.toml: \[waves\] the infante loop cannot take waves"):
        sweep.load_config(f)
    from tuning.config import validate_config

    with pytest.raises(ConfigError, match=r"\[waves\] the arm loop cannot take waves"):
        validate_config({"scenario": {"vehicle": "arm"}, "waves": {"hs": 1.0, "tp": 8.0}})


@pytest.mark.parametrize(
    "table, match",
    [
        ("tp = 8.0\n", r"\[waves\] hs: required \(a number or \[lo, hi\]\)"),
        ("hs = 1.0\n", r"\[waves\] tp: required"),
        ("hs = -1.0\ntp = 8.0\n", r"\[waves\] hs: values must be >= 0"),
        ("hs = 1.0\ntp = [0.0, 8.0]\n", r"\[waves\] tp: values must be > 0"),
        ("hs = 1.0\ntp = 3.0\n", r"\[waves\] tp: the shortest wave period .* tp >= 4 s"),
        ("hs = 1.0\ntp = 8.0\nspectrum = 'swell'\n", r"\[waves\] spectrum: expected one of"),
        ("hs = 1.0\ntp = 8.0\ngamma = 0.5\n", r"\[waves\] gamma: expected a value >= 1"),
        ("hs = 1.0\ntp = 8.0\ncomponents = 0\n", r"\[waves\] components"),
        ("hs = 1.0\ntp = 8.0\nheight = 2.0\n", r"\[waves\] height: unknown key"),
        ("hs = [2.0, 1.0]\ntp = 8.0\n", r"\[waves\] hs: expected finite lo <= hi"),
    ],
)
def test_waves_parse_errors_name_the_key(tmp_path, table, match):
    with pytest.raises(ConfigError, match=match):
        sweep.load_config(_sweep_toml(tmp_path, "odin", table))


def test_tune_waves_parse_errors_name_the_key():
    from tuning.config import validate_config

    base = {"scenario": {"vehicle": "odin"}, "problem": {"dt": 0.1}}
    with pytest.raises(ConfigError, match=r"\[waves\] tp: required"):
        validate_config({**base, "waves": {"hs": 1.0}})
    with pytest.raises(ConfigError, match=r"\[waves\] tp: the shortest wave period"):
        validate_config({**base, "waves": {"hs": 1.0, "tp": 2.0}})
    cfg = validate_config({**base, "waves": {"hs": [0.0, 2.0], "tp": 8.0}})
    assert cfg["waves"]["hs"] == [0.0, 2.0] and cfg["waves"]["components"] == 64


def test_the_cli_refuses_waves_with_exit_2_and_one_line(tmp_path, capsys):
    f = _sweep_toml(tmp_path, "infante", "hs = 1.0\ntp = 8.0\n")
    assert main(["sweep", str(f), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "[waves] the infante loop cannot take waves" in err
    out = str(tmp_path / "sim")
    assert main(["simulate", "sim1", "--waves", "1", "8", "0", "--out", out]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--waves does not apply to sim1" in err
    for argv, msg in (
        (["--waves", "1", "1", "0"], "TP must be >= 40 dt"),
        (["--waves", "-1", "8", "0"], "HS must be >= 0"),
        (["--waves", "1", "nan", "0"], "contains NaN"),
        (["--wave-seed", "3"], "--wave-seed needs --waves"),
        (["--waves", "1", "8", "0", "--wave-seed", "-1"], "outside the PRNG's seed range"),
    ):
        assert main(["simulate", "remus100", *argv, "--out", out]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and msg in err, err


# ------------------------------------------------------------------------ sweeps and tuning


def _spec(**kw):
    base = dict(
        wave_spectrum="jonswap",
        wave_hs=(0.5, 3.0),
        wave_tp=(5.0, 12.0),
        wave_direction_deg=(0.0, 360.0),
        wave_origin_depth=(2.0, 10.0),
        wave_components=16,
    )
    return sweep.ScenarioSpec(current_speed=(0.0, 0.0), **(base | kw))


def test_each_scenario_draws_its_sea_from_its_own_key_whatever_the_chunk():
    loop = _drifter()
    spec = _spec()
    all8 = sweep.sample_scenarios(spec, 5, np.arange(8), loop=loop)
    part = sweep.sample_scenarios(spec, 5, [6], loop=loop)  # a chunk of one: scenario 6
    for f in ("wave_hs", "wave_tp", "wave_direction_deg", "wave_origin_depth"):
        assert _same(getattr(all8, f)[6:7], getattr(part, f))
    # the sea's transcendental functions (the spectrum) may round differently with the batch's
    # vector width: equal to round-off
    for a, b in zip(all8.sea, part.sea, strict=True):
        np.testing.assert_allclose(np.asarray(b), np.asarray(a)[6:7], rtol=1e-14, atol=1e-300)
    hs = np.asarray(all8.wave_hs)
    assert np.all((hs >= 0.5) & (hs <= 3.0)) and np.unique(hs).size == 8
    # the sea is sea_state of the drawn parameters (and of the scenario's own key)
    assert np.all(np.asarray(all8.sea.amplitude).max(axis=1) > 0)
    # without waves nothing else changes: the other draws are those of a spec without [waves]
    plain = sweep.sample_scenarios(
        sweep.ScenarioSpec(current_speed=(0.0, 0.0)), 5, np.arange(8), loop=loop
    )
    assert plain.sea is None and plain.wave_hs is None
    assert _same(plain.eta0, all8.eta0) and _same(plain.key, all8.key)


def _sweep_spec(scenario, chunk_size=3):
    return sweep.SweepSpec(
        scenario=scenario,
        num_scenarios=3,
        variants=("vcm",),
        horizon=1.0,
        dt=0.02,
        chunk_size=chunk_size,
        record_points=5,
        choice=ScenarioChoice(vehicle="test_wave_drifter"),
    )


def test_a_sweep_with_waves_records_the_wave_columns(tmp_path):
    spec = _sweep_spec(_spec(wave_tp=(1.0, 3.0)))
    r = sweep.run_sweep(spec, progress=False)
    for k in ("wave_hs", "wave_tp", "wave_direction_deg", "wave_origin_depth"):
        assert r.scenarios[k].shape == (3,) and np.all(np.isfinite(r.scenarios[k]))
    assert np.all((r.scenarios["wave_tp"] >= 1.0) & (r.scenarios["wave_tp"] <= 3.0))
    assert not np.any(r.metrics["vcm"]["diverged"])
    back = sweep.load_results(sweep.save_results(r, tmp_path / "r.npz"))
    assert back.spec == r.spec
    np.testing.assert_array_equal(back.scenarios["wave_hs"], r.scenarios["wave_hs"])
    table = sweep.summarize(r)["waves"]
    assert sum(map(sum, table["variants"]["vcm"]["count"])) == 3
    assert len(table["hs_edges"]) == 4 and len(table["origin_depth_edges"]) == 4
    files = [f.name for f in sweep_figures(r, tmp_path)]
    assert "sweep_error_vs_waves.png" in files
    try:
        ds = r.to_xarray()
    except ImportError:
        return
    assert ds["wave_hs"].attrs["units"] == "m" and ds["wave_direction_deg"].attrs["units"] == "deg"


def _clearance_by_hand(sea, origin_depth, t, pos):
    """NumPy: ``origin_depth + z + sum_i a_i cos(k_i (n cos b_i + e sin b_i) - w_i t + phi_i)``."""
    a, k, w, phi, b = (np.asarray(x, np.float64) for x in (
        sea.amplitude, sea.wavenumber, sea.omega, sea.phase, sea.direction))  # fmt: skip
    n, e, z = (np.asarray(pos, np.float64)[:, j, None] for j in range(3))
    theta = k * (n * np.cos(b) + e * np.sin(b)) - w * np.asarray(t, np.float64)[:, None] + phi
    return float(origin_depth) + z[:, 0] + np.sum(a * np.cos(theta), axis=1)


def test_a_sweep_in_a_sea_reports_the_runs_above_the_surface(tmp_path, capsys):
    """0.3 m below the mean surface in Hs 3 m seas the drifter is above the local surface for
    part of its runs: the command warns and counts them; each run's fraction of steps above the
    surface and least clearance (streamed with the metrics) agree with the sea summed by hand
    along the run."""
    from vcjax.sweep import run as sweep_run

    cfg_file = tmp_path / "broach.toml"
    cfg_file.write_text(
        '[scenario]\nvehicle = "test_wave_drifter"\n[sweep]\nnum_scenarios = 3\n'
        'variants = ["vcm"]\n[simulation]\nhorizon = 1.0\ndt = 0.02\n[current]\nspeed = 0.0\n'
        "[waves]\nhs = 3.0\ntp = 4.0\ncomponents = 16\norigin_depth = 0.3\n"
    )
    assert main(["sweep", str(cfg_file), "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "vcjax: warning: sweep: vcm: in " in err and "above the local sea surface" in err
    r = sweep.load_results(tmp_path / "o" / "results.npz")
    m, spec = r.metrics["vcm"], r.spec
    got = json.loads((tmp_path / "o" / "summary.json").read_text())["variants"]["vcm"]
    assert got["n_above_surface"] == int(np.sum(m["above_surface_fraction"] > 0)) >= 1
    assert np.any(m["above_surface_fraction"] < 1)
    loop = spec.loop("vcm")
    scs = sweep.sample_scenarios(spec.scenario, spec.seed, np.arange(3), loop=loop)
    nom, cfg = sweep_run.nominal(spec), spec.mc_config()
    one = jax.jit(
        lambda nom, sc: sweep_run.simulate_scenario(
            loop, loop.default_gains(), nom, sc, cfg, spec.dt
        )
    )
    for i in range(3):
        traj, s = one(nom, jax.tree_util.tree_map(lambda x, i=i: x[i], scs))
        pos = loop.signals(traj, s).pos
        c = _clearance_by_hand(s.sea, s.origin_depth, traj.t[: pos.shape[0]], pos)
        assert float(m["above_surface_fraction"][i]) == pytest.approx(np.mean(c < 0), abs=1e-12)
        assert float(m["min_surface_clearance"][i]) == pytest.approx(c.min(), rel=1e-9, abs=1e-9)


def test_a_calm_sea_is_bit_identical_through_the_sweep():
    """The same scenarios (chunks of 2: one padded) with a calm sea and without one: every
    metric and trace equal to the bit; the calm sweep records its (zero) wave heights."""
    calm = _spec(wave_hs=(0.0, 0.0), wave_tp=(1.0, 3.0))
    none = sweep.ScenarioSpec(current_speed=(0.0, 0.0))
    r_calm = sweep.run_sweep(_sweep_spec(calm, 2), progress=False)
    r_none = sweep.run_sweep(_sweep_spec(none, 2), progress=False)
    surface = {k: r_calm.metrics["vcm"].pop(k) for k in sweep.run.SURFACE_METRICS}
    assert _same(r_calm.metrics, r_none.metrics) and _same(r_calm.traces, r_none.traces)
    # a calm sea's surface is the mean surface: the drifter stays origin_depth below it
    np.testing.assert_array_equal(surface["above_surface_fraction"], 0.0)
    np.testing.assert_allclose(
        surface["min_surface_clearance"], r_calm.scenarios["wave_origin_depth"]
    )
    for k in ("wave_hs", "wave_tp", "wave_direction_deg", "wave_origin_depth"):
        assert r_calm.scenarios[k].shape == (3,) and k not in r_none.scenarios
    np.testing.assert_array_equal(r_calm.scenarios["wave_hs"], 0.0)


def _tuning_batches():
    from tuning.scenarios import sample_scenarios

    loop = _drifter()
    kw = dict(loop=loop, current_max=0.2, position_offset=0.1, heading_offset=0.1)
    plain = sample_scenarios(3, 2, **kw)
    extra = dict(wave_spectrum="pm", wave_hs=(0.0, 0.0), wave_tp=(1.0, 1.0), wave_components=8)
    calm = sample_scenarios(3, 2, **kw, extra=extra | dict(wave_origin_depth=(1.0, 2.0)))
    return loop, plain, calm


def test_tuning_batches_carry_their_seas():
    from tuning.scenarios import SCENARIO_AXES, scenario_at

    loop, plain, calm = _tuning_batches()
    assert plain.sea is None and plain.origin_depth is None
    assert calm.sea.amplitude.shape == (2, 8) and calm.origin_depth.shape == (2,)
    for f in loops.Scenario._fields[:9]:
        assert _same(getattr(plain, f), getattr(calm, f))
    one = scenario_at(calm, 1)
    assert one.sea.omega.shape == (8,) and SCENARIO_AXES.sea == 0


def test_a_calm_sea_is_bit_identical_through_the_tuning_loss():
    from tuning.loss import TuningProblem, problem_data, scenario_losses
    from tuning.params import GainSpace

    loop, plain, calm = _tuning_batches()
    problem = TuningProblem(space=GainSpace(loop=loop, tune=("P_G",)), num_steps=20)
    data = problem_data(problem, dt=0.02)
    f = jax.jit(scenario_losses, static_argnames=("problem",))
    assert _same(f(data.theta_ref, data, plain, problem), f(data.theta_ref, data, calm, problem))


def test_the_tuning_evaluation_reports_the_runs_above_the_surface():
    """The held-out evaluation's problem (``surface=True``) adds each scenario's fraction of
    steps above the local surface and its least clearance, as the sea summed by hand along the
    run gives them; a training problem (the default) adds nothing."""
    from tuning.loss import TuningProblem, problem_data, scenario_losses
    from tuning.params import GainSpace
    from tuning.scenarios import sample_scenarios, scenario_at

    loop = _drifter()
    extra = dict(wave_spectrum="jonswap", wave_hs=(3.0, 3.0), wave_tp=(4.0, 4.0))
    batch = sample_scenarios(
        3, 2, loop=loop, current_max=0.0, position_offset=0.1, heading_offset=0.1,
        extra=extra | dict(wave_components=16, wave_origin_depth=(0.3, 0.3)),
    )  # fmt: skip
    surface = TuningProblem(space=GainSpace(loop=loop, tune=("P_G",)), num_steps=50, surface=True)
    assert not TuningProblem(space=surface.space).surface  # training: no surface terms
    data = problem_data(surface, dt=0.02)
    _, terms = jax.jit(scenario_losses, static_argnames=("problem",))(
        data.theta_ref, data, batch, surface
    )
    rolled, gains = surface.loop, surface.space.decode(data.theta_ref, data.base)
    run = jax.jit(lambda sc: loops.simulate(rolled, gains, sc, surface.rollout_config(), 0.02))
    for i in range(3):
        sc = scenario_at(batch, i)
        traj = run(sc)
        pos = rolled.signals(traj, sc).pos
        c = _clearance_by_hand(sc.sea, sc.origin_depth, traj.t[: pos.shape[0]], pos)
        assert float(terms["above_surface_fraction"][i]) == pytest.approx(np.mean(c < 0), abs=1e-12)
        assert float(terms["min_surface_clearance"][i]) == pytest.approx(
            c.min(), rel=1e-9, abs=1e-9
        )
    assert np.any(np.asarray(terms["above_surface_fraction"]) > 0)


# ------------------------------------------------------------------------ vcjax simulate --waves


def test_the_experiments_whose_loops_take_waves_take_the_option():
    import dataclasses

    from vcjax import experiments

    takes = {
        n
        for n, e in experiments.EXPERIMENTS.items()
        if "waves" in {f.name for f in dataclasses.fields(e.options)}
    }
    assert takes == {"remus100", "sim2"}
    remus100, sim2 = experiments.get("remus100"), experiments.get("sim2")
    a = remus100.scenario("vcm3d", remus100.setup(waves=(2.0, 8.0, 90.0), wave_seed=3))
    b = waves.sea_state(jax.random.PRNGKey(3), 2.0, 8.0, np.pi / 2)
    assert _same(a.sea, b) and float(a.origin_depth) == 0.0
    sc = sim2.scenario("full", sim2.setup(waves=(1.0, 6.0, 0.0)))
    assert float(sc.origin_depth) == 107.0 and sc.sea.amplitude.shape == (64,)
    c = waves.sea_state(jax.random.PRNGKey(0), 1.0, 6.0, 0.0)  # --wave-seed: default 0
    assert _same(sc.sea, c)


@pytest.mark.slow
def test_simulate_sim2_with_waves_records_the_sea(tmp_path):
    out = tmp_path / "sim2"
    argv = ["simulate", "sim2", "--waves", "1.5", "6", "30", "--wave-seed", "4"]
    assert main([*argv, "--horizon", "1.0", "--out", str(out)]) in (0, 1)
    m = json.loads((out / "metrics.json").read_text())
    assert m["waves"] == {
        "hs": 1.5,
        "tp": 6.0,
        "direction_deg": 30.0,
        "seed": 4,
        "spectrum": "jonswap",
        "gamma": 3.3,
        "components": 64,
        "origin_depth": 107.0,
    }
    run = json.loads((out / "run.json").read_text())
    assert run["config"]["waves"] == [1.5, 6.0, 30.0] and run["config"]["wave_seed"] == 4
