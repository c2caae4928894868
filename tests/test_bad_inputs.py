"""Bad inputs and unhealthy runs (issue 11): each case asserts its exact outcome -- an error
naming the field or file, a health flag set as data, or a CLI exit code with a one-line message.

CLI cases call :func:`vcjax.cli.main` in-process (exit code returned, message on stderr) instead
of spawning processes. Exit codes: 2 = bad input (no traceback), 1 = a run that went unhealthy
(its figures and metrics are still written), 0 = success.
"""

import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax import cli, experiments, loops
from vcjax.allocation import allocate, clip_allocate
from vcjax.mechanics import (
    MechanicalSystem,
    VCMGains,
    VirtualConstraints,
    check_shapes,
    reaction_force,
    vcm_gains,
)
from vcjax.rollout import RolloutConfig, first_unhealthy_step, rollout
from vcjax.vehicles import infante, odin, remus100

# ------------------------------------------------------------------ the generic engine

_ZERO_BIAS = lambda q, qd, a: jnp.zeros_like(q)  # noqa: E731
_HOLD_Q0 = VirtualConstraints(holonomic=lambda q, t, a: jnp.atleast_1d(q[0] - 1.0))
_GAINS_1 = vcm_gains(P_G=[1.0], P_Phi=[2.0])


def _system(M):
    """A 2-DOF system whose mass matrix is ``M`` (+ 0 q[0], so that under jit it is traced)."""
    M = jnp.asarray(M)
    return MechanicalSystem(mass_matrix=lambda q, a: M + 0.0 * q[0], bias_force=_ZERO_BIAS)


_Q = (jnp.array([0.2, 0.0]), jnp.array([0.1, 0.0]))


@pytest.mark.parametrize(
    "M, message",
    [
        ([[2.0, -3.0], [1.0, 2.0]], "not symmetric"),
        ([[-2.0, 0.0], [0.0, -2.0]], "not positive definite"),
        ([[1.0, 2.0], [2.0, 1.0]], "not positive definite"),  # symmetric, indefinite
    ],
)
def test_mass_matrix_checked_eagerly(M, message):
    with pytest.raises(ValueError, match=rf"mass_matrix\(q\): matrix is {message}"):
        reaction_force(_system(M), _HOLD_Q0, _GAINS_1, *_Q, 0.0)


@pytest.mark.parametrize("M", [[[2.0, -3.0], [1.0, 2.0]], [[-2.0, 0.0], [0.0, -2.0]]])
@pytest.mark.parametrize("method", ["row", "column"])
def test_bad_mass_matrix_inside_jit_is_reported(M, method):
    cons = (
        _HOLD_Q0
        if method == "row"
        else VirtualConstraints(
            holonomic=lambda q, t, a: jnp.stack([q[0] - 1.0, q[1] + 0.5]),
        )
    )
    gains = _GAINS_1 if method == "row" else vcm_gains(P_G=[1.0, 1.0], P_Phi=[2.0, 2.0])
    diag = jax.jit(
        lambda q, qd: reaction_force(_system(M), cons, gains, q, qd, 0.0, method=method)[2]
    )(*_Q)
    # W itself is fine (rank 1 or 2, cond 1): the health must come from M
    assert bool(diag.full_rank) and float(diag.cond) == pytest.approx(1.0)
    assert not bool(diag.mass_spd)
    assert not bool(diag.ok)


