"""Health is the whole truth (issue 24): a controller that reports its solve unusable makes the
rollout unhealthy, and a run swept far off its path is never ``healthy: true``."""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import cli, experiments
from vcjax.mechanics import MechanicalSystem, VirtualConstraints, reaction_force, vcm_gains
from vcjax.metrics import first_excursion, path_bound
from vcjax.rollout import RolloutConfig, controller_ok, first_unhealthy_step, rollout

_HOLD = VirtualConstraints(holonomic=lambda q, t, a: jnp.atleast_1d(q[0] - 1.0))
_GAINS = vcm_gains(P_G=[1.0], P_Phi=[2.0])
_CFG = RolloutConfig(num_steps=20, integrator="rk4", timing="sampled")


def _arm(M_ctrl):
    """Plant: unit masses (always fine). Controller: the reaction force computed with the model
    mass matrix ``M_ctrl`` (traced inside jit, so not checked eagerly); aux = its Diagnostics."""
    M_ctrl = jnp.asarray(M_ctrl)
    system = MechanicalSystem(
        mass_matrix=lambda q, a: M_ctrl + 0.0 * q[0], bias_force=lambda q, qd, a: 0.0 * q
    )

    def plant(t, x, u, p):
        q, qd = x
        return qd, u

    def controller(t, x, z, p):
        q, qd = x
        tau, _, diag = reaction_force(system, _HOLD, _GAINS, q, qd, t)
        return tau, z, diag

    return plant, controller


_run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))


def _x0():
    return (jnp.array([0.2, 0.0]), jnp.array([0.1, 0.0]))


def test_non_symmetric_mass_matrix_inside_jit_makes_the_rollout_unhealthy():
    """The issue's case: every step's Diagnostics say ok = False -> Trajectory.healthy False."""
    plant, ctrl = _arm([[2.0, -3.0], [1.0, 2.0]])
    traj = _run(plant, ctrl, _CFG, None, None, _x0(), jnp.zeros(0), 0.05)
    assert not bool(np.any(np.asarray(traj.aux.ok)))  # the controller said so at every step
    assert bool(np.all(traj.finite))  # the state itself stays finite ...
    assert not bool(traj.healthy)  # ... but the run is not healthy
    assert first_unhealthy_step(traj) == 0


def test_symmetric_mass_matrix_rollout_stays_healthy():
    plant, ctrl = _arm([[2.0, 0.5], [0.5, 1.0]])
    traj = _run(plant, ctrl, _CFG, None, None, _x0(), jnp.zeros(0), 0.05)
    assert bool(np.all(np.asarray(traj.aux.ok))) and bool(traj.healthy)
    assert first_unhealthy_step(traj) is None


def test_dict_aux_ok_flags_the_first_bad_step():
    def plant(t, x, u, p):
        return -x + u

    def controller(t, x, z, p):
        return jnp.zeros_like(x), z, {"e": x, "ok": t < 0.3 - 1e-9}

    traj = _run(plant, controller, _CFG, None, None, jnp.ones(1), jnp.zeros(0), 0.05)
    assert first_unhealthy_step(traj) == 6  # t = 0.30 is step 6


@pytest.mark.parametrize(
    "aux, expected",
    [
        ((), True),
        ({"e": jnp.ones(2)}, True),
        ({"ok": jnp.array(False)}, False),
        ((jnp.ones(1), {"inner": {"ok": jnp.array([True, False])}}), False),
        ((jnp.ones(1), {"inner": {"ok": jnp.array([True, True])}}), True),
    ],
)
def test_controller_ok_finds_ok_anywhere_in_aux(aux, expected):
    assert bool(controller_ok(aux)) is expected


# ------------------------------------------------------------------ path-error bound


@pytest.mark.parametrize(
    "u_d, horizon, bound, expected",
    [
        (2.0, 150.0, None, 75.0),  # Simulation 1: 25 % of 300 m
        (2.0, 30.0, None, 50.0),  # short runs: at least 50 m (PATH_BOUND_MIN_M)
        (0.5, 300.0, None, 50.0),  # Simulation 2's ODIN: 37.5 -> 50 m
        (2.0, 100.0, None, 50.0),  # exactly at the floor: 25 % of 200 m
        (2.0, 101.0, None, 50.5),  # just above it
        (2.0, 150.0, 10.0, 10.0),  # explicit
    ],
)
def test_path_bound(u_d, horizon, bound, expected):
    assert path_bound(u_d, horizon, bound) == expected


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), float("inf")])
def test_path_bound_rejects_bad_bounds(bad):
    with pytest.raises(ValueError, match="diverge_e: expected a finite bound > 0"):
        path_bound(1.0, 1.0, bad)


def test_first_excursion():
    assert first_excursion([0.0, 1.0, -5.0, 2.0], 4.0) == 2
    assert first_excursion([0.0, np.nan], 4.0) == 1
    assert first_excursion([0.0, 4.0], 4.0) is None


