"""Disturbances that wrap any loop (a Gauss–Markov current, sensor noise, waves) and
:func:`simulate`, which rolls any loop out with or without them: the current process and the
noise through :func:`vcjax.rollout.rollout`'s exogenous hook, the sea (:attr:`Scenario.sea`)
inside the plant's vector field."""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax.environment.current import GaussMarkovCurrent, gm_init, gm_step, gm_value
from vcjax.loops.loop import Loop
from vcjax.loops.scenario import check_disturbances
from vcjax.loops.types import Scenario, Water
from vcjax.rollout import Reduction, RolloutConfig, rollout, rollout_reduce

__all__ = ["Disturbances", "DisturbanceParams", "gauss_markov_params", "simulate"]


@dataclasses.dataclass(frozen=True)
class Disturbances:
    """Static choice of the disturbances wrapped around a loop.

    Attributes:
        gauss_markov: the horizontal current is the Gauss–Markov process of
            :mod:`vcjax.environment.current` around ``Scenario.current`` (per-step, exact
            discretisation,
            linear between samples); False: the constant ``Scenario.current``.
        sensor_noise: white Gaussian noise on what the controller measures
            (:meth:`Loop.measure`), drawn per step from ``fold_in(key, k)`` and held.
    """

    gauss_markov: bool = False
    sensor_noise: bool = False

    @property
    def active(self) -> bool:
        return self.gauss_markov or self.sensor_noise


class DisturbanceParams(NamedTuple):
    """Traced parameters of :class:`Disturbances`.

    Attributes:
        current: :class:`~vcjax.environment.current.GaussMarkovCurrent` (mean: the horizontal part
        of
            ``Scenario.current``); noise_std: (n,) sensor-noise standard deviations;
        key: (2,) PRNG key of the run's random processes.
    """

    current: Any
    noise_std: Any
    key: Any


@dataclasses.dataclass(frozen=True)
class _Wrapped:
    """The loop with its disturbances: the current process and the noise through the rollout's
    exogenous hook (once per step), the sea inside the plant (every integrator stage)."""

    loop: Loop
    dist: Disturbances
    waves: bool = False

    def exogenous(self, k, t, s, plant_params, ctrl_params):
        args, gm_p, key_steps, dt, current, sea = plant_params
        ctrl, noise_std, key_noise = ctrl_params
        gm = None
        if self.dist.gauss_markov:
            # current on [t_k, t_k + dt]: linear between the exact GM samples, its rate the slope
            d_next = gm_step(gm_p, s, dt, jax.random.fold_in(key_steps, k))
            V0, V1 = gm_value(gm_p, s), gm_value(gm_p, d_next)
            dV = (V1 - V0) / dt
            vertical = current[2:]
            gm = (jnp.concatenate([V0, vertical]), jnp.concatenate([dV, 0 * vertical]))
            s = d_next
        n = None
        if self.dist.sensor_noise:
            n = noise_std * jax.random.normal(
                jax.random.fold_in(key_noise, k), noise_std.shape, noise_std.dtype
            )
        return s, (args, t, gm, current, sea), (ctrl, n)

    def plant(self, t, x, u, params):
        args, t_k, gm, current, sea = params
        current_dot = None
        if gm is not None:
            V, dV = gm
            current, current_dot = V + (t - t_k) * dV, dV
            args = self.loop.with_current(args, current, dV)
        if self.waves:
            sea, origin_depth = sea
            return self.loop.plant_in_sea(
                t, x, u, args, Water(sea, origin_depth, current, current_dot)
            )
        return self.loop.plant(t, x, u, args)

    def control(self, t, x, z, params):
        ctrl, n = params
        if self.dist.sensor_noise:
            x = self.loop.measure(x, n)
        return self.loop.control(t, x, z, ctrl)


def _process_keys(key):
    """(current init, current steps, noise) keys of a run (see ``gm_sample_path``)."""
    k_cur, k_noise = jax.random.split(key)
    k_init, k_steps = jax.random.split(k_cur)
    return k_init, k_steps, k_noise


def simulate(
    loop: Loop,
    gains,
    sc: Scenario,
    config: RolloutConfig,
    dt,
    dist: Disturbances = Disturbances(),
    dist_params: DisturbanceParams | None = None,
    reduction: Reduction | None = None,
):
    """Roll ``loop`` out on scenario ``sc`` (pure, not jitted; vmap/grad it).

    ``loop``, ``config`` and ``dist`` are static; ``gains``, ``sc``, ``dt`` and ``dist_params``
    are traced. Without disturbances and waves this is one :func:`vcjax.rollout.rollout` of
    ``loop.plant`` / ``loop.control``; with them the same loop gets a Gauss–Markov current
    and/or measurement noise through the rollout's ``exogenous`` hook, and, when the scenario
    has a sea (``sc.sea`` not None, a static choice), its plant feels the waves at the
    vehicle's position in every integrator stage (:meth:`Loop.plant_in_sea`; a calm sea gives
    exactly the run without one). A loop that cannot take what is asked raises ``ValueError``
    (``current: ...`` / ``waves: ...``).

    Returns the :class:`~vcjax.rollout.Trajectory`; with a ``reduction``
    (:class:`~vcjax.rollout.Reduction`) the record is folded segment by segment instead
    (:func:`~vcjax.rollout.rollout_reduce`) and ``(acc, outs)`` is returned.
    """
    if dist.gauss_markov and not loop.takes_time_varying_current:
        raise ValueError(
            f"current: the {loop.vehicle or type(loop).__name__} loop cannot take a "
            "time-varying (Gauss-Markov) current"
        )
    waves = sc.sea is not None
    if waves:
        check_disturbances(loop, False, False, waves=True)
    run = rollout if reduction is None else functools.partial(rollout_reduce, reduction=reduction)
    x0, z0 = loop.initial_state(sc)
    ctrl = loop.ctrl_params(gains, sc)
    dtype = sc.eta0.dtype
    if not dist.active and not waves:
        args = loop.plant_args(sc, sc.current, jnp.zeros(3, dtype))
        return run(loop.plant, loop.control, config, args, ctrl, x0, z0, dt)
    w = _Wrapped(loop, dist, waves)
    args = loop.plant_args(sc, sc.current, jnp.zeros(3, dtype))
    sea = None
    if waves:
        depth = jnp.zeros((), dtype) if sc.origin_depth is None else sc.origin_depth
        sea = (sc.sea, depth)
    if not dist.active:  # waves only: no per-step process
        plant_params = (args, None, None, sc.current, sea)
        return run(w.plant, w.control, config, plant_params, (ctrl, None), x0, z0, dt)
    if dist_params is None:
        raise ValueError("dist_params: required with disturbances")
    dt = jnp.asarray(dt, dtype)
    k_init, k_steps, k_noise = _process_keys(dist_params.key)
    gm_p = dist_params.current
    s0 = gm_init(gm_p, k_init) if dist.gauss_markov else None
    plant_params = (args, gm_p, k_steps, dt, sc.current, sea)
    return run(
        w.plant,
        w.control,
        config,
        plant_params,
        (ctrl, dist_params.noise_std, k_noise),
        x0,
        z0,
        dt,
        exogenous=w.exogenous,
        s0=s0,
    )


def gauss_markov_params(sc: Scenario, sigma, tau, max_speed) -> GaussMarkovCurrent:
    """The Gauss–Markov current around the horizontal part of ``sc.current``."""
    return GaussMarkovCurrent(sc.current[:2], sigma, tau, max_speed)