def test_good_mass_matrix_inside_jit_is_ok_and_matches_kkt():
    M = np.array([[2.0, 0.5], [0.5, 1.0]])
    tau_c, qdd, diag = jax.jit(
        lambda q, qd: reaction_force(_system(M), _HOLD_Q0, _GAINS_1, q, qd, 0.0)
    )(*_Q)
    assert bool(diag.mass_spd) and bool(diag.ok)
    # independent: the KKT system [[M, W^T], [W, 0]] [qdd; lam] = [0; -h], W = [1, 0],
    # Phi = qd0 + P_G (q0 - 1) for G = q0 - 1, so h = dPhi/dq qd + P_Phi Phi = P_G qd0 + P_Phi Phi
    q, qd = (np.asarray(a) for a in _Q)
    W = np.array([[1.0, 0.0]])
    h = 1.0 * qd[0] + 2.0 * (qd[0] + 1.0 * (q[0] - 1.0))
    K = np.block([[M, W.T], [W, np.zeros((1, 1))]])
    sol = np.linalg.solve(K, np.array([0.0, 0.0, -h]))
    np.testing.assert_allclose(np.asarray(qdd), sol[:2], rtol=1e-12)


_EYE2 = MechanicalSystem(mass_matrix=lambda q, a: jnp.eye(2, dtype=q.dtype), bias_force=_ZERO_BIAS)


@pytest.mark.parametrize(
    "gains, message",
    [
        (
            VCMGains(jnp.ones(2), jnp.ones(1)),
            r"P_G: expected shape \(1,\) or \(1, 1\) for .*"
            r"1 rows from `holonomic`.*got \(2,\)",
        ),
        (
            VCMGains(jnp.ones(1), jnp.ones(3)),
            r"P_Phi: expected shape \(1,\) or \(1, 1\).*got \(3,\)",
        ),
        (VCMGains(jnp.ones(1), jnp.ones((2, 2))), r"P_Phi: .*got \(2, 2\)"),
    ],
)
def test_gain_shapes_checked_before_compiling(gains, message):
    with pytest.raises(ValueError, match=message):
        jax.jit(lambda q, qd: reaction_force(_EYE2, _HOLD_Q0, gains, q, qd, 0.0))(*_Q)


def test_constraint_of_shape_1x1_is_named():
    cons = VirtualConstraints(velocity=lambda q, qd, t, a: jnp.reshape(qd[0], (1, 1)))
    with pytest.raises(ValueError, match=r"constraint `velocity`: .* got shape \(1, 1\)"):
        reaction_force(_EYE2, cons, vcm_gains(jnp.zeros(0), [1.0]), *_Q, 0.0)


def test_initial_state_shape_against_the_model():
    with pytest.raises(ValueError, match=r"q: shape \(3,\) does not match the model"):
        reaction_force(_EYE2, _HOLD_Q0, _GAINS_1, jnp.zeros(3), jnp.zeros(3), 0.0)
    with pytest.raises(ValueError, match=r"qd: expected shape \(2,\)"):
        check_shapes(_EYE2, _HOLD_Q0, _GAINS_1, jnp.zeros(2), jnp.zeros(3))


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(P_G=["a"], P_Phi=[1.0]), "P_G: expected numbers"),
        (dict(P_G=[1.0], P_Phi=[1.0, None]), "P_Phi: expected numbers"),
        (dict(P_G=[1.0], P_Phi=[[1.0, 2.0, 3.0]]), r"P_Phi: expected shape \(p,\) or \(p, p\)"),
    ],
)
def test_vcm_gains_name_the_gain(kwargs, message):
    with pytest.raises(ValueError, match=message):
        vcm_gains(**kwargs)


# ------------------------------------------------------------------ rollout


def _scalar_plant(t, x, u, p):
    return u


def _p_controller(t, x, z, k):
    return -k * x, z, ()


_CFG = RolloutConfig(num_steps=150, integrator="rk4")
_run = jax.jit(rollout, static_argnames=("plant", "controller", "config"))


@pytest.mark.parametrize("dt", [0.0, -0.1, math.nan, math.inf])
def test_rollout_rejects_bad_dt(dt):
    with pytest.raises(ValueError, match="dt: expected a finite step size > 0"):
        rollout(_scalar_plant, _p_controller, _CFG, None, 1.0, jnp.ones(1), jnp.zeros(0), dt)


def test_rollout_rejects_bad_bound():
    with pytest.raises(ValueError, match="bound"):
        rollout(
            _scalar_plant, _p_controller, _CFG, None, 1.0, jnp.ones(1), jnp.zeros(0), 0.1, bound=0.0
        )