def test_strong_cross_current_is_not_healthy():
    """A 50 m/s cross current sweeps the vehicle off the line: not healthy, the first step past
    the bound (50 m) named; the paper's current stays healthy."""
    sim1 = experiments.get("sim1")
    bad = sim1.setup(horizon=3.0, dt=0.05, current=(50.0, 0.0))
    run = sim1.outcome("vcm", bad, jax.device_get(sim1.simulate("vcm", bad)))
    m = sim1.metrics(run, bad)
    assert m["healthy"] is False
    e = np.abs(np.asarray(run.loop.signals(run.traj, run.scenario).eps)[:, 1])
    k = m["unhealthy_step"]
    assert e[k] > 50.0 and np.all(e[:k] <= 50.0)  # independent: the first sample past 50 m
    wide = bad._replace(options=bad.options.replace(diverge_e=1e6))
    assert sim1.metrics(run, wide)["healthy"] is True
    good = sim1.setup(horizon=3.0, dt=0.05)
    ok = sim1.outcome("vcm", good, jax.device_get(sim1.simulate("vcm", good)))
    assert sim1.metrics(ok, good)["healthy"] is True


@pytest.mark.parametrize(
    "argv, message",
    [
        (["sim1", "--diverge-e", "0"], "--diverge-e: expected a finite bound > 0 [m], got 0"),
        (["sim1", "--diverge-e", "-3"], "--diverge-e: expected a finite bound > 0 [m], got -3"),
        (["sim2", "--diverge-e", "nan"], "--diverge-e: expected a finite bound > 0 [m], got nan"),
        (
            ["remus100", "--diverge-e", "inf"],
            "--diverge-e: expected a finite bound > 0 [m], got inf",
        ),
        (["remus100", "--edd", "implied"], "--edd does not apply to remus100"),
        (["sim1", "--max-steps", "0"], "--max-steps: expected an integer >= 1, got 0"),
        (["sim1", "--max-steps", "100"], "3000 steps: more than 100"),
    ],
)
def test_simulate_health_options_bad_input(argv, message, tmp_path, capsys):
    rc = cli.main(["simulate", *argv, "--out", str(tmp_path / "o")])
    assert rc == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "o" / "metrics.json").exists()


@pytest.mark.slow  # compiles Simulation 1's six loops
def test_metrics_json_says_unhealthy_for_the_issue_case(tmp_path, capsys):
    """`vcjax simulate sim1 --current 50 0` (shortened): exit 1, healthy false everywhere."""
    out = tmp_path / "o"
    rc = cli.main(["simulate", "sim1", "--current", "50", "0", "--horizon", "2", "--out", str(out)])
    assert rc == 1
    err = capsys.readouterr().err
    m = json.loads((out / "metrics.json").read_text())
    assert all(v["healthy"] is False for v in m.values())
    assert err.count("vcjax: UNHEALTHY RUN:") == len(m)


def test_remus100_off_path_bound_is_the_distance_to_the_survey_path():
    """`vcjax simulate remus100 --diverge-e M`: the mission's health bound is the geometric
    distance to the survey path. A track 20 m to the side of the first leg (parallel legs lie
    60 m apart, so 20 m is its distance to the path): healthy within 25 m (the default) and
    30 m, unhealthy within 15 m; a non-positive bound is refused."""
    from types import SimpleNamespace

    from vcjax import loops, paths
    from vcjax.experiments.remus100 import OFF_PATH_M, mission_extras, mission_geometry

    remus100 = experiments.get("remus100")
    path, coeffs = loops.default_path("remus100")  # the survey lawnmower
    w = jnp.linspace(40.0, 200.0, 33)
    on = jax.vmap(lambda s: paths.path_point(path, coeffs, s))(w)
    tangent = np.gradient(np.asarray(on[:, :2]), axis=0)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], 1) / np.linalg.norm(tangent, axis=1)[:, None]
    pos = np.asarray(on).copy()
    pos[:, :2] += 20.0 * normal

    @jax.jit  # one program for the three bounds (eager, each would take seconds)
    def check(eta):
        traj = SimpleNamespace(x=SimpleNamespace(eta=eta), healthy=jnp.asarray(True))
        flags = [
            mission_extras(traj, path, coeffs, dw=2.0, **kw)["mission_healthy"](None, None)
            for kw in ({}, {"off_path": 30.0}, {"off_path": 15.0})
        ]
        return mission_geometry(traj.x.eta, path, coeffs, dw=2.0)[0], flags

    dist, (default, wide, narrow) = check(jnp.asarray(pos))
    np.testing.assert_allclose(np.asarray(dist), 20.0, atol=0.05)
    assert OFF_PATH_M == 25.0 and bool(default)
    assert bool(wide) and not bool(narrow)
    assert remus100.off_path(remus100.setup(diverge_e=30.0).options) == 30.0
    with pytest.raises(ValueError, match="diverge_e: expected a finite bound > 0"):
        remus100.off_path(remus100.setup(diverge_e=0.0).options)
