"""The environment seam (vcjax.environment): section checks, sampling, the built-in components
against the physics modules they wrap, the registry, the Environment pytree, and the run of
each component through loops.simulate against the older route (Disturbances, Scenario.sea,
Scenario.disturbance) it replaces: the same numbers, bit for bit."""

import dataclasses
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import environment, loops
from vcjax.config.scenario import import_module_file
from vcjax.environment import (
    ConstantCurrent,
    ConstantForce,
    Environment,
    GaussMarkov,
    GaussMarkovParams,
    Key,
    SeaParams,
    SensorNoise,
    Waves,
    check_section,
    current,
    waves,
)
from vcjax.rollout import RolloutConfig

import_module_file(Path(__file__).resolve().parents[1] / "examples" / "loops" / "puck.py")

SCHEMA = {
    "speed": Key(0.5, "m/s", lo=0.0),
    "tau": Key(10.0, "s", lo=0.0, strict_lo=True),
    "kind": Key("a", "", choices=("a", "b")),
}


# ------------------------------------------------------------------ sections and draws


def test_a_section_takes_defaults_numbers_and_ranges():
    assert check_section("x", SCHEMA, None) == {"speed": 0.5, "tau": 10.0, "kind": "a"}
    got = check_section("x", SCHEMA, {"speed": [0.1, 0.2], "tau": 3, "kind": "b"})
    assert got == {"speed": (0.1, 0.2), "tau": 3.0, "kind": "b"}


@pytest.mark.parametrize(
    "raw, msg",
    [
        ({"sped": 1.0}, r"^\[x\] sped: unknown key \(did you mean 'speed'\?\); expected one of"),
        ({"zzz": 1.0}, r"^\[x\] zzz: unknown key; expected one of \['speed', 'tau', 'kind'\]$"),
        ({"speed": -1.0}, r"^\[x\] speed: values must be >= 0.0, got \[-1.0, -1.0\]$"),
        ({"tau": 0.0}, r"^\[x\] tau: values must be > 0, got \[0.0, 0.0\]$"),
        ({"speed": "fast"}, r"^\[x\] speed: expected a number or \[lo, hi\], got 'fast'$"),
        ({"speed": True}, r"^\[x\] speed: expected a number or \[lo, hi\], got True"),
        ({"speed": float("nan")}, r"^\[x\] speed: expected finite lo <= hi, got \[nan, nan\]"),
        ({"speed": [0.3, 0.1]}, r"^\[x\] speed: expected finite lo <= hi, got \[0.3, 0.1\]$"),
        ({"speed": [0.1, 0.2, 0.3]}, r"^\[x\] speed: expected a number or a list \[lo, hi\]"),
        ({"kind": "c"}, r"^\[x\] kind: expected one of \['a', 'b'\], got 'c'$"),
    ],
)
def test_a_bad_section_is_one_line_naming_section_and_key(raw, msg):
    with pytest.raises(ValueError, match=msg):
        check_section("x", SCHEMA, raw)


def test_a_required_key_and_a_section_that_is_not_a_table():
    with pytest.raises(ValueError, match=r"^\[waves\] hs: required \(a number or \[lo, hi\]\)$"):
        Waves().check({"tp": 8.0})
    with pytest.raises(ValueError, match=r"^\[current\]: expected a table"):
        environment.freeze("current", 3.0)
    with pytest.raises(ValueError, match=r"^\[waves\] components: expected an integer"):
        Waves().check({"hs": 1.0, "tp": 8.0, "components": 2.5})
    with pytest.raises(ValueError, match=r"^\[nope\]: no such component; known: "):
        environment.lookup("nope")


def test_a_frozen_section_is_hashable_and_freezes_again_to_itself():
    f = environment.freeze("current", {"speed": [0.0, 1.0]})
    assert f[0] == "current" and dict(f[1]) == {
        "model": "constant",
        "speed": (0.0, 1.0),
        "direction_deg": 90.0,
        "sigma": 0.05,
        "tau": 300.0,
        "max_speed": 2.0,
    }
    assert hash(f) and environment.freeze(*f) == f