def test_finite_divergence_is_flagged():
    # a negative gain built inside jit escapes eager validation: x = exp(2 t) reaches e^30
    traj = _run(
        _scalar_plant, _p_controller, _CFG, None, jnp.asarray(-2.0), jnp.ones(1), jnp.zeros(0), 0.1
    )
    assert bool(np.all(traj.finite))  # never non-finite ...
    assert not bool(traj.healthy)  # ... but diverged
    k = first_unhealthy_step(traj)
    # independent: exact solution exp(2 t) crosses the default bound 1e9 at t = ln(1e9) / 2
    t_cross = math.log(1e9) / 2.0
    assert abs(float(traj.t[k + 1]) - t_cross) <= 0.1 + 1e-9


def test_divergence_bound_is_set_by_the_caller():
    traj = _run(
        _scalar_plant,
        _p_controller,
        _CFG,
        None,
        jnp.asarray(-2.0),
        jnp.ones(1),
        jnp.zeros(0),
        0.1,
        bound=100.0,
    )
    k = first_unhealthy_step(traj)
    assert abs(float(traj.t[k + 1]) - math.log(100.0) / 2.0) <= 0.1 + 1e-9
    ok = _run(
        _scalar_plant,
        _p_controller,
        _CFG,
        None,
        jnp.asarray(2.0),
        jnp.ones(1),
        jnp.zeros(0),
        0.1,
        bound=100.0,
    )
    assert bool(ok.healthy) and first_unhealthy_step(ok) is None


def test_nan_state_is_flagged_and_frozen():
    def nan_plant(t, x, u, p):
        return jnp.where(t > 0.45, jnp.nan, 1.0) * jnp.ones_like(x)

    traj = _run(nan_plant, _p_controller, _CFG, None, 0.0, jnp.ones(1), jnp.zeros(0), 0.1)
    k = first_unhealthy_step(traj)
    assert k == 4 and not bool(traj.finite[4]) and bool(traj.diverged[4])
    assert np.all(np.isfinite(np.asarray(traj.x)))  # frozen at the last finite value


# ------------------------------------------------------------------ PVS replay (REMUS 100)

_RM_ARGS = remus100.remus100_args(remus100.remus100_params())
_RM_X0 = remus100.remus100_state()
_CMDS = jnp.tile(jnp.asarray([0.05, -0.05, 1000.0]), (20, 1))


def test_pvs_rollout_eager_nan_command():
    with pytest.raises(ValueError, match="u_cmds: contains NaN"):
        remus100.pvs_rollout(_RM_X0, _CMDS.at[3, 0].set(jnp.nan), _RM_ARGS, 0.02)


@pytest.mark.parametrize("dt", [-0.02, 0.0, math.nan])
def test_pvs_rollout_eager_bad_dt(dt):
    with pytest.raises(ValueError, match="dt: expected a finite step size > 0"):
        remus100.pvs_rollout(_RM_X0, _CMDS, _RM_ARGS, dt)


def test_pvs_rollout_flags_inside_jit():
    replay = jax.jit(remus100.pvs_rollout)
    rep = replay(_RM_X0, _CMDS.at[3, 0].set(jnp.nan), _RM_ARGS, 0.02)
    np.testing.assert_array_equal(np.asarray(rep.ok), np.arange(20) < 3)
    rep = replay(_RM_X0, _CMDS, _RM_ARGS, -0.02)
    assert not np.any(np.asarray(rep.ok))
    rep = replay(_RM_X0, _CMDS, _RM_ARGS, 0.02)
    assert np.all(np.asarray(rep.ok))


# ------------------------------------------------------------------ allocation

_T = jnp.asarray(np.array([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0]]))


