"""Monte-Carlo sweeps: vmap vs loop, chunking, processes, Gauss–Markov statistics, noise,
health flags, config validation, results on disk, sharding over 4 simulated devices."""

import dataclasses
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import experiments, loops
from vcjax.config import ConfigError
from vcjax.environment import current as currents
from vcjax.metrics import metric_names
from vcjax.plots.sweep import sweep_figures
from vcjax.sweep import (
    FLAGS,
    METRICS,
    ScenarioSpec,
    SweepSpec,
    load_config,
    load_results,
    merge_results,
    nominal,
    perturb_params,
    run_batch,
    run_sweep,
    run_sweep_config,
    sample_scenarios,
    save_results,
)
from vcjax.vehicles import infante

try:  # the xarray extra (installed by the test extra; the rest of this file runs without it)
    import xarray  # noqa: F401

    HAVE_XARRAY = True
except ImportError:  # pragma: no cover
    HAVE_XARRAY = False

HORIZON, DT = 20.0, 0.1
SCEN = ScenarioSpec(
    current_speed=(0.0, 1.0),
    current_direction_deg=(0.0, 360.0),
    initial=(
        ("x", (-5.0, 5.0)),
        ("y", (-5.0, 5.0)),
        ("heading_deg", (60.0, 120.0)),
        ("speed", (1.5, 2.5)),
    ),
    model_error=0.1,
)
# The TOML twin of SPEC (test_config_end_to_end reuses the compiled batch).
TOML = """
[sweep]
num_scenarios = 3
seed = 7
variants = ["ilos"]
chunk_size = 3

[simulation]
horizon = 20.0
dt = 0.1
timing = "sampled"

[current]
speed = [0.0, 1.0]
direction_deg = [0.0, 360.0]

[initial]
x = [-5.0, 5.0]
y = [-5.0, 5.0]
heading_deg = [60.0, 120.0]
speed = [1.5, 2.5]

[model_error]
relative = 0.1

[output]
record_points = 50
"""


def make_spec(**kw):
    base = dict(
        num_scenarios=3,
        scenario=SCEN,
        variants=("ilos",),
        seed=7,
        horizon=HORIZON,
        dt=DT,
        timing="sampled",
        chunk_size=3,
        record_points=50,
    )
    return SweepSpec(**(base | kw))


def as_np(tree):
    return jax.tree_util.tree_map(np.asarray, jax.device_get(tree))


def assert_metrics_equal(a, b, rtol=1e-10):
    for k in (*METRICS, *FLAGS):
        np.testing.assert_allclose(a[k], b[k], rtol=rtol, atol=1e-12, err_msg=k)


# ----------------------------------------------------------------------------- vmap vs loop


def test_vmapped_sweep_equals_loop_of_single_rollouts():
    spec = make_spec()
    res = run_sweep(spec, progress=False)
    nominal = infante.infante_params()
    sim1 = experiments.get("sim1")
    m = res.metrics["ilos"]
    assert set(metric_names(("tau_u", "rudder_deg"))) | set(FLAGS) == set(m)
    assert res.index.tolist() == [0, 1, 2]
    assert np.ptp(res.scenarios["current_speed"]) > 0  # the scenarios really differ
    for i in range(3):
        sc = res.scenarios
        vehicle = perturb_params(
            nominal, spec.mc_config().model_fields, jnp.asarray(sc["model_factors"][i])
        )
        s1 = loops.make_scenario(
            sim1.loop("ilos"),
            eta0=sc["eta0"][i],
            nu0=sc["nu0"][i],
            current=sc["current"][i],
            u_d=float(sc["u_d"][i]),
            plant=vehicle,
            design=nominal,
        )
        setup = sim1.setup(horizon=HORIZON, dt=DT, timing="sampled")
        traj = sim1.simulate("ilos", setup, scenario=s1)
        ref = sim1.metrics(sim1.outcome("ilos", setup, traj, scenario=s1), setup)
        for k in ("ss_abs_e", "ss_abs_s", "ss_abs_u_err", "iae_e", "max_abs_tau_u"):
            np.testing.assert_allclose(m[k][i], ref[k], rtol=1e-9, err_msg=k)
        np.testing.assert_allclose(m["max_abs_rudder_deg"][i], ref["max_abs_rudder_deg"], rtol=1e-9)
        assert m["sat_fraction"][i] == pytest.approx(ref["sat_fraction"], rel=1e-12)
        assert not m["diverged"][i] and ref["healthy"]
        np.testing.assert_allclose(m["max_abs_e"][i], np.abs(traj.aux.eps[:, 1]).max(), rtol=1e-12)
        # recorded traces: every 4th step (200 steps, 50 points)
        np.testing.assert_allclose(res.traces["ilos"]["e"][i], traj.aux.eps[::4, 1], rtol=1e-5)