def test_a_range_draw_is_uniform_and_differentiable_in_both_ends():
    keys = jax.random.split(jax.random.PRNGKey(0), 4000)
    x = np.asarray(jax.vmap(lambda k: environment.draw(k, (1.0, 3.0)))(keys))
    assert x.min() >= 1.0 and x.max() <= 3.0 and abs(x.mean() - 2.0) < 0.05
    k = jax.random.PRNGKey(5)
    u = float(jax.random.uniform(k, (), jnp.float64))
    g = jax.grad(lambda lo, hi: environment.draw(k, (lo, hi)), argnums=(0, 1))(1.0, 3.0)
    np.testing.assert_allclose(g, (1 - u, u), rtol=1e-12)
    assert float(environment.draw(k, 2.5)) == 2.5


# ------------------------------------------------------------------ the built-in components


def test_the_constant_current_is_current_ned_of_its_speed_and_direction():
    p = ConstantCurrent().sample(jax.random.PRNGKey(0), ConstantCurrent().check({"speed": 0.5}))
    np.testing.assert_allclose(p.velocity, [0.0, 0.5, 0.0], atol=1e-15)  # towards east
    v, a = ConstantCurrent().water(p, None, 3.0, jnp.ones(3), None)
    np.testing.assert_array_equal(v, p.velocity)
    np.testing.assert_array_equal(a, np.zeros(3))


def test_the_gauss_markov_component_is_the_sampled_path_of_vcjax_environment_current():
    gm = current.gauss_markov_current(mean=(0.3, -0.1), sigma=0.2, tau=5.0, max_speed=0.4)
    key = jax.random.PRNGKey(3)
    params = GaussMarkovParams(gm, jnp.asarray([0.05]), key)
    dt, n = 0.5, 12
    want = np.asarray(current.gm_sample_path(gm, key, dt, n))
    c, d = GaussMarkov(), GaussMarkov().init(params)
    got = []
    for k in range(n):
        d, (V, dV, t_k) = c.advance(params, d, k, k * dt, jnp.asarray(dt))
        got.append(V)
        # linear between the samples, its rate the slope; the vertical part constant
        v, a = c.water(params, (V, dV, t_k), t_k + dt, None, None)
        np.testing.assert_allclose(v[:2], want[k + 1], atol=1e-14)
        assert float(v[2]) == 0.05 and float(a[2]) == 0.0
    np.testing.assert_allclose(np.asarray(got)[:, :2], want[:n], atol=1e-15)


def test_a_gauss_markov_section_is_sampled_around_its_mean():
    c = GaussMarkov()
    p = c.sample(jax.random.PRNGKey(0), c.check({"speed": 0.5, "direction_deg": 0.0}))
    np.testing.assert_allclose(p.current.mean, [0.5, 0.0], atol=1e-15)
    assert float(p.current.sigma) == 0.05 and float(p.current.tau) == 300.0


def test_the_waves_component_is_a_sea_state_felt_at_the_origin_depth():
    c = Waves()
    sec = c.check({"hs": 2.0, "tp": 9.0, "direction_deg": 45.0, "origin_depth": 3.0})
    key = jax.random.PRNGKey(7)
    p = c.sample(key, sec)
    _, k_sea = jax.random.split(key)
    want = waves.sea_state(k_sea, 2.0, 9.0, np.pi / 4, components=64, dtype=jnp.float64)
    for a, b in zip(p.sea, want, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-14)
    assert float(p.origin_depth) == 3.0
    pos, cur = jnp.asarray([1.0, 2.0, 0.5]), jnp.asarray([0.1, 0.0, 0.0])
    u, a = c.water(p, None, 4.0, pos, cur)
    u0, a0 = waves.orbital_kinematics(want, 4.0, pos.at[2].add(3.0), cur)
    np.testing.assert_allclose(u, u0, rtol=1e-14)
    np.testing.assert_allclose(a, a0, rtol=1e-14)


