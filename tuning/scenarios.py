"""Batches of scenarios of any loop for robust tuning (random currents, starts, disturbances,
model errors).

Drawn with the Monte-Carlo sweep API
([`vcjax.sweep.sample_scenarios`][vcjax.sweep.spec.sample_scenarios] and
[`vcjax.sweep.to_scenario`][vcjax.sweep.run.to_scenario]), so a tuning batch is exactly the
scenarios a ``vcjax sweep``
with the same distribution and seed would run. The default distribution, around the loop's
nominal start (Simulation 1: ``eta0 = [0, 0, pi/2]``, ``nu0 = [2, 0, 0]``, path ``x = 10 m``):

* current speed ``~ U(0, current_max)`` in a direction ``~ U(0, 360 deg)`` (NED);
* initial position offset ``~ U(-position_offset, position_offset)`` on each of the loop's
  ``x`` and ``y`` initial keys [m] (where it has them);
* initial heading offset ``~ U(-heading_offset, heading_offset)`` [rad] (``heading_deg`` key);
* anything else a [`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec] describes (``initial`` ranges that
  override the offsets, ``disturbance`` ranges, ``model_error``, a random sea per scenario:
  ``wave_spectrum``, ``wave_hs``, ...) via ``extra``.

The batch is a [`Scenario`][vcjax.loops.types.Scenario] whose fields carry a leading batch axis
except
``path`` and ``design`` (shared); vmap it with ``SCENARIO_AXES``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import numpy as np

from tuning.params import default_loop
from vcjax import loops, sweep
from vcjax.config import Initial
from vcjax.sweep.run import with_environment

__all__ = [
    "SCENARIO_AXES",
    "Nominal",
    "config_spec",
    "scenario_spec",
    "sample_scenarios",
    "scenario_at",
    "batch_size",
    "shard_scenarios",
]

#: ``in_axes`` of a sampled batch for ``jax.vmap``
SCENARIO_AXES = loops.Scenario(
    eta0=0,
    nu0=0,
    current=0,
    u_d=0,
    varpi0=0,
    path=None,
    plant=0,
    design=None,
    disturbance=0,
    sea=0,
    origin_depth=0,
    environment=0,
)


def scenario_spec(
    loop: loops.Loop,
    *,
    current_max: float = 1.0,
    position_offset: float = 5.0,
    heading_offset: float = np.pi / 4,
    extra: dict | None = None,
) -> sweep.ScenarioSpec:
    """The [`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec] of a tuning batch (module docstring);
    ``extra``:
    further ScenarioSpec fields (its ``initial`` entries override the offsets, its
    ``current_speed``/``current_direction_deg`` the ``current_max`` distribution)."""
    for name, v in (
        ("current_max", current_max),
        ("position_offset", position_offset),
        ("heading_offset", heading_offset),
    ):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{name}: expected a finite value >= 0, got {v!r}")
    h = math.degrees(float(heading_offset))
    init = {}
    for k, v0 in loop.initial_keys.items():
        if k in ("x", "y"):
            init[k] = (v0 - position_offset, v0 + position_offset)
        elif k == "heading_deg":
            init[k] = (v0 - h, v0 + h)
    extra = dict(extra or {})
    init |= dict(extra.pop("initial", ()))
    current = {"current_speed": (0.0, float(current_max)), "current_direction_deg": (0.0, 360.0)}
    return sweep.ScenarioSpec(initial=tuple(init.items()), **(current | extra))


@dataclasses.dataclass(frozen=True)
class Nominal:
    """The nominal parameters a batch perturbs: ``plant``, ``design`` (default: the vehicle's;
    ``plant`` defaults to ``design``) and the path ``coeffs`` (default: the vehicle's default
    path's)."""

    plant: Any = None
    design: Any = None
    coeffs: Any = None


def config_spec(cfg, loop: loops.Loop) -> sweep.ScenarioSpec:
    """The [`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec] of a tune config
    ([`TuneConfig`][tuning.spec.TuneConfig]): its parsed sections as they are (``[current]``,
    ``[waves]``, ``[model_error]``, ``[disturbance]``, ``[simulation] u_d``, the environment
    components'), the ``[initial]`` ranges over the ``[scenarios]`` offsets about ``loop``'s
    start."""
    sc = cfg.scenarios
    base = scenario_spec(
        loop,
        current_max=sc.current_max,
        position_offset=sc.position_offset,
        heading_offset=math.radians(sc.heading_offset_deg),
    )
    init = dict(base.initial.values) | dict(cfg.initial)
    return dataclasses.replace(
        base,
        current=cfg.current,
        waves=cfg.waves,
        initial=Initial(values=tuple(init.items())),
        model_error=cfg.model_error,
        disturbance=cfg.disturbance,
        u_d=cfg.simulation.u_d,
        environment=cfg.environment,
    )


def sample_scenarios(
    seed: int,
    n: int,
    spec: sweep.ScenarioSpec | None = None,
    *,
    loop: loops.Loop | None = None,
    nominal: Nominal | None = None,
    dtype=None,
    **distribution,
) -> loops.Scenario:
    """``n`` random scenarios of ``loop`` (default: Simulation 1's).

    Args:
        seed: PRNG seed (different seeds give independent batches: use one for training and
            another for the held-out batch).
        n: batch size.
        spec: the distribution ([`config_spec`][tuning.scenarios.config_spec] of a config);
            default: ``scenario_spec(loop, **distribution)``
            ([`scenario_spec`][tuning.scenarios.scenario_spec]: ``current_max``,
            ``position_offset``, ``heading_offset``, ``extra``).
        loop: the loop (its vehicle's initial keys and parameters).
        nominal: the nominal parameters ([`Nominal`][tuning.scenarios.Nominal]).
        dtype: float dtype (default: the parameters').

    Returns:
        batched [`Scenario`][vcjax.loops.types.Scenario] (see ``SCENARIO_AXES``); the draws of
        scenario ``i`` are a ``vcjax sweep``'s of the same distribution and seed (environment
        components included).
    """
    if not (isinstance(n, int | np.integer) and n >= 1):
        raise ValueError(f"n: expected a positive int, got {n!r}")
    loop = default_loop() if loop is None else loop
    if spec is None:
        spec = scenario_spec(loop, **distribution)
    elif distribution:
        raise TypeError(f"sample_scenarios: spec given, and also {sorted(distribution)}")
    nominal = Nominal() if nominal is None else nominal
    design = loop.default_params(dtype) if nominal.design is None else nominal.design
    plant = design if nominal.plant is None else nominal.plant
    coeffs = type(loop).default_path()[1] if nominal.coeffs is None else nominal.coeffs
    ftype = jax.numpy.asarray(jax.tree_util.tree_leaves(design)[0]).dtype
    coeffs = jax.tree_util.tree_map(lambda a: jax.numpy.asarray(a, ftype), coeffs)
    mc = sweep.sample_scenarios(spec, int(seed), np.arange(n), dtype=ftype, loop=loop)
    cfg = sweep.MCConfig(
        num_steps=1, model_fields=spec.fields_for(loop), environment=spec.environment
    )
    if spec.model_error.relative == 0:
        cfg = dataclasses.replace(cfg, model_fields=())
        mc = mc._replace(model_factors=mc.model_factors[:, :0])
    to = lambda sc: with_environment(
        loop, sweep.to_scenario(loop, sc, plant, design, coeffs, cfg), sc.key, cfg
    )
    return jax.vmap(to, out_axes=SCENARIO_AXES)(mc)


def batch_size(batch: loops.Scenario) -> int:
    """Number of scenarios in a batch."""
    return int(batch.eta0.shape[0])


def scenario_at(batch: loops.Scenario, i: int) -> loops.Scenario:
    """Scenario ``i`` of a batch (unbatched)."""
    return jax.tree_util.tree_map(
        lambda ax, a: a if ax is None else jax.tree_util.tree_map(lambda x: x[i], a),
        SCENARIO_AXES,
        batch,
        is_leaf=lambda x: x is None,
    )


def shard_scenarios(batch: loops.Scenario, devices=None) -> tuple[loops.Scenario, int]:
    """``(batch, n)``: the batched fields sharded along the scenario axis over ``devices``
    (default ``jax.local_devices()``), and the number of devices used.

    Jitted losses and gradients on a sharded batch run on every device (with host CPU devices,
    [`use_cpu_cores`][vcjax.runtime.devices.use_cpu_cores]: every core), the batch mean becoming a
    cross-device
    sum. The batch is left on one device (``n = 1``) when there is one, or when its size is not
    a multiple of the device count (padding would change the mean loss).
    """
    devices = list(jax.local_devices() if devices is None else devices)
    n = len(devices)
    if n < 2 or batch_size(batch) % n:
        return batch, 1
    from jax.sharding import Mesh, NamedSharding, PartitionSpec

    sh = NamedSharding(Mesh(np.asarray(devices), ("scenarios",)), PartitionSpec("scenarios"))
    put = lambda ax, a: a if ax is None else jax.device_put(a, sh)
    return jax.tree_util.tree_map(put, SCENARIO_AXES, batch, is_leaf=lambda x: x is None), n
