"""The identification models, manoeuvres, shooting problem, fit and figures
(``vcjax.identify.models``, ``manoeuvres``, ``shooting``, ``fit``, ``figures``) on tiny
problems: what a one-step model computes, how logs are cut into segments, the fit's counts,
weights and warnings, and the figures' text. Written for the survivors of the mutation run of
those files (``docs/development/testing.md``, "Mutation testing"); numpy where possible, and
the few JAX programs are one step or a few steps of the 8-state INFANTE-class plant."""

from __future__ import annotations

import dataclasses
import json
import math
import re
import textwrap
from types import SimpleNamespace
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax.identify import fit
from vcjax.identify.data import load_log
from vcjax.identify.figures import cost_history_figure, prediction_figure
from vcjax.identify.fit import CORRELATION_WARN, FitSettings, fit_logs
from vcjax.identify.manoeuvres import (
    SENSOR_NOISE,
    STUDY_PARAMS,
    infante_logs,
    perturbed_params,
    simulate_trial,
)
from vcjax.identify.models import FIT_MODELS, get_fit_model, scalar_fields
from vcjax.identify.shooting import ShootingProblem, make_segments, seg_count
from vcjax.runtime import programs

INFANTE = get_fit_model("infante")
REMUS = get_fit_model("remus100")


# ------------------------------------------------------------------ models


def test_fit_models_are_frozen_and_hashable():
    """A fit model is static: hashable (it keys the program store) and frozen."""
    for model in FIT_MODELS.values():
        assert hash(model) == hash(model)
        with pytest.raises(dataclasses.FrozenInstanceError):
            model.vehicle = "other"


def test_scalar_fields_leave_out_arrays_and_tuples():
    class P(NamedTuple):
        a: float
        b: np.ndarray
        c: tuple
        d: np.ndarray
        e: jnp.ndarray

    p = P(1.0, np.zeros(2), (1.0, 2.0), np.float64(3.0), jnp.ones((2, 2)))
    assert scalar_fields(p) == ("a", "d")
    names = scalar_fields(REMUS.nominal(jnp.float64))
    assert "CD_0" in names and not {"act_max", "cf_x", "T_act", "body"} & set(names)


def _toy_plant(t, s, u, args):
    """A time-varying field on INFANTE's state: ``x_dot = (1 + t) u[0]`` in every entry."""
    return jax.tree.map(lambda a: (1.0 + t) * u[0] * jnp.ones_like(a), s)


@pytest.mark.parametrize("step, increment", [("euler", 1.0), ("heun", 1.25), ("rk4", 1.25)])
def test_an_integrator_step_starts_at_zero_time_and_is_not_pvs(step, increment):
    """One step of ``dt`` integrates the field from t = 0: the integral of ``(1 + t) u0`` is
    ``(dt + dt^2 / 2) u0`` (Heun and RK4 exact; Euler ``dt u0``); ``euler`` and ``heun`` sort
    before ``"pvs"``, which INFANTE does not have."""
    model = dataclasses.replace(INFANTE, plant=_toy_plant)
    p = INFANTE.nominal(jnp.float64)
    x = jnp.arange(8.0)
    got = model.make_step(step)(p, jnp.zeros(2), x, jnp.asarray([2.0, 0.0]), 0.5)
    np.testing.assert_allclose(got, x + 2.0 * 0.5 * increment, rtol=1e-15)


def test_pvs_is_refused_for_infante():
    with pytest.raises(ValueError, match="'pvs' is not available for vehicle 'infante'"):
        INFANTE.make_step("pvs")


@pytest.mark.parametrize("vehicle", ["remus100", "infante"])
def test_make_args_water_is_the_current_with_no_vertical(vehicle):
    model = get_fit_model(vehicle)
    args = model.make_args(model.nominal(jnp.float64), jnp.asarray([0.3, -0.4]))
    np.testing.assert_array_equal(args.water.velocity, [0.3, -0.4, 0.0])
    np.testing.assert_array_equal(args.water.acceleration, np.zeros(3))


def test_remus_actuator_limits_are_the_rudder_and_the_stern_plane():
    p = REMUS.nominal(jnp.float64)._replace(act_max=jnp.asarray([0.1, 0.2, 1500.0]))
    assert REMUS.actuator_limits(p) == {"delta_r": 0.1, "delta_s": 0.2}


# ------------------------------------------------------------------ manoeuvres


def _helm_plant(t, s, u, args):
    """A toy INFANTE-class plant whose trials can be followed by hand: the heading turns at
    minus the commanded rudder angle (positive rudder to port), the x position moves at the
    surge speed (held), y at the water's east velocity, the actuators follow their commands
    at unit rate."""
    vel = args.water.velocity
    eta_dot = jnp.stack([s.nu[0], vel[1], -u[1]])
    return type(s)(eta=eta_dot, nu=jnp.zeros_like(s.nu), act=u - s.act)


@pytest.fixture
def helm(monkeypatch):
    """The INFANTE-class model, its plant replaced by :func:`_helm_plant` (one small program
    per trial)."""
    monkeypatch.setitem(FIT_MODELS, "infante", dataclasses.replace(INFANTE, plant=_helm_plant))
    return INFANTE.nominal(jnp.float64)


def test_the_zigzag_reverses_the_rudder_at_20_degrees_exactly(helm, monkeypatch):
    """With the heading moving at the rudder angle, +-20 deg is reached at exactly 1 s (dt
    0.25 s: sums exact in binary): the rudder reverses at that sample, 2 s later at +20 deg
    again; the thrust command is the trial's, the start straight running at 2.5 m/s."""
    d20 = np.radians(20.0)
    # exact where LLVM optimises (XLA's default level 3, what users run): the tests' level 0
    # (conftest) leaves RK4's sixths one bit short of 20 deg, a sample later than the edge
    from vcjax.runtime import compiler

    monkeypatch.setattr(compiler, "compile_options", lambda: {"xla_backend_optimization_level": 3})
    t, x, u = simulate_trial(helm, "zigzag", dt=0.25, horizon=4.0, thrust=400.0)
    np.testing.assert_array_equal(t, 0.25 * np.arange(17))
    np.testing.assert_array_equal(x[0], [0.0, 0.0, 0.0, 2.5, 0.0, 0.0, 400.0, 0.0])
    assert x[4, 2] == -d20 and x[12, 2] == d20
    np.testing.assert_array_equal(u[:, 1], d20 * np.repeat([1.0, -1.0, 1.0], [4, 8, 5]))
    np.testing.assert_array_equal(u[:, 0], 400.0)
    np.testing.assert_allclose(x[:, 0], 2.5 * t, rtol=1e-14)
    np.testing.assert_array_equal(x[:, 1], 0.0)  # no current