def test_sensor_noise_binds_to_the_loops_channels_in_si_units():
    loop = loops.make_loop("infante", "vcm")
    c = environment.lookup("sensor_noise").bind(loop)
    assert c.channels == tuple(loop.noise_channels.items())
    raw = {k: 1.0 for k in loop.noise_channels}
    p = c.sample(jax.random.PRNGKey(0), c.check(raw))
    want = loop.noise_std({k: np.radians(1.0) if k.endswith("_deg") else 1.0 for k in raw})
    np.testing.assert_allclose(p.std, want, rtol=1e-15)
    _, n = c.advance(p, None, 4, 0.0, 0.1)
    draw = jax.random.normal(jax.random.fold_in(p.key, 4), p.std.shape, p.std.dtype)
    np.testing.assert_array_equal(c.noise(p, n), p.std * draw)
    with pytest.raises(ValueError, match=r"\[sensor_noise\] bogus: unknown key"):
        c.check({"bogus": 1.0})


def test_the_force_binds_to_the_generalised_velocity_size():
    assert environment.lookup("force").bind(loops.make_loop("puck", "vcm")).size == 2
    odin = loops.make_loop("odin", "vcm")
    c = environment.lookup("force").bind(odin)
    assert c.size == 6 and set(c.schema) == {f"tau_{i}" for i in range(6)}
    p = c.sample(jax.random.PRNGKey(0), c.check({"tau_0": 5.0, "tau_5": [1.0, 1.0]}))
    np.testing.assert_array_equal(c.force(p), [5.0, 0, 0, 0, 0, 1.0])
    # through environment.sample (the sweep's and the tuner's route): checked for the loop, not
    # against the unbound 3-force default (a KeyError 'tau_3' before)
    env = environment.sample(jax.random.PRNGKey(0), {"force": {"tau_0": 5.0, "tau_5": 1.0}}, odin)
    np.testing.assert_array_equal(env.params[0].tau, [5.0, 0, 0, 0, 0, 1.0])


def test_a_force_section_is_read_before_its_vehicle_and_checked_against_it(tmp_path, capsys):
    from vcjax import cli
    from vcjax.sweep.config import load_config

    # ODIN has six generalised coordinates: tau_4 in a sweep file is read (it was refused as an
    # unknown key against a three-force default) and keeps only what was written
    odin_cfg = tmp_path / "odin.toml"
    odin_cfg.write_text(
        '[scenario]\nvehicle = "odin"\n[sweep]\nnum_scenarios = 2\nvariants = ["vcm"]\n'
        "[simulation]\nhorizon = 1.0\ndt = 0.05\n[force]\ntau_0 = [0.0, 1.0]\ntau_4 = 2.0\n"
    )
    spec, _ = load_config(odin_cfg)
    assert spec.scenario.environment == (("force", (("tau_0", (0.0, 1.0)), ("tau_4", 2.0))),)
    odin = loops.make_loop("odin", "vcm")
    spec.scenario.check_for(odin)
    env = environment.sample(jax.random.PRNGKey(3), dict(spec.scenario.environment), odin)
    tau = np.asarray(env.params[0].tau)
    assert 0.0 <= tau[0] <= 1.0 and tau[4] == 2.0 and not tau[[1, 2, 3, 5]].any()
    # the puck has two: a tau_2 is refused naming the key and the vehicle, before --out exists
    # (a puck [force] section failed at sampling before: its unbound check filled in tau_2 = 0)
    module = Path(__file__).resolve().parents[1] / "examples" / "loops" / "puck.py"
    head = f'[scenario]\nmodule = "{module.as_posix()}"\nvehicle = "puck"\n'
    runs = {  # the sweep's route and the tuner's
        "sweep": "[sweep]\nnum_scenarios = 2\n[simulation]\nhorizon = 0.5\ndt = 0.01\n",
        "tune": "[simulation]\nhorizon = 1.0\ndt = 0.01\n[train]\nsize = 2\n[heldout]\nsize = 2\n",
    }
    for command, body in runs.items():
        cfg = tmp_path / f"{command}.toml"
        cfg.write_text(head + body + "[force]\ntau_2 = 0.1\n")
        rc = cli.main([command, str(cfg), "--out", str(tmp_path / f"out_{command}")])
        err = capsys.readouterr().err
        assert rc != 0 and "[force] tau_2: unknown key" in err and "'puck'" in err, err
        assert "Traceback" not in err and not (tmp_path / f"out_{command}").exists()
    with pytest.raises(ValueError, match=r"tau_2: unknown key.*'puck'"):
        load_config(tmp_path / "sweep.toml")  # the Python route refuses it too
    with pytest.raises(ValueError, match="sample it for a loop"):
        ConstantForce().sample(jax.random.PRNGKey(0), {"tau_0": 1.0})
    assert ConstantForce().check({"tau_5": 1.0}) == {"tau_5": 1.0}  # nothing filled in unbound


