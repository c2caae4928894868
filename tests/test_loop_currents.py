"""Currents reach every loop or are refused: the generic engine's plant (the puck of
``examples/loops/puck.py``) sees the water through its drag on the relative velocity — checked
against hand computations of the free puck's acceleration and of the closed loop's steady
offsets — takes a Gauss–Markov current, and a loop without water refuses a current."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import loops, paths
from vcjax.config.scenario import import_module_file
from vcjax.rollout import RolloutConfig

ROOT = Path(__file__).resolve().parents[1]
import_module_file(ROOT / "examples" / "loops" / "puck.py")

M, B = 0.2, 0.05  # the puck's mass [kg] and linear drag [kg/s] (examples/loops/puck.py)
PATH, COEFFS = paths.line(origin=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0))  # towards north


def _puck(path=paths.LINE):
    return loops.make_loop("puck", "vcm", path=path)


def test_the_free_puck_is_dragged_by_the_water():
    """At rest, no force: m q'' = -b (q' - V_c), so q'' = b V_c / m — twice as large at
    1.0 m/s as at 0.5 m/s; moving with the water, no drag at all."""
    loop = _puck()
    x = (jnp.zeros(2), jnp.zeros(2))
    for speed in (0.5, 1.0):
        cur = jnp.asarray([0.6, 0.8, 0.0]) * speed
        sc = loops.make_scenario(loop, COEFFS, current=cur)
        _, qdd = loop.plant(0.0, x, jnp.zeros(2), loop.plant_args(sc, sc.current, jnp.zeros(3)))
        np.testing.assert_allclose(np.asarray(qdd), B * np.asarray(cur[:2]) / M, rtol=1e-14)
        _, qdd = loop.plant(
            0.0, (x[0], cur[:2]), jnp.zeros(2), loop.plant_args(sc, sc.current, jnp.zeros(3))
        )
        np.testing.assert_allclose(np.asarray(qdd), 0.0, atol=1e-15)


def _steady(loop, sc, n=1500, dt=0.02):
    g = loop.default_gains()
    traj = loops.simulate(loop, g, sc, RolloutConfig(num_steps=n), dt)
    return g, loop.signals(traj, sc)


def test_the_closed_loop_offsets_follow_the_relative_velocity_drag():
    """The engine's law knows no current, so the plant gets the extra acceleration
    a = b V_c / m; each row of G = [s, e] then obeys G'' + (p_G + p_Phi) G' + p_G p_Phi G = a_row
    (14) on a line, so it settles at a_row / (p_G p_Phi): along-track from the current's
    northern component, cross-track from its eastern one — proportional to the current speed."""
    loop = _puck()
    out = {}
    for speed in (0.5, 1.0):
        cur = np.asarray([np.cos(np.radians(30)), np.sin(np.radians(30)), 0.0]) * speed
        sc = loops.make_scenario(loop, COEFFS, current=cur, initial={"x": 0.0, "y": 0.0})
        g, sig = _steady(loop, sc)
        pg, pphi = np.asarray(g.P_G), np.asarray(g.P_Phi)
        hand = B * cur[:2] / M / (pg * pphi)
        np.testing.assert_allclose(np.asarray(sig.eps[-1]), hand, rtol=1e-4)
        out[speed] = np.asarray(sig.eps[-1])
    np.testing.assert_allclose(out[1.0], 2 * out[0.5], rtol=1e-4)
    assert np.all(np.abs(out[1.0]) > 0.01)  # not the bit-identical results of a dry plant


def test_a_gauss_markov_current_reaches_the_puck():
    """With a vanishing Gauss–Markov intensity the time-varying path reproduces the constant
    current (so the current really goes through ``with_current``); with a real one the run
    differs and stays finite."""
    loop = _puck(paths.CIRCLE)
    _, coeffs = loops.default_path("puck")
    sc = loops.make_scenario(loop, coeffs, current=(0.3, 0.2, 0.0))
    g = loop.default_gains()
    cfg = RolloutConfig(num_steps=200)
    dist = loops.Disturbances(gauss_markov=True)

    def run(sigma):
        dp = loops.DisturbanceParams(
            current=loops.gauss_markov_params(sc, *jnp.asarray([sigma, 5.0, 2.0])),
            noise_std=jnp.zeros(0),
            key=jax.random.PRNGKey(3),
        )
        return loops.simulate(loop, g, sc, cfg, 0.02, dist, dp)

    const = loops.simulate(loop, g, sc, cfg, 0.02)
    dry = loops.simulate(loop, g, sc._replace(current=jnp.zeros(3)), cfg, 0.02)
    quiet, noisy = run(1e-12), run(0.3)
    np.testing.assert_allclose(np.asarray(quiet.x[0]), np.asarray(const.x[0]), atol=1e-9)
    assert np.max(np.abs(np.asarray(const.x[0] - dry.x[0]))) > 1e-3
    assert np.all(np.isfinite(np.asarray(noisy.x[0])))
    assert np.max(np.abs(np.asarray(noisy.x[0] - const.x[0]))) > 1e-3


def test_a_loop_without_water_refuses_a_current():
    arm = loops.make_loop("arm", "vcm")
    assert not arm.can_feel("current") and loops.loop_class("puck").can_feel("varying_current")
    with pytest.raises(ValueError, match="the arm loop takes no current"):
        loops.make_scenario(arm, current=(0.5, 0.0))
    with pytest.raises(ValueError, match="cannot take a time-varying"):
        loops.check_disturbances(loops.ArmLoop, False, True)
    with pytest.raises(ValueError, match="cannot take a time-varying"):
        loops.check_disturbances(loops.make_loop("odin", "vcm"), True, True)
    loops.check_disturbances(loops.make_loop("odin", "vcm"), True, False)  # constant: fine
    loops.check_disturbances(arm, False, False)
    sc = loops.make_scenario(arm)
    with pytest.raises(ValueError, match="time-varying"):
        loops.simulate(
            arm, arm.default_gains(), sc, RolloutConfig(num_steps=2), 0.01,
            loops.Disturbances(gauss_markov=True),
            loops.DisturbanceParams(
                loops.gauss_markov_params(sc, *jnp.asarray([0.1, 5.0, 1.0])), None, None
            ),
        )  # fmt: skip


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_a_sweep_or_tune_config_asking_a_loop_for_a_current_it_cannot_take_is_refused(tmp_path):
    from vcjax.config import ConfigError
    from vcjax.sweep.config import load_config

    arm = '[scenario]\nvehicle = "arm"\n[sweep]\nnum_scenarios = 2\n'
    # no [current]: the arm gets no current (the default current is Simulation 1's)
    spec, _ = load_config(_write(tmp_path, "a.toml", arm))
    assert max(spec.scenario.current_speed) == 0.0
    with pytest.raises(ConfigError, match=r"\[current\] the arm loop takes no current"):
        load_config(_write(tmp_path, "b.toml", arm + "[current]\nspeed = [0.0, 0.5]\n"))
    gm = '[scenario]\nvehicle = "odin"\n[sweep]\nnum_scenarios = 2\n[current]\nmodel = "gauss_markov"\n'
    with pytest.raises(ConfigError, match="cannot take a time-varying"):
        load_config(_write(tmp_path, "c.toml", gm))


def test_the_cli_refuses_it_with_exit_2_and_one_line(tmp_path, capsys):
    from vcjax import cli

    cfg = _write(
        tmp_path,
        "t.toml",
        '[scenario]\nvehicle = "arm"\n[problem]\nhorizon = 1.0\ndt = 0.01\n'
        "[scenarios]\ncurrent_max = 0.5\n[train]\nsize = 2\n[heldout]\nsize = 2\n",
    )
    assert cli.main(["tune", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the arm loop takes no current" in err[0]