def test_the_turning_circle_puts_the_rudder_to_25_degrees_at_5_s(helm):
    t, x, u = simulate_trial(helm, "turning_circle", dt=0.25, horizon=6.0)
    np.testing.assert_array_equal(u[:, 1], np.where(t >= 5.0, np.radians(25.0), 0.0))
    np.testing.assert_array_equal(u[:, 0], 600.0)
    assert u[20, 1] > 0.0 and u[19, 1] == 0.0


def test_the_speed_steps_are_a_quarter_of_the_horizon_each(helm):
    t, x, u = simulate_trial(helm, "speed_steps", dt=0.25, horizon=8.0, thrust=400.0)
    T = np.repeat([400.0, 600.0, 200.0, 400.0], [8, 8, 8, 9])  # the last sample: level 3 held
    np.testing.assert_array_equal(u[:, 0], T)
    np.testing.assert_array_equal(u[:, 1], 0.0)
    assert t.size == 33


@pytest.mark.parametrize("trial", ["circle", "spiral", "zigzag_10"])  # between the names
def test_an_unknown_trial_is_named(trial):
    with pytest.raises(ValueError, match=f"trial: '{trial}' is not one of"):
        simulate_trial(INFANTE.nominal(jnp.float64), trial, dt=0.5, horizon=1.0)


def test_sensor_noise_is_the_documented_one():
    """``docs/guides/identification.md``: 0.1 m, 0.2 deg, 2 cm/s, 0.1 deg/s, 5 N, 0.2 deg."""
    deg = np.radians(1.0)
    assert SENSOR_NOISE == pytest.approx(
        {"x": 0.1, "y": 0.1, "psi": 0.2 * deg, "u": 0.02, "v": 0.02, "r": 0.1 * deg,
         "thrust": 5.0, "delta": 0.2 * deg},
        rel=1e-15,
    )  # fmt: skip
    assert list(SENSOR_NOISE) == list(INFANTE.state_columns)


def test_perturbed_params_scale_the_named_fields_by_one_plus_or_minus_frac():
    base = INFANTE.nominal(jnp.float64)
    for seed in range(4):
        p = perturbed_params(base, 0.25, seed=seed)
        signs = np.random.default_rng(seed).choice([-1.0, 1.0], size=len(STUDY_PARAMS))
        for name, value in zip(base._fields, base, strict=True):
            want = (
                value * (1.0 + 0.25 * signs[STUDY_PARAMS.index(name)])
                if name in STUDY_PARAMS
                else value
            )
            np.testing.assert_array_equal(getattr(p, name), want, err_msg=name)
    ratios = {
        n: float(getattr(perturbed_params(base, 0.5), n) / getattr(base, n)) for n in STUDY_PARAMS
    }
    assert set(ratios.values()) == {0.5, 1.5}  # the default seed draws both signs
    assert ratios == {
        n: float(getattr(perturbed_params(base, 0.5, seed=0), n) / getattr(base, n))
        for n in STUDY_PARAMS
    }
    assert STUDY_PARAMS == ("X_uu", "Y_uv", "Y_ur", "N_uv", "N_ur", "Y_uudr", "N_uudr", "cf_coeff")


def test_infante_logs_defaults_noise_and_provenance(helm, tmp_path):
    """The defaults: 120 s at 10 Hz, the documented sensor noise drawn from seed 0 (white,
    Gaussian: ``N(0, 1)`` draws times each channel's deviation); ``noise=None``: none."""
    (path,) = infante_logs(helm, tmp_path / "a" / "b", trials=("turning_circle",))
    assert path == tmp_path / "a" / "b" / "infante_turning_circle.csv"
    log = load_log(path, INFANTE.state_columns, INFANTE.command_columns)
    t, x, u = simulate_trial(helm, "turning_circle", 0.1, 120.0)
    np.testing.assert_allclose(log.t, t, rtol=1e-9)
    sig = np.array([SENSOR_NOISE[c] for c in INFANTE.state_columns])
    draws = np.random.default_rng(0).normal(size=x.shape)
    np.testing.assert_allclose((log.x - x) / sig, draws, rtol=1e-6, atol=1e-6 * abs(x).max())
    np.testing.assert_allclose(log.u, u, rtol=1e-9)
    assert log.provenance == (
        f"INFANTE-class turning_circle, rk4, dt 0.1 s, sensor noise {json.dumps(SENSOR_NOISE)}"
    )
    (clean,) = infante_logs(
        helm, tmp_path / "b", dt=0.5, horizon=2.0, noise=None, trials=("zigzag",)
    )
    log = load_log(clean, INFANTE.state_columns, INFANTE.command_columns)
    np.testing.assert_array_equal(log.x[:, 1], 0.0)  # no noise on y (no current)
    assert log.provenance == "INFANTE-class zigzag, rk4, dt 0.5 s, sensor noise {}"


def test_infante_logs_refuse_a_diverged_plant(monkeypatch, tmp_path):
    nan_plant = lambda t, s, u, args: jax.tree.map(lambda a: a * jnp.nan, s)  # noqa: E731
    monkeypatch.setitem(FIT_MODELS, "infante", dataclasses.replace(INFANTE, plant=nan_plant))
    with pytest.raises(ValueError, match="trial 'zigzag': the plant diverged"):
        infante_logs(
            INFANTE.nominal(jnp.float64), tmp_path, dt=0.5, horizon=1.0, trials=("zigzag",)
        )


# ------------------------------------------------------------------ shooting


def _log_of(t, x, u, name="a.csv"):
    return SimpleNamespace(name=name, t=np.asarray(t, float), x=np.asarray(x), u=np.asarray(u))


