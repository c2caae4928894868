"""The identification models, manoeuvres, shooting problem, fit and figures
(``vcjax.identify.models``, ``manoeuvres``, ``shooting``, ``fit``, ``figures``) on tiny
problems: what a one-step model computes, how logs are cut into segments, the fit's counts,
weights and warnings, and the figures' text. Written for the survivors of the mutation run of
those files (``docs/development/testing.md``, "Mutation testing"); numpy where possible, and
the few JAX programs are one step or a few steps of the 8-state INFANTE-class plant."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from vcjax.identify.models import FIT_MODELS, get_fit_model, scalar_fields

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
