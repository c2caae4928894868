"""A new disturbance is one class plus one registration line: a tidal current that turns
sinusoidally in time, defined entirely in this file, registered with
:func:`vcjax.environment.register`, then simulated (against the analytic response of a drag-only
body), differentiated, swept through ``vcjax sweep`` with its own ``[tide]`` section in a TOML
file, and tuned, through the public API and from a TOML file with its own ``[tide]``."""

import dataclasses
import json
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tuning.loss import TuningProblem, objective, problem_data
from tuning.optim import run_gradient_tuner
from tuning.params import GainSpace
from tuning.scenarios import sample_scenarios as tuning_batch
from vcjax import environment, loops
from vcjax.cli import main
from vcjax.config.scenario import import_module_file
from vcjax.environment import Key, draw
from vcjax.rollout import RolloutConfig
from vcjax.sweep import load_config, run_sweep

ROOT = Path(__file__).resolve().parents[1]
PUCK = ROOT / "examples" / "loops" / "puck.py"
import_module_file(PUCK)  # the planar drag-only puck of the own-system guide

# ------------------------------------------------------------------ the new disturbance


class TidalParams(NamedTuple):
    speed: Any  # () [m/s]
    omega: Any  # () turning rate [rad/s]
    phase: Any  # () direction at t = 0 [rad, towards, clockwise from north]


@dataclasses.dataclass(frozen=True)
class Tidal(environment.Component):
    """A uniform horizontal current of constant speed whose direction turns at ``2 pi /
    period``: ``v = speed [cos(phi), sin(phi), 0]``, ``phi = phase + omega t``."""

    section = "tide"
    kind = "varying_current"
    schema = {
        "speed": Key(0.3, "speed [m/s]", lo=0.0),
        "period": Key(600.0, "period of one turn [s]", lo=0.0, strict_lo=True),
        "direction_deg": Key(0.0, "direction at t = 0 [deg from north]"),
    }

    def sample(self, key, section):
        k1, k2, k3 = jax.random.split(key, 3)
        omega = 2 * jnp.pi / draw(k2, section["period"])
        return TidalParams(
            draw(k1, section["speed"]), omega, jnp.deg2rad(draw(k3, section["direction_deg"]))
        )

    def water(self, params, held, t, p_ned, current):
        phi = params.phase + params.omega * t
        c, s = jnp.cos(phi), jnp.sin(phi)
        v = params.speed * jnp.stack([c, s, jnp.zeros_like(c)])
        a = params.speed * params.omega * jnp.stack([-s, c, jnp.zeros_like(c)])
        return v, a


environment.register(Tidal())  # the one registration line

# ------------------------------------------------------------------ through the public API

SECTION = {"speed": 0.4, "period": 20.0, "direction_deg": 30.0}


def _tidal_env(section=SECTION, loop=None, seed=0):
    return environment.sample(jax.random.PRNGKey(seed), {"tide": section}, loop)


def test_the_new_disturbance_is_listed_and_its_section_checked():
    assert "tide" in environment.components()
    assert environment.lookup("tide") == Tidal()
    with pytest.raises(ValueError, match=r"\[tide\] sped: unknown key \(did you mean 'speed'\?\)"):
        environment.freeze("tide", {"sped": 1.0})
    with pytest.raises(ValueError, match=r"\[tide\] period: values must be > 0, got \[0.0, 0.0\]"):
        environment.freeze("tide", {"period": 0.0})

    @dataclasses.dataclass(frozen=True)
    class Other(Tidal):
        pass

    with pytest.raises(ValueError, match=r"section \[tide\] is taken"):
        environment.register(Other())


def test_a_loop_that_cannot_feel_it_refuses_it_by_name_before_any_work():
    env = _tidal_env()
    for vehicle, why in (("arm", "an arm in air feels no water"), ("odin", "no door for it")):
        loop = loops.make_loop(vehicle, loops.loop_class(vehicle).default_controller)
        with pytest.raises(ValueError, match=rf"^tide: the {vehicle} loop cannot take a time-"):
            loops.make_scenario(loop, environment=env)
        with pytest.raises(ValueError, match=why):
            loops.check_environment(loop, env)


def _drifting_puck():
    """The puck with its thrusters off: ``m v' = -b (v - V_c(t))``, started at rest."""
    loop = loops.make_loop("puck", "vcm")
    plant = loop.default_params()._replace(tau_max=jnp.zeros(2))
    return loop, plant


def test_a_drifting_body_follows_the_analytic_response_to_the_turning_current():
    loop, plant = _drifting_puck()
    sc = loops.make_scenario(loop, initial={"x": 0.6}, plant=plant, environment=_tidal_env())
    dt, n = 0.02, 500
    traj = loops.simulate(loop, loop.default_gains(), sc, RolloutConfig(num_steps=n), dt)
    v = np.asarray(traj.x[1])[: n + 1]
    # independent: w = vx + i vy solves w' = -k (w - U e^{i(phi0 + omega t)}), w(0) = 0
    k = float(plant.b / plant.m)
    U, om, phi0 = 0.4, 2 * np.pi / 20.0, np.deg2rad(30.0)
    t = dt * np.arange(n + 1)
    w = k * U * np.exp(1j * phi0) / (k + 1j * om) * (np.exp(1j * om * t) - np.exp(-k * t))
    np.testing.assert_allclose(v[:, 0] + 1j * v[:, 1], w, atol=1e-9)
    # the current really turned: the velocity points a quarter turn on after 5 s
    assert abs(np.angle(w[250] / w[-1])) > 1.0