def test_segments_cut_every_log_and_pad_the_last_one():
    """Two logs of 7 and 4 samples in segments of 3: 3 + 2 segments, the last of each padded
    with its last sample (and its last command and step), masked out."""
    x1, u1 = np.arange(7.0)[:, None] * [1.0, 10.0], np.arange(7.0)[:, None] * [-1.0]
    t1 = np.array([0.0, 1.0, 3.0, 6.0, 10.0, 15.0, 21.0])  # steps 1, 2, ..., 6
    x2, u2 = 100.0 + np.arange(4.0)[:, None] * [1.0, 10.0], 100.0 + np.arange(4.0)[:, None]
    logs = [_log_of(t1, x1, u1), _log_of(0.5 * np.arange(4), x2, u2)]
    assert seg_count(logs, 3) == 5 and seg_count(logs, 7) == 2 and seg_count(logs, 2) == 6
    seg = make_segments(logs, 3)
    np.testing.assert_array_equal(
        seg.y[:, :, 0], [[0, 1, 2], [3, 4, 5], [6, 6, 6], [100, 101, 102], [103, 103, 103]]
    )
    np.testing.assert_array_equal(
        seg.y[:, :, 1], 10.0 * seg.y[:, :, 0] - 900.0 * (seg.y[:, :, 0] >= 100)
    )
    np.testing.assert_array_equal(
        seg.u[:, :, 0], [[0, -1], [-3, -4], [-5, -5], [100, 101], [102, 102]]
    )
    np.testing.assert_array_equal(seg.dt, [[1, 2], [4, 5], [6, 6], [0.5, 0.5], [0.5, 0.5]])
    np.testing.assert_array_equal(seg.mask, [[1, 1, 1], [1, 1, 1], [1, 0, 0], [1, 1, 1], [1, 0, 0]])
    np.testing.assert_array_equal(seg.log_index, [0, 0, 0, 1, 1])
    assert seg.mask.dtype == np.float64
    with pytest.raises(dataclasses.FrozenInstanceError):
        seg.y = seg.y[:1]


def _shoot_plant(t, s, u, args):
    """A toy INFANTE-class plant, linear in two of its coefficients: the x position moves at
    ``cf_coeff / 100`` times the surge speed plus the current's north velocity, y at its east
    velocity, the heading at ``N_uudr / 1000`` times the rudder command; the actuators follow
    their commands at unit rate, the velocities are held."""
    p, vel = args.vehicle, args.water.velocity
    eta_dot = jnp.stack([s.nu[0] * p.cf_coeff / 100.0 + vel[0], vel[1], p.N_uudr / 1e3 * u[1]])
    return type(s)(eta=eta_dot, nu=jnp.zeros_like(s.nu), act=u - s.act)


def _shoot_step(x, u, dt, cf, n_uudr, v_c):
    """One forward-Euler step of :func:`_shoot_plant` in numpy."""
    f = np.zeros(8)
    f[0] = x[3] * cf / 100.0 + v_c[0]
    f[1] = v_c[1]
    f[2] = n_uudr / 1e3 * u[1]
    f[6:] = u - x[6:]
    return x + dt * f


SHOOT_BASE = INFANTE.nominal(jnp.float64)
CF0, N0 = float(SHOOT_BASE.cf_coeff), float(SHOOT_BASE.N_uudr)


@pytest.fixture(scope="module")
def shoot():
    """The toy problem: two coefficients and the current (0.5 m/s towards 0.3 rad), Euler."""
    model = dataclasses.replace(INFANTE, plant=_shoot_plant)
    return ShootingProblem(
        model, "euler", ["cf_coeff", "N_uudr"], SHOOT_BASE, True, current_speed=0.5,
        current_direction=0.3,
    )  # fmt: skip


def test_shooting_problem_names_values_and_scaling(shoot):
    z = np.log([1.25, 0.5, 3.0]).tolist() + [0.25]
    assert shoot.all_names == ("cf_coeff", "N_uudr", "current_speed", "current_direction_deg")
    v = shoot.values(z)
    assert v == pytest.approx(
        {"cf_coeff": 1.25 * CF0, "N_uudr": 0.5 * N0, "current_speed": 1.5,
         "current_direction_deg": np.degrees(0.55)}, rel=1e-14,
    )  # fmt: skip
    np.testing.assert_allclose(
        shoot.scale_jacobian(z), [1.25 * CF0, 0.5 * N0, 1.5, np.degrees(1.0)], rtol=1e-14
    )
    np.testing.assert_allclose(shoot.z_initial(2.0), [np.log(2.0)] * 2 + [0.0, 0.0], rtol=1e-15)
    np.testing.assert_array_equal(shoot.z_initial(), np.zeros(4))  # at the nominal values
    params, v_c = shoot.physical(jnp.asarray(z))
    assert float(params.cf_coeff) == pytest.approx(1.25 * CF0, rel=1e-14)
    assert float(params.N_uudr) == pytest.approx(0.5 * N0, rel=1e-14)
    assert float(params.X_uu) == float(SHOOT_BASE.X_uu)
    np.testing.assert_allclose(v_c, [1.5 * np.cos(0.55), 1.5 * np.sin(0.55)], rtol=1e-14)
    plain = ShootingProblem(INFANTE, "euler", ["cf_coeff"], SHOOT_BASE, current_speed=0.5)
    assert plain.all_names == ("cf_coeff",) and plain.z_initial(0.5).tolist() == [np.log(0.5)]
    assert plain.values([np.log(2.0)]) == {"cf_coeff": pytest.approx(2.0 * CF0, rel=1e-15)}
    np.testing.assert_allclose(plain.scale_jacobian([0.0]), [CF0], rtol=1e-15)
    params, v_c = plain.physical(jnp.asarray([0.0]))
    np.testing.assert_allclose(v_c, [0.5, 0.0], rtol=1e-15)