def test_scenarios_depend_only_on_seed_and_index():
    a = as_np(sample_scenarios(SCEN, 7, np.arange(5)))
    b = as_np(sample_scenarios(SCEN, 7, np.array([3, 4])))
    np.testing.assert_array_equal(a.eta0[3:], b.eta0)
    np.testing.assert_array_equal(a.key[3:], b.key)
    c = as_np(sample_scenarios(SCEN, 8, np.arange(5)))
    assert not np.array_equal(a.eta0, c.eta0)
    # ranges are respected; fixed values are exact
    speed = np.hypot(a.current[:, 0], a.current[:, 1])
    np.testing.assert_array_equal(a.current[:, 2], 0.0)
    np.testing.assert_allclose(speed, a.current_speed, rtol=1e-12)
    assert np.all((a.model_factors >= 0.9) & (a.model_factors <= 1.1))
    fixed = as_np(sample_scenarios(ScenarioSpec(), 0, np.arange(2)))
    np.testing.assert_allclose(fixed.eta0, [[0.0, 0.0, np.pi / 2]] * 2, rtol=0, atol=1e-15)
    np.testing.assert_allclose(fixed.current, [[0.0, 0.5, 0.0]] * 2, atol=1e-15)


# ------------------------------------------------------------------------ chunks, processes


def test_chunked_equals_unchunked_and_process_shares_merge():
    whole = run_sweep(make_spec(num_scenarios=7, chunk_size=7), progress=False)
    chunked = run_sweep(make_spec(num_scenarios=7, chunk_size=3), progress=False)  # 3 + 3 + 1
    assert chunked.index.tolist() == list(range(7))
    assert_metrics_equal(chunked.metrics["ilos"], whole.metrics["ilos"], rtol=1e-12)
    np.testing.assert_array_equal(chunked.scenarios["eta0"], whole.scenarios["eta0"])
    # two processes, each its share of the chunks (0, 2 and 1), merged
    spec = make_spec(num_scenarios=7, chunk_size=3)
    parts = [run_sweep(spec, progress=False, process_index=p, process_count=2) for p in (1, 0)]
    assert parts[0].index.tolist() == [3, 4, 5] and parts[1].index.tolist() == [0, 1, 2, 6]
    merged = merge_results(parts)
    assert merged.index.tolist() == list(range(7))
    assert_metrics_equal(merged.metrics["ilos"], chunked.metrics["ilos"], rtol=0)
    np.testing.assert_array_equal(merged.traces["ilos"]["e"], chunked.traces["ilos"]["e"])


# ------------------------------------------------------------------------ Gauss-Markov current


