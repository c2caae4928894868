"""``vcjax fit``: multiple-shooting identification checked against known truths.

* the block Levenberg–Marquardt step and the profiled information matrix against a dense
  least-squares solve (numpy ``lstsq`` / ``inv``) of the same problem;
* the multiple-shooting cost's gradient against central finite differences;
* recovery of REMUS 100 coefficients from PythonVehicleSimulator's own log (an independent
  simulator's output, ``tests/data/remus100_pvs_reference.csv``), started 30 % off;
* with measurement noise, the true values within 3 standard errors;
* the current recovered with ``fit_current``; the continuous INFANTE-class plant (rk4);
* a product pair reported as not identifiable; bad data and bad configs named.
"""

import dataclasses
import json
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax.cli import main
from vcjax.identify import (
    ShootingProblem,
    fit_logs,
    get_fit_model,
    levenberg_marquardt,
    load_log,
    make_segments,
    save_log_csv,
    schur_information,
)
from vcjax.identify.lm import lm_step

CSV = Path(__file__).parent / "data" / "remus100_pvs_reference.csv"
PVS_CURRENT = (0.5, math.radians(170.0))  # the reference run's current
REMUS = get_fit_model("remus100")
FOUR = ["CD_0", "CL_delta_r", "CL_delta_s", "cf_coeff"]


def _pvs_log(n=None):
    log = load_log(CSV, REMUS.state_columns, REMUS.command_columns)
    if n is None:
        return log
    return dataclasses.replace(log, t=log.t[:n], x=log.x[:n], u=log.u[:n])


# ---------------------------------------------------------------------------------------------
# The solver, on a linear problem solved densely
# ---------------------------------------------------------------------------------------------


def _random_block_problem(rng, J=5, m=12, p=3, n=4):
    Jz = rng.normal(size=(J, m, p))
    Js = rng.normal(size=(J, m, n))
    r = rng.normal(size=(J, m))
    return r, Jz, Js


def _dense(Jz, Js):
    J, m, p = Jz.shape
    n = Js.shape[2]
    D = np.zeros((J * m, p + J * n))
    for j in range(J):
        D[j * m : (j + 1) * m, :p] = Jz[j]
        D[j * m : (j + 1) * m, p + j * n : p + (j + 1) * n] = Js[j]
    return D