@pytest.mark.parametrize(
    "names, kw, message",
    [
        (["foo"], {}, "'foo' is not a parameter of vehicle 'infante'; choose from"),
        (["cf_x"], {}, "'cf_x' is not a scalar parameter of vehicle 'infante'"),
        (["x_g"], {}, "'x_g' is 0 in the nominal model"),
        (["X_uu", "N_ur", "X_uu"], {}, "names must be unique"),
        (
            ["X_uu"],
            {"fit_current": True},
            "fit_current needs a positive initial current speed, got 0.0",
        ),
        (["X_uu"], {"fit_current": True, "current_speed": -0.5}, "positive initial current speed"),
    ],
)
def test_shooting_problem_refuses(names, kw, message):
    with pytest.raises(ValueError, match=message):
        ShootingProblem(INFANTE, "euler", names, SHOOT_BASE, **kw)


def _shoot_logs():
    rng = np.random.default_rng(3)
    t1 = 0.25 * np.arange(7)
    x1 = rng.normal(size=(7, 8))
    x1[4, 2] += 2 * np.pi  # a heading logged a turn away: the residual wraps
    x2 = rng.normal(size=(5, 8))
    return [
        _log_of(t1, x1, rng.normal(size=(7, 2))),
        _log_of(0.5 * np.arange(5), x2, rng.normal(size=(5, 2))),
    ]


def test_shooting_residuals_linearisation_and_free_run_by_hand(shoot):
    """Every residual: the segment simulated from its own start ``s_j`` (Euler, in numpy),
    minus the measurement, the heading wrapped, weighted per channel, padding masked; the
    Jacobians against central differences; the free run from each log's first sample. (The
    differentiable ``cost`` is checked in ``tests/test_identify.py``.)"""
    logs = _shoot_logs()
    seg = make_segments(logs, 3)
    z = np.array([np.log(1.25), np.log(0.5), np.log(3.0), 0.25])
    cf, n_uudr, v_c = 1.25 * CF0, 0.5 * N0, 1.5 * np.array([np.cos(0.55), np.sin(0.55)])
    s = seg.y[:, 0, :] + 0.125
    s[1, 2] += 2.775  # a heading 2.9 rad off (wrapped: itself, closer to pi than to 0)
    w = np.arange(1.0, 9.0) / 4.0
    want = np.zeros(seg.y.shape)
    for j in range(seg.y.shape[0]):
        x = s[j]
        for k in range(3):
            d = x - seg.y[j, k]
            d[2] -= 2 * np.pi * np.round(d[2] / (2 * np.pi))
            want[j, k] = d * w * seg.mask[j, k]
            if k < 2:
                x = _shoot_step(x, seg.u[j, k], seg.dt[j, k], cf, n_uudr, v_c)
    r = shoot.residuals(z, s, seg, w)
    assert r.shape == (5, 24)
    np.testing.assert_allclose(r, want.reshape(5, 24), rtol=1e-12, atol=1e-12)
    assert abs(want[1, 1, 2] / w[2]) <= np.pi  # the heading logged a turn away, wrapped
    assert want[1, 0, 2] / w[2] == pytest.approx(2.9, rel=1e-12)
    r2, Jz, Js = shoot.linearize(z, s, seg, w)
    np.testing.assert_allclose(r2, r, rtol=1e-13, atol=1e-13)
    assert Jz.shape == (5, 24, 4) and Js.shape == (5, 24, 8)
    h = 1e-6
    for i in range(4):
        dz = h * np.eye(4)[i]
        fd = (shoot.residuals(z + dz, s, seg, w) - shoot.residuals(z - dz, s, seg, w)) / (2 * h)
        np.testing.assert_allclose(Jz[:, :, i], fd, rtol=1e-6, atol=1e-7)
    for i in (0, 3, 7):
        ds = h * np.eye(8)[i]
        fd = (shoot.residuals(z, s + ds, seg, w) - shoot.residuals(z, s - ds, seg, w)) / (2 * h)
        np.testing.assert_allclose(Js[:, :, i], fd, rtol=1e-6, atol=1e-7)
    for log in logs:
        x, xs = log.x[0], [log.x[0]]
        for k in range(log.t.size - 1):
            x = _shoot_step(x, log.u[k], log.t[k + 1] - log.t[k], cf, n_uudr, v_c)
            xs.append(x)
        np.testing.assert_allclose(shoot.free_run(z, log), xs, rtol=1e-12, atol=1e-12)


# ------------------------------------------------------------------ fit (its helpers, numpy)


def test_non_finite_numbers_become_null_at_any_depth():
    tree = {"a": [1.0, float("nan"), (float("inf"), 2)], "b": {"c": -float("inf"), "d": 3}}
    assert fit._finite_or_none(tree) == {"a": [1.0, None, [None, 2]], "b": {"c": None, "d": 3}}
    assert fit._finite_or_none(float("nan")) is None and fit._finite_or_none(1.5) == 1.5


def test_channel_rms_over_the_real_samples_only():
    phys = np.zeros((2, 3, 2))
    phys[0, 0] = [3.0, 4.0]
    phys[1, 2] = [100.0, 100.0]  # padding
    mask = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert fit._channel_rms(phys, mask, ("a", "b")) == {"a": 3.0, "b": 4.0}
    mask = np.array([[1.0, 1.0, 1.0], [1.0, 0.0, 0.0]])
    assert fit._channel_rms(phys, mask, ("a", "b")) == {"a": 1.5, "b": 2.0}
    assert fit._channel_rms(phys, 0.0 * mask, ("a", "b")) == {"a": 0.0, "b": 0.0}


@pytest.mark.parametrize("c", [0.995, -0.995])
def test_a_correlated_pair_is_named_with_its_signed_correlation(c):
    corr = np.array([[1.0, 0.2, c], [0.2, 1.0, 0.1], [c, 0.1, 1.0]])
    (w,) = fit._identifiability(("a", "b", "c"), corr, np.diag([1e-12, 1.0, 1.0]))
    assert w == (
        f"a and c are not separately identifiable from these data (correlation {c:+.4f}): "
        "only a combination of them is determined"
    )


def test_a_correlation_of_exactly_the_bound_is_not_named():
    corr = np.array([[1.0, 0.99], [0.99, 1.0]])
    assert CORRELATION_WARN == 0.99
    assert fit._identifiability(("a", "b"), corr, np.eye(2)) == []


