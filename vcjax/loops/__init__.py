"""Closed loops by name: the layer under ``vcjax simulate``, ``vcjax sweep`` and ``vcjax tune``.

A *loop* assembles a vehicle's plant, the controller's design model, a law and the actuator map
(and the thruster allocation where there is one) into the ``(plant, controller)`` pair that
:func:`vcjax.rollout.rollout` runs. Three kinds of data, kept apart:

* the :class:`~vcjax.loops.base.Loop` itself — static and hashable (vehicle, controller, path
  kind, static law options such as ``edd``, ``smooth``): one compilation per loop;
* the :class:`~vcjax.loops.base.Scenario` — traced, the same container for every loop: initial
  state ``eta0``/``nu0``, ``current`` (the water's NED velocity (3,) [m/s], built from a speed
  and a direction with :func:`vcjax.currents.current_ned`), ``u_d``, ``varpi0``, the path's
  coefficients, the ``plant`` and ``design`` parameters, a constant ``disturbance`` force;
* the gains — a NamedTuple pytree, traced (a new gain value never recompiles).

:func:`~vcjax.loops.base.simulate` rolls any loop out, optionally with disturbances that wrap
any loop (:class:`~vcjax.loops.base.Disturbances`: a Gauss–Markov current, sensor noise);
model error is just a ``plant`` that differs from ``design``.
:func:`vcjax.metrics.run_metrics` turns any loop's :class:`~vcjax.loops.base.Signals` into the
one set of metrics and health flags.

Registry (``vehicle -> Loop subclass``)::

    loops.vehicles()                     # ("arm", "infante", "odin", ...)
    loops.controllers("infante")         # ("vcm", "vcm_integral", "vcm_ilos", "ilos", "los_pid")
    loop = loops.make_loop("infante", "vcm_integral", path=paths.CIRCLE)   # path: a Path kind
    path, coeffs = loops.default_path("infante")                           # the vehicle's default
    sc = loops.make_scenario(loop, coeffs, current=(0.0, 0.5, 0.0))        # validated, eager
    traj = loops.simulate(loop, loop.default_gains(), sc, RolloutConfig(num_steps=400), 0.05)

How to add a vehicle or a law (one new file + one :func:`register` line; nothing else changes —
``tests/test_loops.py`` defines a loop entirely inside the test file and sweeps and tunes it):

1. Subclass :class:`~vcjax.loops.base.Loop` as a frozen dataclass; extra static options are
   dataclass fields. Class attributes: ``vehicle`` (the registry name), ``controllers`` (the laws
   it supports; errors list them), ``initial_keys`` (the ``[initial]`` keys of sweep/tune
   configs with their defaults; keys ending in ``_deg`` are given in degrees in configs and
   arrive in radians), ``noise_channels`` (sensor-noise channel name -> entries; leave empty if
   you model no sensors), ``takes_disturbance``, ``default_speed``.
2. Implement:
   ``default_params(dtype)`` — the plant parameters (a NamedTuple; its field names, dotted for
   nested NamedTuples, are the names ``[model_error] fields`` and parameter files use;
   restrict them with ``param_names()``, choose the default perturbed set with
   ``default_model_fields()``);
   ``default_gains()`` — the gains NamedTuple; ``gain_specs()`` — how each tunable group is read
   and written (:class:`~vcjax.loops.base.GainSpec`: a positive gain is tuned in log space, a
   gain with a ``bound`` depending on the others as a fraction of it), plus optionally
   ``symmetric_pairs()``; ``default_path()`` (classmethod) — ``(Path, coeffs)``;
   ``plant(t, x, u, args)``, ``control(t, x, z, ctrl) -> (u, z_dot, aux)``;
   ``plant_args(sc, current, current_dot)``, ``ctrl_params(gains, sc)`` (the design model comes
   from ``sc.design``), ``initial_state(sc) -> (x0, z0)``, ``initial_from(values) -> (eta0,
   nu0)``, ``position(eta, params) -> (3,)`` (where the path must be: craft position, end
   effector); ``signals(traj, sc) -> Signals`` (true errors, commands over limits, actuator
   magnitudes); optionally ``measure(x, noise)`` and ``with_current(args, current, rate)``.
3. ``loops.register(MyLoop)``. Then ``[scenario] vehicle = "my_vehicle"`` works in sweep and
   tune configs, and :mod:`tuning` tunes ``gain_specs()``.

Parameter overrides (``[scenario] params`` / ``plant_params`` files of sweep and tune configs,
e.g. a ``vcjax fit`` result): :func:`~vcjax.loops.base.replace_params` with names from
``loop.param_names()``; :func:`apply_param_file` reads a flat ``{name: value}`` map or a ``fit``
output's ``"estimates"`` map and rejects unknown names, listing the valid ones.
"""