def test_gauss_markov_stationary_variance_and_correlation_time():
    sigma, tau, dt, steps = 0.2, 30.0, 1.5, 40  # lag 20 dt = tau, lag 40 dt = 2 tau
    p = currents.gauss_markov_current(mean=(0.3, -0.1), sigma=sigma, tau=tau, max_speed=10.0)
    keys = jax.random.split(jax.random.PRNGKey(0), 4000)
    V = jax.vmap(lambda k: currents.gm_sample_path(p, k, dt, steps, clip=False))(keys)
    d = np.asarray(V) - np.array([0.3, -0.1])  # (4000, 41, 2): 8000 samples per time
    d = np.concatenate([d[..., 0], d[..., 1]], axis=0)
    for k in (0, 20, 40):  # stationary from t = 0
        assert abs(d[:, k].std() / sigma - 1.0) < 0.05, k
        assert abs(d[:, k].mean()) < 0.02
    for lag in (1, 20, 40):
        rho = np.mean(d[:, 0] * d[:, lag]) / sigma**2
        assert abs(rho - np.exp(-lag * dt / tau)) < 0.04, lag


def test_gauss_markov_current_is_clipped_and_zero_sigma_is_constant():
    p = currents.gauss_markov_current(mean=(0.0, 0.9), sigma=0.5, tau=10.0, max_speed=1.0)
    V = np.asarray(currents.gm_sample_path(p, jax.random.PRNGKey(1), 0.5, 400))
    speed = np.hypot(V[:, 0], V[:, 1])
    assert speed.max() <= 1.0 + 1e-12 and (speed > 0.999).mean() > 0.1
    p0 = p._replace(sigma=jnp.asarray(0.0))
    V0 = np.asarray(currents.gm_sample_path(p0, jax.random.PRNGKey(1), 0.5, 10))
    np.testing.assert_array_equal(V0, np.tile([0.0, 0.9], (11, 1)))
    np.testing.assert_allclose(currents.current_vector(2.0, np.pi / 2), [0.0, 2.0], atol=1e-15)


# ------------------------------------------------------------- exogenous current and noise


def test_zero_noise_and_zero_sigma_equal_the_plain_loop_and_nonzero_ones_act():
    spec = make_spec()
    gains = loops.infante_gains()
    sc = sample_scenarios(spec.scenario, spec.seed, np.arange(3))
    plain = spec.mc_config()
    both = dataclasses.replace(plain, current_model="gauss_markov", sensor_noise=True)
    args = (spec.loop("ilos"), gains, nominal(spec))
    ref, ref_tr = as_np(run_batch(*args, sc, plain, DT, 50.0))
    zero = sc._replace(current_sigma=jnp.zeros(3), noise_std=jnp.zeros((3, 6)))
    got, got_tr = as_np(run_batch(*args, zero, both, DT, 50.0))
    assert_metrics_equal(got, ref, rtol=1e-9)
    np.testing.assert_allclose(got_tr["e"], ref_tr["e"], rtol=1e-6, atol=1e-9)
    # noise only / current fluctuation only: different, still healthy
    noisy = zero._replace(noise_std=jnp.tile(jnp.array([0.5, 0.5, 0.02, 0.05, 0.05, 0.01]), (3, 1)))
    m_noise, _ = as_np(run_batch(*args, noisy, both, DT, 50.0))
    gm = zero._replace(current_sigma=jnp.full(3, 0.3, float), current_tau=jnp.full(3, 5.0, float))
    m_gm, _ = as_np(run_batch(*args, gm, both, DT, 50.0))
    for m in (m_noise, m_gm):
        assert not m["diverged"].any()
        assert np.all(np.abs(m["iae_e"] - ref["iae_e"]) > 1e-6 * ref["iae_e"])


# ----------------------------------------------------------------------------- health flags