def test_a_near_null_direction_of_three_or_more_is_named():
    """Eigenvalue ratio below 1e-10 with no correlated pair: the parameters with an
    eigenvector component above 0.1 in magnitude, and the condition number."""
    v = np.array([0.6, -0.8, 0.0])  # the null direction: a and b
    Q = np.column_stack([v, [0.8, 0.6, 0.0], [0.0, 0.0, 1.0]])
    for lam0, warned in [(0.5e-10, True), (2e-10, False)]:
        info = Q @ np.diag([4 * lam0, 4.0, 2.0]) @ Q.T  # the largest eigenvalue 4, not 1
        out = fit._identifiability(("a", "b", "c"), np.eye(3), info)
        assert out == (
            [
                "parameters ['a', 'b'] are not separately identifiable from these data "
                f"(information matrix condition number {1.0 / lam0:.2g})"
            ]
            if warned
            else []
        )
    exact = np.diag([1e-10, 1.0, 1.0])  # a ratio of exactly 1e-10: not below it
    assert fit._identifiability(("a", "b", "c"), np.eye(3), exact) == []
    info2 = np.diag([1e-14, 1.0])  # two parameters: the correlation speaks for them
    assert fit._identifiability(("a", "b"), np.eye(2), info2) == []
    v = np.array([0.995, 0.0999, 0.0])  # |component| 0.0999: not involved
    v /= np.linalg.norm(v)
    u2 = np.array([-v[1], v[0], 0.0])
    Q = np.column_stack([v, u2, [0.0, 0.0, 1.0]])
    out = fit._identifiability(("a", "b", "c"), np.eye(3), Q @ np.diag([1e-14, 1.0, 1.0]) @ Q.T)
    assert out[0].startswith("parameters ['a'] are not")
    for lam0 in (0.0, -1e-20):  # a singular (or rounding-negative) information: capped
        out = fit._identifiability(("a", "b", "c"), np.eye(3), np.diag([lam0, 1.0, 2.0]))
        assert out == [
            "parameters ['a'] are not separately identifiable from these data "
            "(information matrix condition number 2e+300)"
        ]