from __future__ import annotations

import json
from pathlib import Path as _FsPath

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import paths
from vcjax.loops.arm import ArmLoop, ArmLoopParams, arm_loop_params
from vcjax.loops.base import (
    DisturbanceParams,
    Disturbances,
    GainSpec,
    Loop,
    Scenario,
    Signals,
    gains_from_json,
    gains_to_json,
    gauss_markov_params,
    get_param,
    param_names,
    replace_params,
    simulate,
    start_parameter,
)
from vcjax.loops.engine import EngineAux, EngineGains, EngineLoop, engine_gains
from vcjax.loops.infante import InfanteGains, InfanteLoop, infante_gains
from vcjax.loops.odin import OdinGains, OdinLoop, default_odin_gains, odin_gains
from vcjax.loops.remus100 import Remus100Loop

__all__ = [
    "Disturbances",
    "DisturbanceParams",
    "GainSpec",
    "Loop",
    "Scenario",
    "Signals",
    "InfanteGains",
    "InfanteLoop",
    "infante_gains",
    "ArmLoop",
    "ArmLoopParams",
    "arm_loop_params",
    "EngineAux",
    "EngineGains",
    "EngineLoop",
    "engine_gains",
    "OdinGains",
    "OdinLoop",
    "odin_gains",
    "default_odin_gains",
    "gains_from_json",
    "gains_to_json",
    "gauss_markov_params",
    "get_param",
    "param_names",
    "replace_params",
    "simulate",
    "start_parameter",
    "register",
    "vehicles",
    "loop_class",
    "controllers",
    "make_loop",
    "default_path",
    "make_scenario",
    "read_param_file",
    "apply_params",
]

_REGISTRY: dict[str, type[Loop]] = {}


def register(cls: type[Loop]) -> type[Loop]:
    """Register a :class:`Loop` subclass under ``cls.vehicle`` (usable as a decorator)."""
    if not (isinstance(cls, type) and issubclass(cls, Loop)) or not cls.vehicle:
        raise ValueError(f"register: expected a Loop subclass with a vehicle name, got {cls!r}")
    if not cls.controllers:
        raise ValueError(f"register: {cls.__name__} lists no controllers")
    _REGISTRY[cls.vehicle] = cls
    return cls


def vehicles() -> tuple[str, ...]:
    """Registered vehicle names (sorted)."""
    return tuple(sorted(_REGISTRY))


def loop_class(vehicle: str) -> type[Loop]:
    """The :class:`Loop` subclass of ``vehicle``; ``ValueError`` listing the vehicles if none."""
    if vehicle not in _REGISTRY:
        raise ValueError(f"vehicle: expected one of {list(vehicles())}, got {vehicle!r}")
    return _REGISTRY[vehicle]


def controllers(vehicle: str) -> tuple[str, ...]:
    """The controllers ``vehicle``'s loop supports."""
    return loop_class(vehicle).controllers


def default_path(vehicle: str):
    """``(Path, coeffs)``: the vehicle's default path (e.g. Simulation 1's line for INFANTE)."""
    return loop_class(vehicle).default_path()


def make_loop(vehicle: str, controller: str, path: paths.Path | None = None, **options) -> Loop:
    """The loop of ``vehicle`` x ``controller`` on ``path`` (default: the vehicle's default path
    kind); ``options``: the loop's static fields (e.g. ``edd``, ``smooth``)."""
    cls = loop_class(vehicle)
    if controller not in cls.controllers:
        raise ValueError(
            f"controller: vehicle {vehicle!r} supports {list(cls.controllers)}, got {controller!r}"
        )
    path = cls.default_path()[0] if path is None else path
    try:
        return cls(controller=controller, path=path, **options)
    except TypeError as err:
        raise ValueError(f"{vehicle} loop options: {err}") from None