@pytest.mark.parametrize("f_max", [-10.0, [10.0, -1.0, 10.0], math.nan, [10.0, 0.0, 10.0]])
@pytest.mark.parametrize("fn", [allocate, clip_allocate])
def test_allocation_limits_checked(fn, f_max):
    with pytest.raises(ValueError, match="f_max"):
        fn(_T, jnp.asarray([1.0, 2.0]), f_max)


@pytest.mark.parametrize("f_max", [-10.0, math.nan])
def test_allocation_bad_limits_inside_jit_are_infeasible(f_max):
    a = jax.jit(allocate)(_T, jnp.asarray([1.0, 2.0]), jnp.asarray(f_max))
    assert not bool(a.feasible)
    np.testing.assert_array_equal(np.asarray(a.f), 0.0)  # no thrust, never a reversed one


# ------------------------------------------------------------------ vehicle parameters


@pytest.mark.parametrize(
    "field, value, message",
    [
        ("mass", -3331.8, r"plant.mass: every entry must be > 0"),
        ("Iz", math.nan, r"plant.Iz: contains NaN"),
        ("thrust_max", 0.0, r"plant.thrust_max: every entry must be > 0"),
        ("Y_vdot", 1e5, r"plant: M \(mass, Iz, x_g and added mass\): symmetric part of the"),
    ],
)
def test_edited_infante_params_rejected_by_the_scenario(field, value, message):
    bad = infante.infante_params()._replace(**{field: jnp.asarray(value)})
    with pytest.raises(ValueError, match=message):
        loops.make_scenario(loops.make_loop("infante", "vcm"), plant=bad)


def test_edited_design_vehicle_and_plant_args():
    bad = infante.infante_params()._replace(T_rudder=jnp.asarray(-0.1))
    loop = loops.make_loop("infante", "vcm")
    with pytest.raises(ValueError, match="design.T_rudder"):
        loops.make_scenario(loop, design=bad)
    with pytest.raises(ValueError, match="vehicle.T_rudder"):
        infante.plant_args(bad)
    with pytest.raises(ValueError, match="plant: expected InfanteParams, got OdinParams"):
        loops.make_scenario(loop, plant=odin.odin_params())


def test_edited_odin_and_remus_params():
    p = odin.odin_params()
    with pytest.raises(ValueError, match="vehicle.T_thrust"):
        odin.odin_args(p._replace(T_thrust=jnp.asarray(0.0)))
    body = p.body._replace(M_A=-10.0 * p.body.M_RB)
    with pytest.raises(ValueError, match=r"vehicle.body: M_RB \+ M_A: matrix is not positive"):
        odin.odin_args(p._replace(body=body))
    r = remus100.remus100_params()
    with pytest.raises(ValueError, match="vehicle.act_max"):
        remus100.remus100_args(r._replace(act_max=-r.act_max))


# ------------------------------------------------------------------ gains files


@pytest.mark.parametrize(
    "data, message",
    [
        (None, "gains file: expected an object, got NoneType"),
        ([1, 2], "gains file: expected an object, got list"),
        ({"vcm": None}, "section 'vcm' must be an object"),
        ({"vcm": {"P_G": None}}, r"P_G: expected shape \(3,\)"),
        ({"vcm": {"P_G": [None, 1, 1]}}, "P_G: expected a numeric array"),
        ({"vcm": {"P_G": [1, 2]}}, r"P_G: expected shape \(3,\)"),
        ({"vcm": {"Pg": [1, 1, 1]}}, "Pg"),
        ({"baseline": {"k_u": -1}}, "k_u: every entry must be > 0"),
        ({"lqr": {}}, r"unknown sections \['lqr'\]"),
    ],
)
def test_gains_from_json(data, message):
    with pytest.raises(ValueError, match=message):
        experiments.get("sim1").load_gains(data)


# ------------------------------------------------------------------ CLI (in-process)


def _cli(capsys, *argv):
    rc = cli.main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


def _one_line_error(err: str, *fragments):
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vcjax: "), err
    assert "Traceback" not in err
    for frag in fragments:
        assert frag in lines[0], (frag, err)