def test_health_flags_catch_divergence_without_leaking_nans():
    spec = make_spec()
    args = (spec.loop("ilos"), loops.infante_gains(), nominal(spec))
    cfg = spec.mc_config()
    sc = sample_scenarios(spec.scenario, spec.seed, np.arange(3))
    ref, _ = as_np(run_batch(*args, sc, cfg, DT, 50.0))
    # scenario 1: a plant with zero mass and inertia (singular M: non-finite at once)
    bad = sc._replace(model_factors=sc.model_factors.at[1, :2].set(0.0))
    bad = bad._replace(model_factors=bad.model_factors.at[1, 2:7].set(0.0))
    m, tr = as_np(run_batch(*args, bad, cfg, DT, 50.0))
    assert m["nonfinite"].tolist() == [False, True, False]
    assert m["diverged"].tolist() == [False, True, False]
    for k in METRICS:
        np.testing.assert_allclose(m[k][[0, 2]], ref[k][[0, 2]], rtol=1e-12, err_msg=k)
        assert np.all(np.isfinite(m[k][[0, 2]]))
    # a finite run that leaves the corridor counts as diverged (threshold is traced)
    m_tight, _ = as_np(run_batch(*args, sc, cfg, DT, 1e-3))
    assert m_tight["diverged"].all() and not m_tight["nonfinite"].any()


# ------------------------------------------------------------------ config, files, figures


