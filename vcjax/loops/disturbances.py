"""[`simulate`][vcjax.loops.disturbances.simulate], which rolls any loop out in its environment: the
components of
[`vcjax.environment`][vcjax.environment] (``Scenario.environment``, and the older
[`Disturbances`][vcjax.loops.disturbances.Disturbances]
— a Gauss–Markov current, sensor noise — and ``Scenario.sea`` mapped onto them), their
processes through [`vcjax.rollout.rollout`][vcjax.rollout.rollout]'s exogenous hook, the water
inside the plant's
vector field."""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax.environment import (
    Environment,
    GaussMarkov,
    GaussMarkovParams,
    NoiseParams,
    SeaParams,
    SensorNoise,
    Waves,
)
from vcjax.environment.current import GaussMarkovCurrent
from vcjax.loops.loop import Loop
from vcjax.loops.scenario import check_disturbances, check_environment
from vcjax.loops.types import Scenario, Water
from vcjax.rollout import Reduction, RolloutConfig, rollout, rollout_reduce

__all__ = ["Disturbances", "DisturbanceParams", "gauss_markov_params", "simulate"]


@dataclasses.dataclass(frozen=True)
class Disturbances:
    """Static choice of the disturbances wrapped around a loop.

    Attributes:
        gauss_markov: the horizontal current is the Gauss–Markov process of
            [`vcjax.environment.current`][vcjax.environment.current] around ``Scenario.current``
            (per-step, exact
            discretisation, linear between samples); False: the constant ``Scenario.current``.
        sensor_noise: white Gaussian noise on what the controller measures
            ([`Loop.measure`][vcjax.loops.loop.Loop.measure]), drawn per step from ``fold_in(key,
            k)`` and held.
    """

    gauss_markov: bool = False
    sensor_noise: bool = False

    @property
    def active(self) -> bool:
        return self.gauss_markov or self.sensor_noise


class DisturbanceParams(NamedTuple):
    """Traced parameters of [`Disturbances`][vcjax.loops.disturbances.Disturbances].

    Attributes:
        current: [`GaussMarkovCurrent`][vcjax.environment.current.GaussMarkovCurrent] (mean: the
            horizontal part
            of ``Scenario.current``); noise_std: (n,) sensor-noise standard deviations;
        key: (2,) PRNG key of the run's random processes.
    """

    current: Any
    noise_std: Any
    key: Any


@dataclasses.dataclass(frozen=True)
class _Wrapped:
    """The loop in its environment (static: the loop and the components). Processes advance
    through the rollout's exogenous hook (once per step); uniform currents and fields are
    evaluated in every integrator stage (the fields at the vehicle's position); noise is added
    to what the controller measures."""

    loop: Loop
    comps: tuple

    def _varying(self):
        return any(c.kind == "varying_current" for c in self.comps)

    def exogenous(self, k, t, s, plant_params, ctrl_params):
        args, env_params, base, dt, _ = plant_params
        ctrl, _ = ctrl_params
        states, held, j = [], [], 0
        for c, p in zip(self.comps, env_params, strict=True):
            h = None
            if c.process:
                s_j, h = c.advance(p, s[j], k, t, dt)
                states.append(s_j)
                j += 1
            held.append(h)
        held = tuple(held)
        return tuple(states), (args, env_params, base, dt, held), (ctrl, (env_params, held))

    def plant(self, t, x, u, params):
        args, env_params, base, _, held = params
        held = (None,) * len(self.comps) if held is None else held
        cur, cur_dot, fields = base, None, []
        for c, p, h in zip(self.comps, env_params, held, strict=True):
            if c.kind == "varying_current":
                v, a = c.water(p, h, t, None, cur)
                cur, cur_dot = cur + v, a if cur_dot is None else cur_dot + a
            elif c.kind == "waves":
                fields.append((c, p, h))
        if self._varying():
            args = self.loop.with_current(args, cur, cur_dot)
        if fields:
            return self.loop.plant_in_sea(t, x, u, args, Water(tuple(fields), cur, cur_dot))
        return self.loop.plant(t, x, u, args)

    def control(self, t, x, z, params):
        ctrl, (env_params, held) = params
        held = (None,) * len(self.comps) if held is None else held
        noise = None
        for c, p, h in zip(self.comps, env_params, held, strict=True):
            if c.kind == "noise":
                n = c.noise(p, h)
                noise = n if noise is None else noise + n
        if noise is not None:
            x = self.loop.measure(x, noise)
        return self.loop.control(t, x, z, ctrl)


def _process_keys(key):
    """(current, noise) keys of a run (the current's: ``split`` into its initial draw and its
    steps, see ``gm_sample_path``)."""
    k_cur, k_noise = jax.random.split(key)
    return k_cur, k_noise