def _inputs(**kw):
    log = SimpleNamespace(name="a.csv", x=np.zeros((5, 8)), u=np.zeros((5, 2)))
    args = {"logs": [log], "params": ["X_uu"], "o": FitSettings(), **kw}
    fit._check_inputs(INFANTE, args["logs"], args["params"], args["o"])


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"logs": []}, "files: no logs given"),
        ({"o": FitSettings(segment_steps=1)}, "segment_steps: expected an int >= 2, got 1"),
        ({"o": FitSettings(segment_steps=2.0)}, "segment_steps: expected an int >= 2, got 2.0"),
        ({"o": FitSettings(max_iters=0)}, "max_iters: expected an int >= 1, got 0"),
        ({"o": FitSettings(max_iters=1.0)}, "max_iters: expected an int >= 1, got 1.0"),
        ({"o": FitSettings(initial_scale=0.0)}, "initial_scale: expected a finite value > 0"),
        ({"o": FitSettings(initial_scale=-1.0)}, "initial_scale: expected a finite value > 0"),
        ({"o": FitSettings(initial_scale=math.inf)}, "initial_scale: expected a finite value"),
        ({"o": FitSettings(initial_scale=math.nan)}, "initial_scale: expected a finite value"),
        ({"params": []}, "params: nothing to fit"),
        ({"logs": [SimpleNamespace(name="b.csv", x=np.zeros((5, 7)), u=np.zeros((5, 2)))]},
         "b.csv: state/command columns do not match 'infante'"),
        ({"logs": [SimpleNamespace(name="b.csv", x=np.zeros((5, 8)), u=np.zeros((5, 3)))]},
         "b.csv: state/command columns do not match 'infante'"),
        ({"logs": [SimpleNamespace(name="b.csv", x=np.zeros((5, 9)), u=np.zeros((5, 2)))]},
         "b.csv: state/command columns do not match 'infante'"),
        ({"logs": [SimpleNamespace(name="b.csv", x=np.zeros((5, 8)), u=np.zeros((5, 1)))]},
         "b.csv: state/command columns do not match 'infante'"),
    ],
)  # fmt: skip
def test_fit_inputs_are_checked_before_the_data(kw, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        _inputs(**kw)


@pytest.mark.parametrize(
    "kw",
    [
        {},
        {"o": FitSettings(segment_steps=2, max_iters=1, initial_scale=1e-3)},
        {"params": [], "o": FitSettings(fit_current=True, current_speed=0.5)},
    ],
)
def test_fit_inputs_at_their_bounds_are_accepted(kw):
    _inputs(**kw)


def test_fit_shots_count_the_degrees_of_freedom_and_the_noise():
    """Two logs of 5 and 4 samples in segments of 3 (J = 4, 9 real samples): m = 9 n_x
    residuals for 2 + 4 n_x unknowns; the noise per channel is the RMS of the real physical
    residuals times the degrees-of-freedom factor's root; a channel constant over every log
    has spread 1; no degree of freedom left is refused."""
    logs = [
        _log_of(np.arange(5.0), np.arange(40.0).reshape(5, 8) ** 2, np.zeros((5, 2))),
        _log_of(np.arange(4.0), np.ones((4, 8)), np.zeros((4, 2))),
    ]
    logs[0].x[:, 5] = 7.0
    logs[1].x[:, 5] = 7.0
    logs[0].x[:, 4] = [0.0, 0.25, 0.0, 0.25, 0.0]  # a spread below 1: kept
    logs[1].x[:, 4] = 0.25
    sh = fit._shots(INFANTE, logs, FitSettings(segment_steps=3), 2)
    assert sh.n_real == 9.0 and sh.m == 72.0 and sh.n_par == 2 + 4 * 8
    assert sh.dof_factor == 72.0 / 38.0
    spread = np.std(np.concatenate([logs[0].x, logs[1].x]), axis=0)
    np.testing.assert_array_equal(sh.spread, np.where(np.arange(8) == 5, 1.0, spread))
    w = np.arange(1.0, 9.0)
    r = np.ones((4, 3, 8)) * w  # every physical residual 1 ...
    r[1, 2] = 1e6 * w  # ... but the padding of the first log's last segment (3, 4, pad)
    r[3, 1:] = 1e6 * w  # ... and of the second's (3, pad, pad)
    np.testing.assert_allclose(sh.noise(r.reshape(4, 24), w), np.sqrt(72 / 38), rtol=1e-14)
    one = [_log_of(np.arange(4.0), np.arange(32.0).reshape(4, 8), np.zeros((4, 2)))]
    with pytest.raises(
        ValueError,
        match=re.escape(
            "segment_steps: 2 leaves no residual degrees of freedom (32 residuals for 32 unknowns)"
        ),
    ):
        fit._shots(INFANTE, one, FitSettings(segment_steps=2), 16)
    assert fit._shots(INFANTE, one, FitSettings(segment_steps=2), 15).dof_factor == 32.0
    with pytest.raises(ValueError, match=re.escape("(32 residuals for 33 unknowns)")):
        fit._shots(INFANTE, one, FitSettings(segment_steps=2), 17)


def test_fit_ending_warnings():
    res = SimpleNamespace(reason="interrupted", converged=False)
    assert fit._ending(res, [3, 4], FitSettings()) == [
        "interrupted after 7 iterations: the estimates are the last accepted iterate, "
        "not an optimum"
    ]
    res = SimpleNamespace(reason="max_iters", converged=False)
    assert fit._ending(res, [3], FitSettings(max_iters=9)) == [
        "did not converge in 9 iterations ; raise max_iters"
    ]
    assert fit._ending(SimpleNamespace(reason="ftol", converged=True), [3], FitSettings()) == []


def test_shooting_programs_come_from_the_store_once_per_argument_shape(shoot, tmp_path):
    """With the program store on (the command line), each of the problem's programs is built
    through the store once per argument shape and gives what its jitted form gives."""
    logs = _shoot_logs()
    seg = make_segments(logs, 3)
    z, s, w = np.array([0.1, -0.2, 0.3, 0.1]), seg.y[:, 0, :], np.ones(8)
    want_r, want_free = shoot.residuals(z, s, seg, w), shoot.free_run(z, logs[0])
    before = programs.store_dir()
    programs.set_store(tmp_path / "programs")
    try:
        if programs.store_dir() is None:
            pytest.skip(f"the program store is off: {programs.off_reason()}")
        prob = ShootingProblem(
            shoot.model, "euler", shoot.names, SHOOT_BASE, True, 0.5, 0.3
        )  # a problem with no program built yet
        for _ in range(2):
            np.testing.assert_array_equal(prob.residuals(z, s, seg, w), want_r)
            np.testing.assert_array_equal(prob.free_run(z, logs[0]), want_free)
        prob.free_run(z, logs[1])  # another length: another program
        names = sorted(e["name"] for e in programs.report())
        assert names == ["fit:free_run", "fit:free_run", "fit:residuals"]
    finally:
        programs.set_store(before)


# ------------------------------------------------------------------ fit (a whole toy fit)

TOY_TRUE = {"cf_coeff": 1.25 * CF0, "N_uudr": 0.8 * N0}


def _toy_logs():
    """Two noise-free logs of the toy plant at the true coefficients (numpy), 40 and 25
    samples at 10 Hz; the second's heading logged a turn away from sample 10 on."""
    logs = []
    for n, phase in [(40, 0.0), (25, 1.0)]:
        k = np.arange(n)
        u = np.column_stack([np.full(n, 500.0), 0.2 * np.sin(0.3 * k + phase)])
        x = np.zeros((n, 8))
        x[0] = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 500.0, 0.0]
        for i in range(n - 1):
            x[i + 1] = _shoot_step(
                x[i], u[i], 0.1, TOY_TRUE["cf_coeff"], TOY_TRUE["N_uudr"], (0, 0)
            )
        logs.append(_log_of(0.1 * k, x, u, name=f"toy{n}.csv"))
    logs[1].x[10:, 2] += 2 * np.pi
    return logs


def _toy_run(log, cf, n_uudr):
    xs = [log.x[0]]
    for i in range(log.t.size - 1):
        xs.append(_shoot_step(xs[-1], log.u[i], 0.1, cf, n_uudr, (0, 0)))
    return np.array(xs)


@pytest.fixture(scope="module")
def toy_fit():
    model = dataclasses.replace(INFANTE, plant=_shoot_plant)
    logs = _toy_logs()
    res = fit_logs(
        model, logs, ["cf_coeff", "N_uudr"], step="euler", segment_steps=10, base=SHOOT_BASE,
        initial_scale=1.1, max_iters=20,
    )  # fmt: skip
    return logs, res


def test_a_noise_free_toy_fit_recovers_the_truth_in_one_stage(toy_fit):
    logs, res = toy_fit
    assert res.estimates == pytest.approx(TOY_TRUE, rel=1e-9)
    assert res.initial == pytest.approx({"cf_coeff": 1.1 * CF0, "N_uudr": 1.1 * N0}, rel=1e-14)
    assert res.nominal == pytest.approx({"cf_coeff": CF0, "N_uudr": N0}, rel=1e-15)
    assert (res.samples, res.segments) == (65, 4 + 3)
    assert len(res.stage_iterations) == 1 and res.iterations == res.stage_iterations[0] >= 1
    assert len(res.cost_history) == res.iterations + 1
    assert res.converged is True and res.warnings == [] and res.reason != "interrupted"
    spread = np.std(np.concatenate([log.x for log in logs]), axis=0)
    np.testing.assert_array_equal(res.weights, 1.0 / np.where(spread > 0, spread, 1.0))
    assert res.s.shape == (7, 8) and set(res.sensitivity) == set(TOY_TRUE)
    assert all(v > 0 for v in res.sensitivity.values())
    assert max(res.residual_rms_after.values()) < 1e-9
    assert max(res.free_run_rms_after.values()) < 1e-9  # the heading's turn wrapped away
    assert max(res.noise_std.values()) < 1e-9
    assert 0.0 < res.wall_time_s < 600.0
    assert "problem=" not in repr(res) and "estimates=" in repr(res)