def make_scenario(
    loop: Loop,
    coeffs=None,
    *,
    initial: dict | None = None,
    current=(0.0, 0.0, 0.0),
    u_d=None,
    plant=None,
    design=None,
    disturbance=None,
    varpi0=None,
    dtype=None,
) -> Scenario:
    """A validated :class:`Scenario` for ``loop`` (eager; not for use under ``jit``).

    Args:
        coeffs: path coefficients (default: the vehicle's default path's).
        initial: values of ``loop.initial_keys`` (``*_deg`` in degrees); missing keys take the
            defaults.
        current: (2,) or (3,) water velocity in NED [m/s].
        u_d: desired speed [m/s] (default ``loop.default_speed``).
        plant, design: parameters (default ``loop.default_params()``; ``design`` defaults to
            ``plant``).
        disturbance: constant generalised disturbance (default zeros).
        varpi0: initial particle (default: the path point nearest to the start).
    """
    plant = loop.default_params(dtype) if plant is None else plant
    design = plant if design is None else design
    dt = jnp.asarray(jax.tree_util.tree_leaves(plant)[0]).dtype
    coeffs = type(loop).default_path()[1] if coeffs is None else coeffs
    coeffs = _cast(coeffs, dt)
    initial = dict(initial or {})
    unknown = sorted(set(initial) - set(loop.initial_keys))
    if unknown:
        raise ValueError(f"initial: unknown keys {unknown}; expected {list(loop.initial_keys)}")
    vals = {}
    for k, default in loop.initial_keys.items():
        v = float(initial.get(k, default))
        if not np.isfinite(v):
            raise ValueError(f"initial: {k}: not finite: {v}")
        vals[k] = jnp.asarray(np.radians(v) if k.endswith("_deg") else v, dt)
    eta0, nu0 = loop.initial_from(vals)
    cur = np.asarray(current, dtype=float)
    if cur.shape == (2,):
        cur = np.concatenate([cur, [0.0]])
    if cur.shape != (3,) or not np.all(np.isfinite(cur)):
        raise ValueError(f"current: expected a finite (2,) or (3,) NED velocity, got {current!r}")
    u_d = loop.default_speed if u_d is None else u_d
    if not (np.isfinite(u_d) and u_d > 0):
        raise ValueError(f"u_d: expected a finite value > 0, got {u_d!r}")
    n_nu = int(np.shape(nu0)[0])
    if disturbance is None:
        disturbance = np.zeros(n_nu)
    disturbance = np.asarray(disturbance, dtype=float)
    if disturbance.shape != (n_nu,) or not np.all(np.isfinite(disturbance)):
        raise ValueError(f"disturbance: expected a finite ({n_nu},) force, got {disturbance!r}")
    if np.any(disturbance != 0) and not loop.takes_disturbance:
        raise ValueError(f"disturbance: the {loop.vehicle} plant takes no disturbance force")
    if varpi0 is None:
        varpi0 = start_parameter(loop.path, coeffs, loop.position(eta0, design))
    return Scenario(
        eta0=eta0,
        nu0=nu0,
        current=jnp.asarray(cur, dt),
        u_d=jnp.asarray(u_d, dt),
        varpi0=jnp.asarray(varpi0, dt),
        path=coeffs,
        plant=plant,
        design=design,
        disturbance=jnp.asarray(disturbance, dt),
    )


def _cast(tree, dtype):
    def f(a):
        a = jnp.asarray(a)
        return a.astype(dtype) if jnp.issubdtype(a.dtype, jnp.floating) else a

    return jax.tree_util.tree_map(f, tree)


def read_param_file(path, loop: Loop, where: str = "params") -> dict:
    """``{name: value}`` from a JSON file: a flat map, or a ``vcjax fit`` output whose
    ``"estimates"`` map is used. Unknown names raise ``ValueError`` listing the valid ones."""
    path = _FsPath(path)
    try:
        d = json.loads(path.read_text())
    except OSError as err:
        raise ValueError(f"{where}: cannot read {path}: {err}") from None
    except json.JSONDecodeError as err:
        raise ValueError(f"{where}: {path}: not valid JSON: {err}") from None
    if isinstance(d, dict) and isinstance(d.get("estimates"), dict):
        d = d["estimates"]
    if not isinstance(d, dict):
        raise ValueError(f"{where}: {path}: expected an object of parameter values")
    valid = loop.param_names()
    bad = sorted(set(d) - set(valid))
    if bad:
        raise ValueError(
            f"{where}: {path}: unknown {loop.vehicle} parameters {bad}; valid: {list(valid)}"
        )
    return d


def apply_params(params, values: dict, where: str = "params"):
    """``params`` with ``values`` (name -> number or nested list) replaced, shapes checked."""
    new = {}
    for k, v in values.items():
        ref = get_param(params, k)
        a = np.asarray(v, dtype=float)
        if a.shape != np.shape(ref) or not np.all(np.isfinite(a)):
            raise ValueError(
                f"{where}: {k}: expected a finite value of shape {np.shape(ref)}, got {v!r}"
            )
        new[k] = jnp.asarray(a, jnp.asarray(ref).dtype)
    return replace_params(params, new)


register(InfanteLoop)
register(OdinLoop)
register(ArmLoop)
register(Remus100Loop)