@pytest.mark.parametrize("command", [["simulate", "sim1"], ["demo"]])
def test_cli_out_is_an_existing_file(capsys, tmp_path, command):
    f = tmp_path / "file"
    f.write_text("x")
    rc, _, err = _cli(capsys, *command, "--out", str(f))
    assert rc == 2
    _one_line_error(err, f"--out {f}", "not a directory")


def test_cli_out_under_dev_null(capsys):
    rc, _, err = _cli(capsys, "demo", "--out", "/dev/null/figures")
    assert rc == 2
    _one_line_error(err, "--out /dev/null/figures", "cannot create the directory")


@pytest.mark.parametrize(
    "content, fragment",
    [
        ("null", "expected an object, got NoneType"),
        ('{"vcm": {"P_G": [1, 1, 1],}}', "Expecting"),
        ('{"vcm": {"P_G": [1, 1]}}', "P_G: expected shape (3,)"),
    ],
)
def test_cli_bad_gains_file(capsys, tmp_path, content, fragment):
    g = tmp_path / "g.json"
    g.write_text(content)
    rc, _, err = _cli(capsys, "simulate", "sim1", "--gains", str(g), "--out", str(tmp_path))
    assert rc == 2
    _one_line_error(err, f"gains file {g}", fragment)


def test_cli_missing_gains_file(capsys, tmp_path):
    out = tmp_path / "out"  # never the checkout's out/sim1 (the README's main job writes it)
    rc, _, err = _cli(
        capsys, "simulate", "sim1", "--gains", str(tmp_path / "no.json"), "--out", str(out)
    )
    assert rc == 2
    _one_line_error(err, "no.json", "No such file")
    assert not out.exists()  # the input is read before --out is touched


@pytest.mark.parametrize("horizon", ["0", "-1", "nan", "inf", "0.001"])
def test_cli_demo_bad_horizon(capsys, tmp_path, horizon):
    rc, _, err = _cli(capsys, "demo", "--horizon", horizon, "--out", str(tmp_path))
    assert rc == 2
    _one_line_error(err, "vcjax: demo: need")
    assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize(
    "dt, horizon, fragment",
    [
        ("inf", "inf", "need finite --dt and --horizon"),
        ("0.05", "nan", "need finite --dt and --horizon"),
        ("0", "10", "need 0 < dt <= horizon"),
        ("-0.05", "10", "need 0 < dt <= horizon"),
        ("1", "0.5", "need 0 < dt <= horizon"),
        ("1e-9", "1e6", "steps: more than"),
    ],
)
def test_cli_simulate_bad_time_grid(capsys, tmp_path, dt, horizon, fragment):
    out = tmp_path / "o"
    rc, _, err = _cli(
        capsys, "simulate", "sim1", "--dt", dt, "--horizon", horizon, "--out", str(out)
    )
    assert rc == 2
    _one_line_error(err, "vcjax: simulate: ", fragment)
    assert not out.exists()


def test_cli_simulate_bad_current_and_sim2_options(capsys, tmp_path):
    rc, _, err = _cli(capsys, "simulate", "sim1", "--current", "nan", "0", "--out", str(tmp_path))
    assert rc == 2
    _one_line_error(err, "current: contains NaN")
    rc, _, err = _cli(capsys, "simulate", "sim2", "--current", "0", "0", "--out", str(tmp_path))
    assert rc == 2
    _one_line_error(err, "--current is not supported")