def test_block_step_equals_dense_gauss_newton():
    rng = np.random.default_rng(0)
    r, Jz, Js = _random_block_problem(rng)
    D = _dense(Jz, Js)
    x = np.linalg.lstsq(D, -r.reshape(-1), rcond=None)[0]
    dz, ds, predicted = lm_step(r, Jz, Js, 0.0)
    np.testing.assert_allclose(dz, x[:3], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(ds.reshape(-1), x[3:], rtol=1e-10, atol=1e-12)
    res = r.reshape(-1) + D @ x
    np.testing.assert_allclose(predicted, 0.5 * (r.ravel() @ r.ravel() - res @ res), rtol=1e-10)
    # the profiled information: the inverse of the (z, z) block of the dense (D^T D)^-1
    cov = np.linalg.inv(D.T @ D)[:3, :3]
    np.testing.assert_allclose(np.linalg.inv(schur_information(Jz, Js)), cov, rtol=1e-9)


def test_lm_solves_a_nonlinear_block_problem():
    """y = a exp(b t) + c_j per block, with per-block offsets c_j: recovers (a, b) and c_j."""
    rng = np.random.default_rng(1)
    t = np.linspace(0, 1, 15)
    a, b, c = 2.0, -1.3, rng.normal(size=6)
    y = a * np.exp(b * t)[None, :] + c[:, None]

    def residual(z, s):
        return z[0] * np.exp(z[1] * t)[None, :] + s - y

    def linearize(z, s):
        e = np.exp(z[1] * t)
        Jz = np.stack([np.broadcast_to(e, (6, 15)), np.broadcast_to(z[0] * t * e, (6, 15))], -1)
        return residual(z, s), Jz, np.ones((6, 15, 1))

    res = levenberg_marquardt(linearize, residual, np.array([1.0, 0.0]), np.zeros((6, 1)))
    assert res.converged, res.reason
    np.testing.assert_allclose(res.z, [a, b], rtol=1e-8)
    np.testing.assert_allclose(res.s[:, 0], c, rtol=1e-8, atol=1e-10)


# ---------------------------------------------------------------------------------------------
# Multiple-shooting cost: gradient vs finite differences
# ---------------------------------------------------------------------------------------------


def test_shooting_gradient_matches_finite_differences():
    log = _pvs_log(121)
    prob = ShootingProblem(REMUS, "pvs", FOUR, REMUS.nominal(jnp.float64), False, *PVS_CURRENT)
    seg = make_segments([log], 30)
    w = 1.0 / np.maximum(np.std(log.x, axis=0), 1e-3)
    z = np.log(np.array([1.2, 0.8, 1.1, 1.3]))
    rng = np.random.default_rng(3)
    s = seg.y[:, 0, :] + 1e-3 * rng.normal(size=seg.y[:, 0, :].shape) * np.std(log.x, axis=0)
    vg = jax.jit(jax.value_and_grad(lambda z_, s_: prob.cost(z_, s_, seg, w), argnums=(0, 1)))

    def cost(z_, s_):
        return float(vg(jnp.asarray(z_), jnp.asarray(s_))[0])

    _, (gz, gs) = vg(jnp.asarray(z), jnp.asarray(s))
    h = 1e-6
    for i in range(z.size):
        e = np.zeros_like(z)
        e[i] = h
        fd = (cost(z + e, s) - cost(z - e, s)) / (2 * h)
        np.testing.assert_allclose(float(gz[i]), fd, rtol=1e-5)
    # a few segment-state directions, in their own units
    for j, k in [(0, 6), (1, 5), (2, 12), (3, 14)]:
        hs = 1e-6 * max(abs(s[j, k]), 1.0)
        e = np.zeros_like(s)
        e[j, k] = hs
        fd = (cost(z, s + e) - cost(z, s - e)) / (2 * hs)
        np.testing.assert_allclose(float(gs[j, k]), fd, rtol=1e-5, atol=1e-9)
    # the LM Jacobians are those of the same residuals: J^T r equals the gradient
    r, Jz, Js = prob.linearize(z, s, seg, w)
    np.testing.assert_allclose(np.einsum("jmp,jm->p", Jz, r), gz, rtol=1e-9)


# ---------------------------------------------------------------------------------------------
# REMUS 100 from PythonVehicleSimulator's own log
# ---------------------------------------------------------------------------------------------


def _rel_err(result):
    return {n: result.estimates[n] / result.nominal[n] - 1.0 for n in result.names}


def test_recovers_four_coefficients_from_pvs_log_short():
    """The first 10 s of the PVS log (rudder and stern planes active), 30 % off: within 1e-6."""
    res = fit_logs(
        REMUS, [_pvs_log(501)], FOUR, step="pvs", current_speed=PVS_CURRENT[0],
        current_direction=PVS_CURRENT[1], initial_scale=1.3, segment_steps=25, max_iters=30,
    )  # fmt: skip
    err = _rel_err(res)
    assert all(abs(e) < 1e-6 for e in err.values()), err
    assert res.initial["CD_0"] == pytest.approx(1.3 * res.nominal["CD_0"])
    assert res.converged and not res.warnings
    for c in ("x", "u", "r"):
        assert res.residual_rms_after[c] < 1e-6 * res.residual_rms_before[c] + 1e-9


@pytest.mark.slow
def test_recovers_four_coefficients_from_full_pvs_log_cli(tmp_path):
    """The acceptance check through the CLI: the whole 60 s log, four coefficients, 1 %."""
    cfg = tmp_path / "fit.toml"
    cfg.write_text(
        f'[data]\nfiles = ["{CSV}"]\n[model]\nvehicle = "remus100"\nstep = "pvs"\n'
        "current_speed = 0.5\ncurrent_direction_deg = 170.0\n"
        f"[fit]\nparams = {json.dumps(FOUR)}\ninitial_scale = 1.3\nsegment_steps = 50\n"
    )
    out = tmp_path / "out"
    assert main(["fit", str(cfg), "--out", str(out), "--quiet"]) == 0
    fit = json.loads((out / "fit.json").read_text())
    for n in FOUR:
        assert abs(fit["estimates"][n] / fit["nominal"][n] - 1) < 0.01, fit["estimates"]
        assert abs(fit["initial"][n] / fit["nominal"][n] - 1.3) < 1e-12


def _noisy(log, seed):
    sig = np.array(
        [0.02] * 3 + [math.radians(0.1)] * 3 + [0.01] * 3 + [0.002] * 3
        + [math.radians(0.1)] * 2 + [2.0]
    )  # fmt: skip
    rng = np.random.default_rng(seed)
    return dataclasses.replace(log, x=log.x + rng.normal(size=log.x.shape) * sig), sig


@pytest.mark.slow
def test_noisy_log_true_values_within_three_standard_errors():
    log, sig = _noisy(_pvs_log(), seed=1)
    res = fit_logs(
        REMUS, [log], FOUR, step="pvs", current_speed=PVS_CURRENT[0],
        current_direction=PVS_CURRENT[1], initial_scale=1.3, segment_steps=50,
    )  # fmt: skip
    for n in FOUR:
        z = (res.estimates[n] - res.nominal[n]) / res.std[n]
        assert abs(z) < 3.0, (n, z, res.estimates, res.std)
        assert res.std[n] < 0.02 * abs(res.nominal[n])  # informative, not vacuous
    # the fit's own noise estimate matches the noise added
    np.testing.assert_allclose(list(res.noise_std.values()), sig, rtol=0.1)


@pytest.mark.slow
def test_fit_current_recovers_the_current():
    log = _pvs_log(1501)
    res = fit_logs(
        REMUS, [log], ["CD_0", "CL_delta_r"], step="pvs", fit_current=True,
        current_speed=0.3, current_direction=math.radians(120.0), initial_scale=1.3,
        segment_steps=25, max_iters=40,
    )  # fmt: skip
    assert res.estimates["current_speed"] == pytest.approx(0.5, rel=1e-4)
    assert res.estimates["current_direction_deg"] == pytest.approx(170.0, abs=1e-2)
    assert res.initial["current_speed"] == 0.3
    for n in ("CD_0", "CL_delta_r"):
        assert res.estimates[n] == pytest.approx(res.nominal[n], rel=1e-4)
    fit = res.to_json()
    assert set(fit["estimates"]) == {"CD_0", "CL_delta_r"}  # flat map of vehicle parameters
    assert set(fit["current"]["estimates"]) == {"current_speed", "current_direction_deg"}


def test_product_pair_reported_not_identifiable_cli(tmp_path, capsys):
    """A_r and CL_delta_r enter the rudder force only as their product: through the CLI,
    fit.json says so (correlation -1, a warning) and a warning line goes to stderr; fit.json
    has the keys of the issue and the figures are written."""
    log = _pvs_log(201)
    path = save_log_csv(
        tmp_path / "run.csv", log.t, log.x, log.u, REMUS.state_columns, REMUS.command_columns
    )
    cfg = _write_config(
        tmp_path, [path], params=["A_r", "CL_delta_r"],
        extra="initial_scale = 1.2\nsegment_steps = 25\nmax_iters = 20\n",
    )  # fmt: skip
    cfg.write_text(
        cfg.read_text().replace('step = "pvs"', 'step = "pvs"\ncurrent_speed = 0.5\n'
                                "current_direction_deg = 170.0")
    )  # fmt: skip
    out = tmp_path / "out"
    assert main(["fit", str(cfg), "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "warning: A_r and CL_delta_r are not separately identifiable" in err
    fit = json.loads((out / "fit.json").read_text())
    for key in ("estimates", "std", "correlation", "initial", "residual_rms", "iterations",
                "wall_time_s", "warnings", "cost_history"):  # fmt: skip
        assert key in fit, key
    assert fit["correlation"]["names"] == ["A_r", "CL_delta_r"]
    run = json.loads((out / "run.json").read_text())  # how to reproduce it
    assert run["command"] == "fit" and run["config"]["fit"]["segment_steps"] == 25
    assert fit["correlation"]["matrix"][0][1] < -0.99
    assert set(fit["residual_rms"]["before"]) == set(REMUS.state_columns)
    assert any("not separately identifiable" in w for w in fit["warnings"])
    # the product is still determined
    est, nom = fit["estimates"], fit["nominal"]
    prod = est["A_r"] * est["CL_delta_r"]
    assert prod == pytest.approx(nom["A_r"] * nom["CL_delta_r"], rel=1e-6)
    for png in ("cost_history.png", "measured_vs_predicted.png"):
        assert (out / png).stat().st_size > 10_000


# ---------------------------------------------------------------------------------------------
# The continuous INFANTE-class plant (rk4)
# ---------------------------------------------------------------------------------------------


def test_infante_rk4_recovers_coefficients(tmp_path):
    from vcjax.identify.manoeuvres import infante_logs, perturbed_params

    model = get_fit_model("infante")
    names = ["Y_uudr", "N_uudr", "N_ur", "X_uu"]
    true = perturbed_params(model.nominal(jnp.float64), 0.2, seed=5, names=names)
    logs = infante_logs(true, tmp_path, dt=0.1, horizon=30.0, noise=None, trials=("zigzag",))
    res = fit_logs(
        model, [load_log(f, model.state_columns, model.command_columns) for f in logs], names,
        step="rk4", initial_scale=1.3, segment_steps=20, max_iters=30,
    )  # fmt: skip
    for n in names:
        assert res.estimates[n] == pytest.approx(float(getattr(true, n)), rel=1e-5), n


# ---------------------------------------------------------------------------------------------
# Bad data and bad configs: named, before anything is compiled (CLI: one line, exit 2)
# ---------------------------------------------------------------------------------------------


def _write_config(tmp_path, files, params=("CD_0",), extra=""):
    cfg = tmp_path / "fit.toml"
    cfg.write_text(
        f"[data]\nfiles = {json.dumps([str(f) for f in files])}\n"
        '[model]\nvehicle = "remus100"\nstep = "pvs"\n'
        f"[fit]\nparams = {json.dumps(list(params))}\n{extra}"
    )
    return cfg


def _cli_error(cfg, tmp_path, capsys):
    code = main(["fit", str(cfg), "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err
    return err


def _short_csv(tmp_path, n=30):
    log = _pvs_log(n)
    return log, save_log_csv(
        tmp_path / "run.csv", log.t, log.x, log.u, REMUS.state_columns, REMUS.command_columns,
        provenance="test log",
    )  # fmt: skip


def test_missing_column_named(tmp_path, capsys):
    _, path = _short_csv(tmp_path)
    lines = path.read_text().splitlines()
    cols = lines[1].split(",")
    k = cols.index("q")
    body = [",".join(c for i, c in enumerate(row.split(",")) if i != k) for row in lines[1:]]
    path.write_text("\n".join([lines[0]] + body) + "\n")
    err = _cli_error(_write_config(tmp_path, [path]), tmp_path, capsys)
    assert "run.csv" in err and "missing column 'q'" in err


def test_nan_rows_named(tmp_path, capsys):
    _, path = _short_csv(tmp_path)
    lines = path.read_text().splitlines()
    row = lines[10].split(",")
    row[7] = "nan"  # column u
    lines[10] = ",".join(row)
    path.write_text("\n".join(lines) + "\n")
    err = _cli_error(_write_config(tmp_path, [path]), tmp_path, capsys)
    assert "run.csv" in err and "column 'u'" in err and "line 11" in err


def test_non_monotonic_time_named(tmp_path, capsys):
    log, _ = _short_csv(tmp_path)
    t = log.t.copy()
    t[12] = t[10]
    path = tmp_path / "run.npz"
    np.savez(
        path, t=t,
        **{c: log.x[:, i] for i, c in enumerate(REMUS.state_columns)},
        **{c: log.u[:, i] for i, c in enumerate(REMUS.command_columns)},
    )  # fmt: skip
    err = _cli_error(_write_config(tmp_path, [path]), tmp_path, capsys)
    assert "run.npz" in err and "column 't' must strictly increase" in err and "row 12" in err


def test_unknown_parameter_named(tmp_path, capsys):
    _, path = _short_csv(tmp_path)
    err = _cli_error(_write_config(tmp_path, [path], params=["CD_0", "C_magic"]), tmp_path, capsys)
    assert "[fit] params" in err and "'C_magic'" in err and "remus100" in err


@pytest.mark.parametrize(
    "extra, expect",
    [
        ("segment_step = 10\n", "[fit] segment_step: unknown key"),
        ("max_iters = 0\n", "[fit] max_iters"),
        ("initial_scale = -1.0\n", "[fit] initial_scale"),
        ("fit_current = 1\n", "[fit] fit_current: expected true or false"),
        ("[plot]\nx = 1\n", "unknown section [plot]"),
    ],
)
def test_bad_config_named(tmp_path, capsys, extra, expect):
    _, path = _short_csv(tmp_path)
    err = _cli_error(_write_config(tmp_path, [path], extra=extra), tmp_path, capsys)
    assert "fit.toml" in err and expect in err


def test_step_pvs_rejected_for_infante(tmp_path, capsys):
    cfg = tmp_path / "fit.toml"
    cfg.write_text(
        '[data]\nfiles = ["a.csv"]\n[model]\nvehicle = "infante"\nstep = "pvs"\n'
        '[fit]\nparams = ["N_ur"]\n'
    )
    err = _cli_error(cfg, tmp_path, capsys)
    assert "[model] step" in err and "'pvs'" in err and "infante" in err


def test_missing_file_named(tmp_path, capsys):
    err = _cli_error(_write_config(tmp_path, [tmp_path / "nope.csv"]), tmp_path, capsys)
    assert "nope.csv" in err and "no such file" in err


# ---------------------------------------------------------------------------------------------
# The study's manoeuvres
# ---------------------------------------------------------------------------------------------


def test_manoeuvres_against_steady_state_and_switching_rule():
    """Speed steps settle at the calibrated straight-line speed 5 sqrt(T / 920) m/s (920 N gives
    5 m/s by construction of X_u|u|); the zig-zag reverses the rudder where the heading crosses
    +-20 deg, and only there."""
    from vcjax.identify.manoeuvres import simulate_trial

    p = get_fit_model("infante").nominal(jnp.float64)
    t, x, u = simulate_trial(p, "speed_steps", dt=0.2, horizon=800.0, thrust=600.0)
    for level, T in enumerate([600.0, 900.0, 300.0, 600.0]):
        k = int(round((level + 1) * 200.0 / 0.2)) - 1  # end of each 200 s level
        assert u[k, 0] == T
        assert x[k, 3] == pytest.approx(5.0 * math.sqrt(T / 920.0), rel=2e-4)
    t, x, u = simulate_trial(p, "zigzag", dt=0.1, horizon=60.0)
    psi, delta_cmd = np.degrees(x[:, 2]), np.degrees(u[:, 1])
    flips = np.flatnonzero(np.diff(delta_cmd) != 0) + 1
    assert flips.size >= 3
    for k in flips:  # rudder reversed at the first sample beyond +-20 deg
        assert abs(psi[k]) >= 20.0 and abs(psi[k - 1]) < 20.0 + 1e-9
        assert np.sign(delta_cmd[k]) == np.sign(psi[k])  # positive rudder turns to port