def test_the_toy_fits_rms_before_by_hand(toy_fit):
    """The residual RMS of the segments from the measured samples and the free-run RMS, both
    at the initial guess, per channel (numpy, the heading wrapped)."""
    logs, res = toy_fit
    cf, n_uudr = 1.1 * CF0, 1.1 * N0
    seg = make_segments(logs, 10)
    sq = np.zeros(8)
    for j in range(seg.y.shape[0]):
        x = seg.y[j, 0]
        for k in range(10):
            d = x - seg.y[j, k]
            d[2] = (d[2] + np.pi) % (2 * np.pi) - np.pi
            sq += seg.mask[j, k] * d**2
            if k < 9:
                x = _shoot_step(x, seg.u[j, k], seg.dt[j, k], cf, n_uudr, (0, 0))
    cols = INFANTE.state_columns
    assert res.residual_rms_before == pytest.approx(
        dict(zip(cols, np.sqrt(sq / 65), strict=True)), rel=1e-9, abs=1e-15
    )
    d = np.concatenate([_toy_run(log, cf, n_uudr) - log.x for log in logs])
    d[:, 2] = (d[:, 2] + np.pi) % (2 * np.pi) - np.pi
    want = dict(zip(cols, np.sqrt(np.mean(d**2, axis=0)), strict=True))
    assert res.free_run_rms_before == pytest.approx(want, rel=1e-9, abs=1e-15)
    assert res.free_run_rms_before["psi"] < 1.0  # not the 2 pi turn
    # the first cost: the spread weights, the segments from the measured samples
    assert res.cost_history[0] == pytest.approx(0.5 * np.sum(sq * res.weights**2), rel=1e-9)


def test_the_toy_fits_json(toy_fit):
    _, res = toy_fit
    out = res.to_json()
    assert list(out) == [
        "vehicle", "step", "estimates", "std", "initial", "nominal", "correlation",
        "residual_rms", "free_run_rms", "noise_std", "units", "cost_history", "iterations",
        "stage_iterations", "converged", "reason", "wall_time_s", "segments", "samples",
        "warnings", "sensitivity",
    ]  # fmt: skip
    assert (out["vehicle"], out["step"], out["segments"], out["samples"]) == (
        "infante",
        "euler",
        7,
        65,
    )
    assert out["estimates"] == res.estimates and out["std"] == res.std
    assert out["correlation"]["names"] == ["cf_coeff", "N_uudr"]
    np.testing.assert_array_equal(out["correlation"]["matrix"], np.round(res.correlation, 6))
    assert out["units"] == dict(zip(INFANTE.state_columns, INFANTE.units, strict=True))
    assert out["residual_rms"] == {
        "before": res.residual_rms_before,
        "after": res.residual_rms_after,
    }
    assert out["free_run_rms"]["before"] == res.free_run_rms_before
    assert out["wall_time_s"] == round(res.wall_time_s, 3)
    assert out["converged"] is True and out["iterations"] == res.iterations
    corr = np.array([[1.0, -0.123456789], [-0.123456789, 1.0]])
    out = dataclasses.replace(res, correlation=corr, wall_time_s=12.3456789).to_json()
    assert out["correlation"]["matrix"] == [[1.0, -0.123457], [-0.123457, 1.0]]
    assert out["wall_time_s"] == 12.346


# ------------------------------------------------------------------ figures (matplotlib only)


@pytest.fixture
def saved(monkeypatch):
    """The figures' ``savefig_atomic``, recording ``(fig, path, kwargs)`` instead of writing."""
    from vcjax.runtime import outputs

    out = []
    monkeypatch.setattr(
        outputs, "savefig_atomic", lambda fig, path, **kw: out.append((fig, path, kw))
    )
    return out


def _result(warnings=(), converged=True):
    return SimpleNamespace(
        problem=SimpleNamespace(model=INFANTE, step_name="rk4"), warnings=list(warnings),
        converged=converged, cost_history=[8.0, 4.0, 2.0, 1.0, 0.5, 0.0], stage_iterations=[2, 2],
        iterations=4, wall_time_s=1.26,
    )  # fmt: skip


def test_the_prediction_figure_shows_every_channel_in_display_units(saved, tmp_path):
    t = 0.5 * np.arange(4)
    x = np.arange(32.0).reshape(4, 8)
    log = SimpleNamespace(name="a.csv", t=t, x=x)
    path = prediction_figure(_result(), log, 2.0 * x, 3.0 * x, tmp_path / "p.png")
    assert path == tmp_path / "p.png"
    ((fig, p, kw),) = saved
    assert p == tmp_path / "p.png" and kw == {"dpi": 120}
    np.testing.assert_array_equal(fig.get_size_inches(), [12.0, 2.1 * 3])
    axes = fig.axes
    assert len(axes) == 9 and [a.get_visible() for a in axes] == [True] * 8 + [False]
    assert fig._suptitle.get_text() == (
        "a.csv: measured vs free simulation from the first sample (infante, step 'rk4')"
    )
    labels = ["x [m]", "y [m]", "psi [deg]", "u [m/s]", "v [m/s]", "r [deg/s]", "thrust [N]", "delta [deg]"]  # fmt: skip
    for i, ax in enumerate(axes[:8]):
        assert ax.get_ylabel() == labels[i]
        conv = np.degrees(1.0) if "deg" in labels[i] else 1.0
        measured, initial, fitted = ax.lines
        for line, k in [(measured, 1.0), (initial, 2.0), (fitted, 3.0)]:
            np.testing.assert_array_equal(line.get_xdata(), t)
            np.testing.assert_allclose(line.get_ydata(), k * x[:, i] * conv, rtol=1e-15)
        assert (measured.get_label(), initial.get_label(), fitted.get_label()) == (
            "measured",
            "initial model",
            "fitted model",
        )
        assert (measured.get_color(), measured.get_linewidth(), measured.get_alpha()) == (
            "0.5",
            2.2,
            0.6,
        )
        assert (initial.get_color(), initial.get_linestyle(), initial.get_linewidth()) == (
            "C3",
            ":",
            1.2,
        )
        assert (fitted.get_color(), fitted.get_linestyle(), fitted.get_linewidth()) == (
            "C0",
            "--",
            1.2,
        )
        assert ax.get_xlabel() == ("t [s]" if i >= 5 else "")  # the bottom of each column
        assert ax.xaxis.get_gridlines()[0].get_alpha() == 0.3
    assert [t.get_text() for t in axes[0].get_legend().get_texts()] == [
        "measured",
        "initial model",
        "fitted model",
    ]
    assert axes[0].get_legend().get_texts()[0].get_fontsize() == 8
    assert all(a.get_legend() is None for a in axes[1:])
    assert all(a.xaxis.get_tick_params().get("labelbottom", True) for a in axes[5:8])
    assert fig.texts == [fig._suptitle]  # converged, no warnings