def _environment(loop: Loop, sc: Scenario, dist: Disturbances, dist_params):
    """``(Environment, base current (3,))`` of a run: the
    [`Disturbances`][vcjax.loops.disturbances.Disturbances] and the
    scenario's sea as components, then the scenario's own ``Scenario.environment``."""
    comps, params = [], []
    base = sc.current
    dtype = sc.eta0.dtype
    if dist.active:
        if dist_params is None:
            raise ValueError("dist_params: required with disturbances")
        k_cur, k_noise = _process_keys(dist_params.key)
        if dist.gauss_markov:  # its mean is the scenario's current: it replaces it
            comps.append(GaussMarkov())
            params.append(GaussMarkovParams(dist_params.current, sc.current[2:], k_cur))
            base = jnp.zeros(3, dtype)
        if dist.sensor_noise:
            comps.append(SensorNoise().bind(loop))
            params.append(NoiseParams(dist_params.noise_std, k_noise))
    if sc.sea is not None:
        depth = jnp.zeros((), dtype) if sc.origin_depth is None else sc.origin_depth
        comps.append(Waves())
        params.append(SeaParams(sc.sea, depth))
    env = Environment(comps, params)
    if sc.environment is not None:
        env = env + sc.environment
    return env, base


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

    ``loop``, ``config``, ``dist`` and the components of ``sc.environment`` are static;
    ``gains``, ``sc`` (the components' parameters included), ``dt`` and ``dist_params`` are
    traced. Without an environment this is one [`vcjax.rollout.rollout`][vcjax.rollout.rollout] of
    ``loop.plant`` / ``loop.control``. Otherwise every component enters through the one seam
    ([`vcjax.environment`][vcjax.environment]): processes (a Gauss–Markov current, sensor noise)
    advance once
    per step through the rollout's ``exogenous`` hook; uniform currents reach the plant through
    [`Loop.plant_args`][vcjax.loops.loop.Loop.plant_args] (constant) or
    [`Loop.with_current`][vcjax.loops.loop.Loop.with_current] (time-varying, every stage);
    water that varies in space (a sea: ``sc.sea`` or a ``"waves"`` component) is evaluated at
    the vehicle's position in every stage
    ([`Loop.plant_in_sea`][vcjax.loops.loop.Loop.plant_in_sea]; a calm sea gives exactly
    the run without one); forces add to ``Scenario.disturbance``; noise is added to what
    the controller measures ([`Loop.measure`][vcjax.loops.loop.Loop.measure]).
    ``dist``/``dist_params`` (a Gauss–Markov
    current around ``sc.current`` and sensor noise) are mapped onto the same components. A
    component the loop cannot feel raises ``ValueError`` naming it before any work.

    Returns the [`Trajectory`][vcjax.rollout.Trajectory]; with a ``reduction``
    ([`Reduction`][vcjax.rollout.Reduction]) the record is folded segment by segment instead
    ([`rollout_reduce`][vcjax.rollout.rollout_reduce]) and ``(acc, outs)`` is returned.
    """
    if dist.gauss_markov and not loop.can_feel("varying_current"):
        raise ValueError(
            f"current: the {loop.vehicle or type(loop).__name__} loop cannot take a "
            "time-varying (Gauss-Markov) current"
        )
    if sc.sea is not None:
        check_disturbances(loop, False, False, waves=True)
    env, base = _environment(loop, sc, dist, dist_params)
    check_environment(loop, env)
    run = rollout if reduction is None else functools.partial(rollout_reduce, reduction=reduction)
    x0, z0 = loop.initial_state(sc)
    ctrl = loop.ctrl_params(gains, sc)
    dtype = sc.eta0.dtype
    zero = jnp.zeros(3, dtype)
    if not len(env):
        args = loop.plant_args(sc, sc.current, zero)
        return run(loop.plant, loop.control, config, args, ctrl, x0, z0, dt)
    forces = [c.force(p) for c, p in env if c.kind == "force"]
    if forces:
        sc = sc._replace(disturbance=functools.reduce(jnp.add, forces, sc.disturbance))
    for c, p in env:  # constant uniform currents: once
        if c.kind == "current":
            base = base + c.water(p, None, jnp.zeros((), dtype), zero, base)[0]
    args = loop.plant_args(sc, base, zero)
    w = _Wrapped(loop, env.components)
    if not any(c.process for c in env.components):
        plant_params = (args, env.params, base, dt, None)
        return run(w.plant, w.control, config, plant_params, (ctrl, (env.params, None)), x0, z0, dt)
    dt = jnp.asarray(dt, dtype)
    s0 = tuple(c.init(p) for c, p in env if c.process)
    plant_params = (args, env.params, base, dt, None)
    ctrl_params = (ctrl, (env.params, None))
    hook = {"exogenous": w.exogenous, "s0": s0}
    return run(w.plant, w.control, config, plant_params, ctrl_params, x0, z0, dt, **hook)


def gauss_markov_params(sc: Scenario, sigma, tau, max_speed) -> GaussMarkovCurrent:
    """The Gauss–Markov current around the horizontal part of ``sc.current``."""
    return GaussMarkovCurrent(sc.current[:2], sigma, tau, max_speed)