def write(tmp_path, text, name="c.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


@pytest.mark.parametrize(
    "text, match",
    [
        ("[sweep]\nnum_scenarios = 4\n[bogus]\na = 1\n", r"unknown section \[bogus\]"),
        ("[sweep]\nnum_scenarios = 4\nnum_scenario = 3\n", r"\[sweep\] num_scenario: unknown key"),
        ("[sweep]\nseed = 1\n", r"num_scenarios is required"),
        ("[sweep]\nnum_scenarios = -4\n", r"\[sweep\] num_scenarios: expected an integer >= 1"),
        ("[sweep]\nnum_scenarios = 4.0\n", r"\[sweep\] num_scenarios: expected an integer"),
        ("[sweep]\nnum_scenarios = 4\nchunk_size = 0\n", r"\[sweep\] chunk_size"),
        (
            "[sweep]\nnum_scenarios = 4\nvariants = ['pid']\n",
            r"\[sweep\] variants: expected one of",
        ),
        (
            "[sweep]\nnum_scenarios = 4\n[simulation]\ndt = 'fast'\n",
            r"\[simulation\] dt: expected a finite number",
        ),
        (
            "[sweep]\nnum_scenarios = 4\n[current]\nspeed = [1.0, 0.5]\n",
            r"\[current\] speed: expected finite lo <= hi",
        ),
        (
            "[sweep]\nnum_scenarios = 4\n[current]\nspeed = -1.0\n",
            r"\[current\] speed: values must be >= 0",
        ),
        (
            "[sweep]\nnum_scenarios = 4\n[current]\nmodel = 'tidal'\n",
            r"\[current\] model: expected one of",
        ),
        (
            "[sweep]\nnum_scenarios = 4\n[model_error]\nrelative = 1.5\n",
            r"\[model_error\] relative",
        ),
        (
            "[sweep]\nnum_scenarios = 4\n[model_error]\nfields = ['mass', 'wings']\n",
            r"\[model_error\] fields: unknown",
        ),
        (
            "[sweep]\nnum_scenarios = 4\n[sensor_noise]\nposition_std = -0.1\n",
            r"\[sensor_noise\] position_std",
        ),
        ("[sweep]\nnum_scenarios = 4\n[output]\nfigures = 'yes'\n", r"\[output\] figures"),
        ("[sweep]\nnum_scenarios = 4\n[simulation]\ngains = 'missing.json'\n", r"no such file"),
        ("[sweep]\nnum_scenarios = \n", r"not valid TOML"),
    ],
)
def test_config_validation_errors(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        load_config(write(tmp_path, text))


def test_example_configs_are_valid():
    root = Path(__file__).parents[1] / "examples" / "sweeps"
    files = sorted(root.glob("*.toml"))
    assert len(files) >= 2
    for f in files:
        spec, extras = load_config(f)
        assert spec.num_scenarios >= 1 and extras["figures"] in (True, False)


def test_config_end_to_end_writes_results_summary_and_figures(tmp_path):
    path = write(tmp_path, TOML)
    spec, _ = load_config(path)
    assert spec == make_spec()
    lines = []
    out = run_sweep_config(
        path, tmp_path / "out", progress=lines.append, netcdf=HAVE_XARRAY, draw=sweep_figures
    )
    assert len(lines) == 1 and "1/1" in lines[0]
    names = {p.name for p in out["files"]}
    assert {"results.npz", "summary.json", "sweep_envelopes.png", "sweep_paths.png"} <= names
    assert all(p.is_file() and p.stat().st_size > 0 for p in out["files"])
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    entry = summary["variants"]["ilos"]
    assert entry["n"] == 3 and entry["n_diverged"] == 0
    assert set(entry["metrics"]) == set(metric_names(("tau_u", "rudder_deg")))
    assert set(entry["metrics"]["ss_abs_e"]) == {"mean", "std", "p5", "p50", "p95", "min", "max"}
    res = load_results(tmp_path / "out" / "results.npz")
    assert res.spec == spec
    vals = res.metrics["ilos"]["iae_e"]
    assert entry["metrics"]["iae_e"]["mean"] == pytest.approx(vals.mean(), rel=1e-12)
    assert entry["metrics"]["iae_e"]["p95"] == pytest.approx(np.percentile(vals, 95), rel=1e-12)
    # save/load round trip
    again = load_results(save_results(res, tmp_path / "again.npz"))
    assert_metrics_equal(again.metrics["ilos"], res.metrics["ilos"], rtol=0)
    np.testing.assert_array_equal(again.scenarios["model_factors"], res.scenarios["model_factors"])
    if HAVE_XARRAY:
        _check_xarray(res, tmp_path / "out" / "results.nc")


def _check_xarray(res, nc_path):
    """to_xarray labels every number with its variant, scenario and units; results.nc holds the
    same dataset. A second variant (the first one's metrics doubled) makes the variant axis
    real: each value must come back under its own label."""
    import xarray as xr

    two = dataclasses.replace(
        res,
        metrics={**res.metrics, "twice": {k: 2 * v for k, v in res.metrics["ilos"].items()}},
        traces={**res.traces, "twice": res.traces["ilos"]},
    )
    ds = two.to_xarray()
    assert ds.sizes["variant"] == 2 and ds.sizes["scenario"] == 3
    assert list(ds["scenario"].values) == res.index.tolist()
    for pos, i in enumerate(res.index):
        for v, factor in (("ilos", 1.0), ("twice", 2.0)):
            got = float(ds["iae_e"].sel(variant=v, scenario=i))
            assert got == factor * res.metrics["ilos"]["iae_e"][pos]
        assert float(ds["current_speed"].sel(scenario=i)) == res.scenarios["current_speed"][pos]
        # (the sampled current's components are labelled north/east/down)
        north = float(ds["current"].sel(scenario=i, current_component="north"))
        assert north == res.scenarios["current"][pos][0]
    fields = list(ds["model_field"].values)
    assert fields == list(res.spec.scenario.fields_for(res.spec.loop("ilos")))
    k = fields.index("mass")
    np.testing.assert_array_equal(
        ds["model_factors"].sel(model_field="mass").values, res.scenarios["model_factors"][:, k]
    )
    assert ds["iae_e"].attrs["units"] == "m s" and ds["ss_abs_u_err"].attrs["units"] == "m/s"
    assert ds["max_abs_rudder_deg"].attrs["units"] == "deg" and ds["diverged"].dtype == bool
    np.testing.assert_array_equal(ds["time"].values, res.trace_t)
    np.testing.assert_array_equal(ds["trace_e"].sel(variant="ilos").values, res.traces["ilos"]["e"])
    assert json.loads(ds.attrs["spec_json"])["seed"] == 7
    # results.nc, written by `vcjax sweep --netcdf`
    with xr.open_dataset(nc_path, engine="scipy") as nc:
        nc = nc.load()
    assert list(nc["variant"].values) == ["ilos"]
    np.testing.assert_array_equal(
        nc["iae_e"].sel(variant="ilos").values, res.metrics["ilos"]["iae_e"]
    )
    np.testing.assert_array_equal(nc["diverged"].values[0], res.metrics["ilos"]["diverged"])
    assert nc["ss_abs_e"].attrs["units"] == "m"


# -------------------------------------------------------------------------- 4 CPU devices

SHARDED = """
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
from vcjax.sweep import ScenarioSpec, SweepSpec, run_sweep
assert jax.device_count() == 4, jax.devices()
spec = SweepSpec(
    num_scenarios=10, variants=("ilos",), seed=3, horizon=10.0, dt=0.1, chunk_size=6,
    timing="sampled",
    scenario=ScenarioSpec(current_speed=(0.0, 1.0), current_direction_deg=(0, 360),
                          initial=(("x", (-5, 5)),), model_error=0.1,
                          noise=(("position_std", 0.2),)),
)
sharded = run_sweep(spec, progress=False)  # chunks of 8 over 4 devices, last one padded
single = run_sweep(spec, progress=False, devices=jax.devices()[:1])
assert sharded.devices == 4 and single.devices == 1
assert sharded.index.tolist() == list(range(10))
for k, a in sharded.metrics["ilos"].items():
    np.testing.assert_allclose(a, single.metrics["ilos"][k], rtol=1e-10, atol=1e-12, err_msg=k)
np.testing.assert_allclose(sharded.traces["ilos"]["e"], single.traces["ilos"]["e"], rtol=1e-6)
# sea states drawn per scenario key: the same bits sharded over 4 devices as on one
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from vcjax.environment import waves
keys = jax.random.split(jax.random.PRNGKey(11), 8)
def draw(k, hs):
    sea = waves.sea_state(k, hs, 8.0, 0.3, spreading=2.0, components=16)
    return sea, waves.orbital_velocity(sea, 30.0, jax.numpy.array([5.0, -3.0, 4.0]))
draws = jax.jit(jax.vmap(draw))
hs = jax.numpy.linspace(0.5, 3.0, 8)
mesh = Mesh(np.array(jax.devices()), ("d",))
on4 = jax.device_put((keys, hs), NamedSharding(mesh, PartitionSpec("d")))
on1 = jax.device_put((keys, hs), jax.devices()[0])
a, b = draws(*on4), draws(*on1)
assert len(a[1].sharding.device_set) == 4 and len(b[1].sharding.device_set) == 1
for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
    np.testing.assert_array_equal(np.asarray(x), np.asarray(y))
print("SHARDED_OK")
"""


@pytest.mark.slow  # 11 s; test_devices' two-device case stays default
def test_sharded_over_four_cpu_devices_equals_single_device():
    env = dict(os.environ)
    env["XLA_FLAGS"] = (
        env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=4"
    ).strip()
    env["JAX_PLATFORMS"] = "cpu"
    root = Path(__file__).parents[1]
    r = subprocess.run(
        [sys.executable, "-c", SHARDED],
        env=env,
        cwd=root,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert "SHARDED_OK" in r.stdout


def test_variants_without_a_paper_style_get_a_full_line_style():
    """Variants of other loops (e.g. remus100's vcm3d_ilos) are not in plots.STYLE: the fallback
    style carries every key the figures read (the REMUS sweep died on a missing 'ls')."""
    from vcjax.plots import STYLE
    from vcjax.plots import sweep as sweep_plots

    keys = set().union(*(set(s) for s in STYLE.values()))
    for v in ("vcm3d_ilos", "alos3d", "decoupled"):
        assert v not in STYLE
        assert keys <= set(sweep_plots._style(v))