def test_the_cost_history_figure_joins_the_two_stages(saved, tmp_path):
    cost_history_figure(_result(), tmp_path / "c.png")
    ((fig, _, kw),) = saved
    (ax,) = fig.axes
    np.testing.assert_array_equal(fig.get_size_inches(), [7.0, 4.0])
    s1, s2 = ax.lines
    np.testing.assert_array_equal(s1.get_xdata(), [0, 1, 2])
    np.testing.assert_array_equal(s1.get_ydata(), [8.0, 4.0, 2.0])
    np.testing.assert_array_equal(s2.get_xdata(), [3, 4, 5])
    np.testing.assert_array_equal(s2.get_ydata(), [1.0, 0.5, 1e-300])  # a zero cost, floored
    assert (s1.get_marker(), s1.get_linestyle(), s1.get_markersize()) == ("o", "-", 3)
    assert (
        s1.get_label() == "stage 1 (spread weights)" and s2.get_label() == "stage 2 (noise weights)"
    )
    assert ax.get_yscale() == "log" and ax.get_xlabel() == "iteration (both stages)"
    assert ax.get_ylabel() == "cost 0.5 |r|^2 (weighted)"
    assert ax.get_title() == "vcjax fit: cost history (4 iterations, 1.3 s)"
    assert ax.get_legend().get_texts()[0].get_fontsize() == 8 and kw == {"dpi": 120}


@pytest.mark.parametrize("n, converged", [(0, False), (1, True), (5, False), (7, True)])
def test_the_warnings_are_written_in_red_at_the_bottom(saved, tmp_path, n, converged):
    warns = [f"warning number {i}:" + " word" * 40 for i in range(n)]
    cost_history_figure(_result(warns, converged), tmp_path / "c.png")
    ((fig, _, _),) = saved
    lines = ([] if converged else ["NOT CONVERGED / NOT TRUSTWORTHY"]) + [
        f"warning: {w}" for w in warns
    ]
    (text,) = fig.texts
    shown = text.get_text().split("\n")
    assert len(shown) == min(len(lines), 6)
    assert shown == [textwrap.shorten(x, 150, placeholder=" ...") for x in lines[:6]]
    assert max(len(s) for s in shown) == (150 if n else 31)
    assert (text.get_color(), text.get_fontsize(), text.get_position()) == ("C3", 6, (0.01, 0.005))
    assert (text.get_va(), text.get_ha()) == ("bottom", "left")
    bottom = min(0.04 + 0.025 * min(len(lines), 6), 0.3)
    assert fig.subplotpars.bottom >= bottom  # the axes above the text
    assert fig.axes[0].get_position().y0 >= bottom


def test_figures_without_warnings_use_the_whole_height(saved, tmp_path):
    cost_history_figure(_result(), tmp_path / "c.png")
    ((fig, _, _),) = saved
    assert fig.texts == [] and fig.axes[0].get_position().y0 < 0.15


def test_fit_settings_defaults_and_frozen():
    assert dataclasses.asdict(FitSettings()) == {
        "step": "rk4", "fit_current": False, "current_speed": 0.0, "current_direction": 0.0,
        "initial_scale": 1.0, "segment_steps": 50, "max_iters": 50, "base": None, "dtype": None,
        "max_memory_gb": None,
    }  # fmt: skip
    with pytest.raises(dataclasses.FrozenInstanceError):
        FitSettings().max_iters = 3


def test_a_noisy_toy_fit_reweights_in_a_second_stage():
    """Noise on the positions: stage 1 (spread weights) leaves residuals well above round-off,
    so stage 2 runs with the noise weights; the callback hears both stages, in order."""
    logs = _toy_logs()
    rng = np.random.default_rng(7)
    for log in logs:
        log.x[:, :2] += 0.01 * rng.normal(size=(log.t.size, 2))
    model = dataclasses.replace(INFANTE, plant=_shoot_plant)
    stages = []
    res = fit_logs(
        model, logs, ["cf_coeff", "N_uudr"], step="euler", segment_steps=10, base=SHOOT_BASE,
        initial_scale=1.1, max_iters=20, callback=lambda stage, it, c, lam: stages.append(stage),
    )  # fmt: skip
    assert len(res.stage_iterations) == 2 and stages == sorted(stages) and set(stages) == {1, 2}
    assert stages.count(1) == res.stage_iterations[0] and res.reason != "interrupted"
    assert res.noise_std["x"] == pytest.approx(0.01, rel=0.5)


def test_an_interrupted_toy_fit_stops_after_its_first_stage():
    """A stop requested during stage 1 (the command line's Ctrl-C) ends the fit there: no
    second stage, the last accepted iterate, the warning that says so."""
    from vcjax.runtime import interrupts

    model = dataclasses.replace(INFANTE, plant=_shoot_plant)
    try:
        res = fit_logs(
            model, _toy_logs(), ["cf_coeff", "N_uudr"], step="euler", segment_steps=10,
            base=SHOOT_BASE, initial_scale=1.1, max_iters=20,
            callback=lambda stage, it, c, lam: interrupts.request_stop(),
        )  # fmt: skip
    finally:
        interrupts._stop.clear()
        interrupts._stop_signal.clear()
    assert res.reason == "interrupted" and res.stage_iterations == [1]
    assert res.converged is False
    assert (
        "interrupted after 1 iterations: the estimates are the last accepted iterate"
        in res.warnings[-1]
    )