def test_the_response_differentiates_through_the_sampled_parameters():
    loop, plant = _drifting_puck()
    cfg = RolloutConfig(num_steps=50)
    sc = loops.make_scenario(loop, initial={"x": 0.6}, plant=plant)
    env = _tidal_env(SECTION, loop)

    def final_y(speed):
        e = environment.Environment(env.components, (env.params[0]._replace(speed=speed),))
        return loops.simulate(loop, loop.default_gains(), sc._replace(environment=e), cfg, 0.02).x[
            0
        ][-1, 1]

    value_and_grad = jax.jit(jax.value_and_grad(final_y))  # one compilation for all three
    _, g = value_and_grad(jnp.asarray(0.4))
    h = 1e-6
    fd = (value_and_grad(jnp.asarray(0.4 + h))[0] - value_and_grad(jnp.asarray(0.4 - h))[0]) / (
        2 * h
    )
    assert abs(float(g)) > 1e-3 and float(g) == pytest.approx(float(fd), rel=1e-6)


def _toml(tmp_path, tidal: str) -> Path:
    f = tmp_path / "tidal.toml"
    f.write_text(
        f"""
[scenario]
vehicle = "puck"
module = "{PUCK}"

[sweep]
num_scenarios = 2
seed = 3
chunk_size = 2

[simulation]
horizon = 2.0
dt = 0.05

[current]
speed = 0.0

[tide]
{tidal}
[output]
record_points = 5
figures = false
"""
    )
    return f


def test_the_new_disturbance_is_swept_with_its_own_section(tmp_path):
    f = _toml(tmp_path, "speed = [0.0, 0.6]\nperiod = 30.0\n")
    spec, _ = load_config(f)
    assert [s for s, _ in spec.scenario.environment] == ["tide"]
    res = run_sweep(spec, progress=False)
    iae = res.metrics["vcm"]["iae_e"]
    # the two scenarios differ only in the tidal speed drawn from [0, 0.6]: the loop felt it
    assert np.all(np.isfinite(iae)) and abs(iae[0] - iae[1]) > 1e-6
    # the CLI: the same file, its [tide] section, results on disk; a typo: one line, exit 2
    out = tmp_path / "out"
    assert main(["sweep", str(f), "--out", str(out)]) in (0, 1)
    summary = json.loads((out / "summary.json").read_text())
    assert summary
    ran = json.loads((out / "run.json").read_text())["config"]["spec"]  # what ran, as summary's
    assert ran["scenario"]["environment"] == [
        ["tide", [["direction_deg", 0.0], ["period", 30.0], ["speed", [0.0, 0.6]]]]
    ]
    bad = _toml(tmp_path, "sped = 0.4\n")
    assert main(["sweep", str(bad), "--out", str(tmp_path / "bad")]) == 2
    assert not (tmp_path / "bad" / "summary.json").exists()


@pytest.mark.slow  # 7 s; test_the_new_disturbance_is_tuned_from_its_own_section tunes it too
def test_the_new_disturbance_is_tuned():
    loop = loops.make_loop("puck", "vcm")
    problem = TuningProblem(space=GainSpace(loop=loop), num_steps=40, timing="sampled")
    data = problem_data(problem, dt=0.05)
    train = tuning_batch(0, 2, loop=loop, position_offset=0.1, current_max=0.0)
    keys = jax.random.split(jax.random.PRNGKey(1), 2)
    env = jax.vmap(lambda k: environment.sample(k, {"tide": SECTION}, loop))(keys)
    felt = train._replace(environment=env)
    loss = lambda th, d, s: objective(th, d, s, problem)[0]
    r = run_gradient_tuner(
        loss, data.theta_ref, (data, felt), optimizer="adam", steps=2, learning_rate=0.05
    )
    assert r.n_bad == 0 and np.isfinite(r.loss)
    g0 = r.history[0]["grad_norm"]
    assert g0 is not None and np.isfinite(g0) and g0 > 0


def _tune_toml(tmp_path, tidal: str) -> Path:
    f = tmp_path / "tune_tidal.toml"
    f.write_text(
        f"""
[scenario]
vehicle = "puck"
module = "{PUCK}"
controller = "vcm"

[simulation]
horizon = 2.0
dt = 0.05
timing = "sampled"

[scenarios]
current_max = 0.0
position_offset = 0.1

[tide]
{tidal}
[train]
size = 2

[heldout]
size = 2

[optimizer]
name = "adam"
steps = 2
"""
    )
    return f


def test_the_new_disturbance_is_tuned_from_its_own_section(tmp_path):
    from tuning.config import load_config as load_tune
    from tuning.run import build
    from vcjax.config import ConfigError

    cfg = load_tune(_tune_toml(tmp_path, "speed = [0.0, 0.6]\nperiod = 20.0\n"))
    assert [s for s, _ in cfg.environment] == ["tide"]
    problem, _, data, train, heldout = build(cfg)
    (comp,), (params,) = train.environment.components, train.environment.params
    assert comp == Tidal() and heldout.environment.components == (Tidal(),)
    speed = np.asarray(params.speed)  # one draw per scenario from [0, 0.6]
    assert speed.shape == (2,) and np.all((speed >= 0) & (speed <= 0.6)) and speed[0] != speed[1]
    loss = lambda th, d, s: objective(th, d, s, problem)[0]
    r = run_gradient_tuner(
        loss, data.theta_ref, (data, train), optimizer="adam", steps=2, learning_rate=0.05
    )
    assert r.n_bad == 0 and np.isfinite(r.loss) and r.history[0]["grad_norm"] > 0
    with pytest.raises(ConfigError, match=r"\[tide\] sped: unknown key \(did you mean 'speed'"):
        load_tune(_tune_toml(tmp_path, "sped = 0.4\n"))
