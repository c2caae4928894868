"""Batches of Simulation 1 scenarios for robust tuning (random currents and initial offsets).

A compact sampler (``vcjax`` had no Monte-Carlo sweep module when this was written): around the
paper's Simulation 1 (path ``x = 10 m`` heading east, ``eta0 = [0, 0, pi/2]``, ``nu0 = [2, 0, 0]``)

* current speed ``|V_c| ~ U(0, current_max)`` in a direction ``~ U(0, 2 pi)`` (NED);
* initial position offset ``~ U(-position_offset, position_offset)`` on each of x and y [m];
* initial heading offset ``~ U(-heading_offset, heading_offset)`` [rad].

The batch is a :class:`~vcjax.sim1.Sim1Scenario` whose ``eta0``, ``nu0``, ``V_c`` carry a leading
batch axis; vmap it with :data:`SCENARIO_AXES`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import sim1

__all__ = ["SCENARIO_AXES", "sample_scenarios", "scenario_at", "batch_size"]

#: ``in_axes`` of a sampled batch for ``jax.vmap``
SCENARIO_AXES = sim1.Sim1Scenario(
    eta0=0, nu0=0, V_c=0, u_d=None, vehicle=None, path=None, design_vehicle=None
)


def sample_scenarios(
    seed: int,
    n: int,
    *,
    current_max: float = 1.0,
    position_offset: float = 5.0,
    heading_offset: float = np.pi / 4,
    base: sim1.Sim1Scenario | None = None,
) -> sim1.Sim1Scenario:
    """``n`` random scenarios around ``base`` (default: the paper's Simulation 1).

    Args:
        seed: PRNG seed (different seeds give independent batches: use one for training and
            another for the held-out batch).
        n: batch size.
        current_max: largest current speed [m/s] (speeds are uniform on ``[0, current_max]``).
        position_offset: half-width of the uniform initial x and y offsets [m].
        heading_offset: half-width of the uniform initial heading offset [rad].
        base: the nominal scenario.

    Returns:
        batched :class:`~vcjax.sim1.Sim1Scenario` (``eta0`` (n, 3), ``nu0`` (n, 3), ``V_c``
        (n, 2)).
    """
    if not (isinstance(n, int | np.integer) and n >= 1):
        raise ValueError(f"n: expected a positive int, got {n!r}")
    for name, v in (
        ("current_max", current_max),
        ("position_offset", position_offset),
        ("heading_offset", heading_offset),
    ):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{name}: expected a finite value >= 0, got {v!r}")
    base = sim1.sim1_scenario() if base is None else base
    dtype = base.eta0.dtype
    k_speed, k_dir, k_pos, k_head = jax.random.split(jax.random.PRNGKey(int(seed)), 4)
    speed = current_max * jax.random.uniform(k_speed, (n,), dtype=dtype)
    direction = 2 * np.pi * jax.random.uniform(k_dir, (n,), dtype=dtype)
    V_c = jnp.stack([speed * jnp.cos(direction), speed * jnp.sin(direction)], axis=1)
    d_pos = jax.random.uniform(k_pos, (n, 2), dtype=dtype, minval=-1.0, maxval=1.0)
    d_head = jax.random.uniform(k_head, (n, 1), dtype=dtype, minval=-1.0, maxval=1.0)
    offset = jnp.concatenate([position_offset * d_pos, heading_offset * d_head], axis=1)
    eta0 = base.eta0[None, :] + offset
    nu0 = jnp.broadcast_to(base.nu0, (n, 3))
    return base._replace(eta0=eta0, nu0=nu0, V_c=V_c)


def batch_size(batch: sim1.Sim1Scenario) -> int:
    """Number of scenarios in a batch."""
    return int(batch.eta0.shape[0])


def scenario_at(batch: sim1.Sim1Scenario, i: int) -> sim1.Sim1Scenario:
    """Scenario ``i`` of a batch (unbatched)."""
    return batch._replace(eta0=batch.eta0[i], nu0=batch.nu0[i], V_c=batch.V_c[i])