# ------------------------------------------------------------------ registry and pytree


def test_the_registry_refuses_what_is_not_a_complete_component():
    assert set(environment.components()) >= {
        "current",
        "gauss_markov",
        "waves",
        "sensor_noise",
        "force",
    }
    with pytest.raises(ValueError, match="expected a Component"):
        environment.register(object())

    @dataclasses.dataclass(frozen=True)
    class NoKind(environment.Component):
        section = "no_kind"

    @dataclasses.dataclass(frozen=True)
    class NoSample(environment.Component):
        section = "no_sample"
        kind = "force"

    with pytest.raises(ValueError, match="needs a section and a kind"):
        environment.register(NoKind())
    with pytest.raises(ValueError, match="defines no sample"):
        environment.register(NoSample())
    with pytest.raises(ValueError, match=r"section \[force\] is taken"):
        environment.register(ConstantForce(size=4))
    environment.register(Waves())  # the same component again: fine


def test_an_environment_is_a_pytree_whose_components_are_static():
    sections = {"current": {"speed": [0.0, 1.0]}, "force": {"tau_0": [-1.0, 1.0]}}
    puck = loops.make_loop("puck", "vcm")
    keys = jax.random.split(jax.random.PRNGKey(0), 5)
    batch = jax.vmap(lambda k: environment.sample(k, sections, puck))(keys)
    assert [c.section for c in batch.components] == ["current", "force"]
    assert batch.params[0].velocity.shape == (5, 3) and batch.params[1].tau.shape == (5, 2)
    assert len(set(np.asarray(batch.params[0].velocity[:, 1]).round(12))) == 5
    leaves, tree = jax.tree_util.tree_flatten(batch)
    assert len(leaves) == 2 and jax.tree_util.tree_unflatten(tree, leaves).kinds() == (
        "current",
        "force",
    )
    both = batch + Environment()
    assert len(both) == 2 and "current" in repr(both)
    with pytest.raises(ValueError, match="one params entry per component"):
        Environment((Waves(),), ())


# ------------------------------------------------------------------ through loops.simulate


def _run(loop, sc, **kw):
    cfg = RolloutConfig(num_steps=60)
    traj = loops.simulate(loop, loop.default_gains(), sc, cfg, 0.05, **kw)
    return jax.tree_util.tree_leaves(traj.x)


def _same(a, b):
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


def test_a_gauss_markov_component_gives_the_disturbances_run_bit_for_bit():
    loop = loops.make_loop("infante", "vcm")
    sc = loops.make_scenario(loop, current=(0.0, 0.4, 0.0))
    key = jax.random.PRNGKey(2)
    gm = loops.gauss_markov_params(sc, jnp.asarray(0.2), jnp.asarray(4.0), jnp.asarray(2.0))
    dist = loops.Disturbances(gauss_markov=True)
    old = _run(loop, sc, dist=dist, dist_params=loops.DisturbanceParams(gm, jnp.zeros(0), key))
    k_cur, _ = jax.random.split(key)
    env = Environment((GaussMarkov(),), (GaussMarkovParams(gm, sc.current[2:], k_cur),))
    new = _run(loop, sc._replace(current=jnp.zeros(3), environment=env))
    _same(old, new)
    calm = _run(loop, sc)
    assert not np.allclose(np.asarray(old[0]), np.asarray(calm[0]))