def test_cli_unhealthy_simulation_exits_nonzero_and_still_writes(capsys, tmp_path):
    # the gains: P_Phi = 1000 makes the VCM variants blow up within a fraction of a second
    g = tmp_path / "g.json"
    g.write_text(json.dumps({"vcm": {"P_Phi": [1000] * 5, "P_G": [1000] * 3}}))
    out = tmp_path / "out"
    rc, stdout, err = _cli(
        capsys, "simulate", "sim1", "--gains", str(g), "--horizon", "2", "--out", str(out)
    )
    assert rc == 1
    metrics = json.loads((out / "metrics.json").read_text())
    bad = [v for v, m in metrics.items() if not m["healthy"]]
    assert bad and set(bad) <= {"vcm", "vcm_integral", "vcm_ilos"}
    assert metrics["ilos"]["healthy"] and metrics["los_pid"]["healthy"]
    for v in bad:
        k = metrics[v]["unhealthy_step"]
        assert f"UNHEALTHY RUN: {v} diverged at step {k} " in err
    assert "Traceback" not in err
    assert (out / "sim1_path.png").exists() or any(out.glob("*.png"))


# ------------------------------------------------------------------ sweep, tune, fit (CLI)
# in-process, JAX already runs with one CPU device: the sweeps say --cpu-devices 1

_SWEEP = """
[sweep]
num_scenarios = 2
seed = 0
variants = ["vcm"]

[simulation]
horizon = 2.0
dt = 0.05
gains = "g.json"

[output]
record_points = 10
"""


@pytest.mark.parametrize("command", ["sweep", "tune", "fit"])
def test_cli_inputs_checked_before_out(capsys, tmp_path, command):
    """Every input is read and checked before --out is touched (a bad --out with good inputs:
    tests/test_bad_inputs_cli.py)."""
    out = tmp_path / "out"
    rc, _, err = _cli(capsys, command, str(tmp_path / "missing.toml"), "--out", str(out))
    assert rc == 2
    _one_line_error(err, f"vcjax: {command}:", "missing.toml")
    assert not out.exists()


def test_cli_sweep_malformed_gains_file_is_named(capsys, tmp_path):
    (tmp_path / "g.json").write_text('{"vcm": {"P_G": [1, 1, 1],}}')
    cfg = tmp_path / "s.toml"
    cfg.write_text(_SWEEP)
    rc, _, err = _cli(
        capsys, "sweep", str(cfg), "--out", str(tmp_path / "out"), "--cpu-devices", "1"
    )
    assert rc == 2
    _one_line_error(err, "[simulation] gains", str(tmp_path / "g.json"), "Expecting")


def test_cli_sweep_with_a_diverging_variant_completes(capsys, tmp_path):
    # the gains: every run of vcm diverges; divergence is data in a Monte-Carlo study
    (tmp_path / "g.json").write_text(json.dumps({"vcm": {"P_Phi": [1000] * 5, "P_G": [1000] * 3}}))
    cfg = tmp_path / "s.toml"
    cfg.write_text(_SWEEP)
    out = tmp_path / "out"
    rc, stdout, err = _cli(capsys, "sweep", str(cfg), "--out", str(out), "--cpu-devices", "1")
    assert rc == 0, err
    summary = json.loads((out / "summary.json").read_text())
    s = summary["variants"]["vcm"]
    assert s["n"] == 2 and s["n_diverged"] == 2
    assert s["metrics"]["ss_abs_e"]["p50"] is None  # no healthy run to summarise
    assert "vcjax: warning: sweep: vcm: 2 of 2 runs diverged" in err
    assert "vcm            no metrics: diverged 2 of 2" in stdout
    assert "Traceback" not in err
    assert (out / "sweep_envelopes.png").exists()


def test_progress_eta_excludes_the_compiling_step(monkeypatch):
    """The ETA of a run whose first step compiles (55 s) and later steps take 1 s is based on
    the later steps: 3 steps left -> 3 s, not 3 x 55 s."""
    import io

    from vcjax.runtime import progress

    clock = iter([0.0, 55.0, 56.0, 57.0])
    monkeypatch.setattr(progress.time, "perf_counter", lambda: next(clock))
    stream = io.StringIO()
    bar = progress.ProgressBar(5, "tune ", stream=stream, warmup=1)
    bar.show(1)
    assert "ETA after warm-up" in stream.getvalue() and "incl. compiling" in stream.getvalue()
    bar.show(2)
    assert "~3 s left (1 s/step)" in stream.getvalue()
