"""Batches of Simulation 1 scenarios for robust tuning (random currents and initial offsets).

Drawn with the Monte-Carlo sweep API (:func:`vcjax.sweep.sample_scenarios`, so a tuning batch is
exactly the scenarios a ``vcjax sweep`` with the same distribution and seed would run), around the
paper's Simulation 1 (path ``x = 10 m`` heading east, ``eta0 = [0, 0, pi/2]``, ``nu0 = [2, 0, 0]``):

* current speed ``|V_c| ~ U(0, current_max)`` in a direction ``~ U(0, 360 deg)`` (NED);
* initial position offset ``~ U(-position_offset, position_offset)`` on each of x and y [m];
* initial heading offset ``~ U(-heading_offset, heading_offset)`` [rad].

The batch is a :class:`~vcjax.sim1.Sim1Scenario` whose ``eta0``, ``nu0``, ``V_c`` carry a leading
batch axis; vmap it with :data:`SCENARIO_AXES`.
"""

from __future__ import annotations

import math

import numpy as np

from vcjax import sim1, sweep

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
    x0, y0, psi0 = (float(v) for v in np.asarray(base.eta0))
    h = math.degrees(float(heading_offset))
    spec = sweep.ScenarioSpec(
        current_speed=(0.0, float(current_max)),
        current_direction_deg=(0.0, 360.0),
        x0=(x0 - position_offset, x0 + position_offset),
        y0=(y0 - position_offset, y0 + position_offset),
        heading0_deg=(math.degrees(psi0) - h, math.degrees(psi0) + h),
        speed0=(float(base.nu0[0]),) * 2,
        u_d=(float(base.u_d),) * 2,
    )
    mc = sweep.sample_scenarios(spec, int(seed), np.arange(n), dtype=base.eta0.dtype)
    eta0, nu0, V_c = mc.eta0, mc.nu0, mc.V_c
    return base._replace(eta0=eta0, nu0=nu0, V_c=V_c)


def batch_size(batch: sim1.Sim1Scenario) -> int:
    """Number of scenarios in a batch."""
    return int(batch.eta0.shape[0])


def scenario_at(batch: sim1.Sim1Scenario, i: int) -> sim1.Sim1Scenario:
    """Scenario ``i`` of a batch (unbatched)."""
    return batch._replace(eta0=batch.eta0[i], nu0=batch.nu0[i], V_c=batch.V_c[i])
