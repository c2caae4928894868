"""Ocean currents in the horizontal plane: constant and first-order Gauss–Markov.

Units and frames: a current ``V_c`` is a (2,) velocity in the inertial NED frame [m/s] (north,
east), the quantity [`PlantArgs`][vcjax.vehicles.infante.PlantArgs] takes. A *direction* is the
oceanographic one: the direction the water flows **towards**, measured clockwise from north
[rad] (the paper's current ``[0, 0.5]`` m/s has direction ``pi/2``, "towards east").

Slowly varying current (docs/method.md, Sec. 4.2: "constant or slowly varying"): the mean current
plus a
fluctuation ``d`` (2,) whose components are independent first-order Gauss–Markov (Ornstein–
Uhlenbeck) processes::

    dd = -d / T dt + q dW,          q = sigma * sqrt(2 / T),

with correlation time ``T`` [s] and stationary standard deviation ``sigma`` [m/s] per component
(``q`` [m/s/sqrt(s)]; stationary covariance ``sigma^2 exp(-|tau| / T)``). It is advanced by its
*exact* discretisation over a step ``dt``::

    d_{k+1} = a d_k + sigma sqrt(1 - a^2) xi_k,   a = exp(-dt / T),   xi_k ~ N(0, I_2),

so the sampled process has the continuous one's statistics for any ``dt``. The current handed to
the plant is ``clip(V_mean + d)``: the vector is scaled down to at most ``max_speed`` [m/s]
(the internal state ``d`` is not clipped, so the process itself stays exactly Gauss–Markov).
``d_0`` is drawn from the stationary distribution, so the process is stationary from ``t = 0``.

The noise of step ``k`` comes from ``jax.random.fold_in(key, k)``: a realisation is a pure
function of ``(key, k)``, needs no ``(N, 2)`` array, and is the same whatever the chunking or
sharding of a sweep.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp

from vcjax._checks import check_array, check_positive

__all__ = [
    "current_ned",
    "current_vector",
    "GaussMarkovCurrent",
    "gauss_markov_current",
    "gm_init",
    "gm_step",
    "gm_value",
    "gm_sample_path",
]


def current_ned(speed, direction):
    """(3,) the water's velocity in NED [m/s]: ``speed`` [m/s] flowing towards ``direction``
    [rad, clockwise from north], horizontal (``[V cos(beta), V sin(beta), 0]``).

    The one current convention of vcjax: every loop's [`Scenario`][vcjax.loops.types.Scenario] takes
    this
    vector (planar craft use its first two components). Pure ``jax.numpy``; broadcasts over
    leading axes.
    """
    speed = jnp.asarray(speed)
    direction = jnp.asarray(direction)
    v = current_vector(speed, direction)
    return jnp.concatenate([v, jnp.zeros_like(v[..., :1])], axis=-1)


def current_vector(speed, direction):
    """(2,) horizontal part of [`current_ned`][vcjax.environment.current.current_ned]: north and
    east [m/s] of ``speed`` [m/s]
    flowing towards ``direction`` [rad from north] (what the Gauss–Markov process works on).

    Pure ``jax.numpy``; broadcasts over leading axes of ``speed`` and ``direction``.
    """
    speed = jnp.asarray(speed)
    direction = jnp.asarray(direction)
    return jnp.stack([speed * jnp.cos(direction), speed * jnp.sin(direction)], axis=-1)


class GaussMarkovCurrent(NamedTuple):
    """Traced parameters of a Gauss–Markov current.

    Attributes:
        mean: (2,) mean current in NED [m/s].
        sigma: () stationary standard deviation of each fluctuation component [m/s] (>= 0).
        tau: () correlation time T [s] (> 0).
        max_speed: () bound on the speed of the current handed to the plant [m/s] (> 0).
    """

    mean: Any
    sigma: Any
    tau: Any
    max_speed: Any


def gauss_markov_current(mean=(0.0, 0.5), sigma=0.1, tau=300.0, max_speed=2.0, dtype=None):
    """Validated [`GaussMarkovCurrent`][vcjax.environment.current.GaussMarkovCurrent] (eager; see
    the module docstring for units)."""
    check_array("mean", mean, (2,))
    check_positive("sigma", sigma, (), strict=False)
    check_positive("tau", tau, ())
    check_positive("max_speed", max_speed, ())
    dtype = jnp.asarray(0.0).dtype if dtype is None else jnp.dtype(dtype)
    f = lambda x: jnp.asarray(x, dtype=dtype)
    return GaussMarkovCurrent(f(mean), f(sigma), f(tau), f(max_speed))


def gm_init(p: GaussMarkovCurrent, key):
    """(2,) fluctuation ``d_0`` drawn from the stationary distribution ``N(0, sigma^2 I)``."""
    return p.sigma * jax.random.normal(key, (2,), dtype=p.sigma.dtype)


def gm_step(p: GaussMarkovCurrent, d, dt, key):
    """(2,) ``d_{k+1}`` from ``d_k`` by the exact discretisation over ``dt`` [s]."""
    a = jnp.exp(-dt / p.tau)
    xi = jax.random.normal(key, (2,), dtype=d.dtype)
    return a * d + p.sigma * jnp.sqrt(1.0 - a * a) * xi


def gm_value(p: GaussMarkovCurrent, d):
    """(2,) current handed to the plant: ``V_mean + d`` scaled to at most ``max_speed`` [m/s].

    NaN-free and differentiable at zero current (double ``where`` on the norm).
    """
    v = p.mean + d
    n2 = jnp.sum(v * v)
    safe = jnp.where(n2 > 0, n2, 1.0)
    n = jnp.where(n2 > 0, jnp.sqrt(safe), 0.0)
    scale = jnp.where(n > p.max_speed, p.max_speed / jnp.where(n > 0, n, 1.0), 1.0)
    return v * scale


def gm_sample_path(p: GaussMarkovCurrent, key, dt, num_steps: int, clip: bool = True):
    """(num_steps + 1, 2) one realisation on the grid ``t_k = k dt`` (the sweep's own draws).

    Step ``k`` uses ``fold_in(key_steps, k)`` with ``key_init, key_steps = split(key)``, exactly
    as a Monte-Carlo sweep does; ``clip=False`` returns ``V_mean + d`` unclipped (for tests of
    the process statistics).
    """
    key_init, key_steps = jax.random.split(key)
    d0 = gm_init(p, key_init)
    dt = jnp.asarray(dt, dtype=d0.dtype)

    def step(d, k):
        d_next = gm_step(p, d, dt, jax.random.fold_in(key_steps, k))
        return d_next, d_next

    _, ds = jax.lax.scan(step, d0, jnp.arange(num_steps, dtype=jnp.int32))
    ds = jnp.concatenate([d0[None], ds], axis=0)
    if not clip:
        return p.mean + ds
    return jax.vmap(lambda d: gm_value(p, d))(ds)