@pytest.mark.slow  # 9 s; the calm-sea suite stays default
def test_a_waves_component_gives_the_scenario_sea_run_bit_for_bit():
    loop = loops.make_loop("remus100", "vcm3d")
    sea = waves.sea_state(jax.random.PRNGKey(4), 1.5, 7.0, 0.3, components=16)
    sc = loops.make_scenario(loop, current=(0.1, 0.2, 0.0))
    old = _run(loop, sc._replace(sea=sea, origin_depth=jnp.asarray(2.0)))
    env = Environment((Waves(),), (SeaParams(sea, jnp.asarray(2.0)),))
    _same(old, _run(loop, sc._replace(environment=env)))


def test_noise_and_force_components_give_the_older_route_bit_for_bit():
    loop = loops.make_loop("puck", "vcm")
    sc = loops.make_scenario(loop, initial={"x": 0.7})
    tau = jnp.asarray([0.3, -0.2])
    force = environment.lookup("force").bind(loop)
    env = Environment((force,), (environment.ForceParams(tau),))
    _same(_run(loop, sc._replace(disturbance=tau)), _run(loop, sc._replace(environment=env)))

    infante = loops.make_loop("infante", "vcm")
    sc = loops.make_scenario(infante)
    std = jnp.asarray(infante.noise_std({k: 0.1 for k in infante.noise_channels}))
    key = jax.random.PRNGKey(9)
    dp = loops.DisturbanceParams(None, std, key)
    old = _run(infante, sc, dist=loops.Disturbances(sensor_noise=True), dist_params=dp)
    _, k_noise = jax.random.split(key)
    noise = SensorNoise().bind(infante)
    env = Environment((noise,), (environment.NoiseParams(std, k_noise),))
    _same(old, _run(infante, sc._replace(environment=env)))


def test_a_component_the_loop_cannot_feel_is_refused_before_any_work():
    sea = Environment((Waves(),), (SeaParams(waves.calm_sea(4), jnp.asarray(0.0)),))
    for vehicle in ("infante", "arm", "puck"):
        loop = loops.make_loop(vehicle, loops.loop_class(vehicle).default_controller)
        with pytest.raises(ValueError, match=rf"^waves: the {vehicle} loop cannot take waves: "):
            loops.make_scenario(loop, environment=sea)
    arm = loops.make_loop("arm", loops.loop_class("arm").default_controller)
    with pytest.raises(ValueError, match="^current: the arm loop cannot take a current: an arm"):
        loops.check_environment(arm, [ConstantCurrent()])
    with pytest.raises(ValueError, match="^environment: expected a vcjax.environment"):
        loops.make_scenario(arm, environment={"waves": {}})
    assert not loops.loop_class("puck").can_feel("noise")
    assert "no noise_channels" in loops.loop_class("puck").refusal("noise")
    assert loops.loop_class("infante").can_feel("noise")


def test_a_key_that_does_not_apply_is_refused_when_written_even_at_its_default():
    """``gamma`` with the PM spectrum and a Gauss-Markov key with a constant current are
    refused whenever a table writes them (their default included), while a frozen table,
    whose defaults were filled in by the check, checks again as itself."""
    for section, table, key in (
        ("waves", {"spectrum": "pm", "hs": 1.0, "tp": 8.0, "gamma": 3.3}, "gamma"),
        ("current", {"sigma": 0.05}, "sigma"),
    ):
        with pytest.raises(ValueError, match=rf"\[{section}\] {key}: "):
            environment.freeze(section, table)
        table = {k: v for k, v in table.items() if k != key}
        f = environment.freeze(section, table)
        assert dict(f[1])[key] is not None and environment.freeze(*f) == f


def test_a_strict_lower_bound_above_zero_holds_for_numbers_and_ranges():
    """``strict_lo`` at a bound other than 0 (a user's component): the bound itself is
    refused, for a number and for either end of a range."""
    schema = {"ratio": Key(2.0, "", lo=1.0, strict_lo=True)}
    assert check_section("x", schema, {"ratio": [1.5, 3.0]}) == {"ratio": (1.5, 3.0)}
    for bad in (1.0, [1.0, 2.0], 0.5):
        with pytest.raises(ValueError, match=r"^\[x\] ratio: values must be "):
            check_section("x", schema, {"ratio": bad})
