"""Scenarios by hand and from files: [`make_scenario`][vcjax.loops.scenario.make_scenario]
(validated, eager), parameter files
([`read_param_file`][vcjax.loops.scenario.read_param_file],
[`apply_params`][vcjax.loops.scenario.apply_params]), and
[`check_disturbances`][vcjax.loops.scenario.check_disturbances] (whether a loop
can take the current a config asks for)."""

from __future__ import annotations

import json
from pathlib import Path as _FsPath

import jax
import jax.numpy as jnp
import numpy as np

from vcjax.environment import Environment, waves
from vcjax.environment.component import KIND_WORDS
from vcjax.loops.geometry import start_parameter
from vcjax.loops.loop import Loop
from vcjax.loops.params import get_param, replace_params
from vcjax.loops.types import Scenario

__all__ = [
    "make_scenario",
    "read_param_file",
    "apply_params",
    "check_disturbances",
    "check_environment",
]


def check_disturbances(
    loop, current_nonzero: bool, gauss_markov: bool, waves: bool = False
) -> None:
    """Refuse (``ValueError``, one line naming the reason) a current or a sea the loop cannot
    take.

    Args:
        loop: a [`Loop`][vcjax.loops.loop.Loop] or a Loop subclass.
        current_nonzero: the config asks for a non-zero (mean) current.
        gauss_markov: the config asks for a time-varying (Gauss–Markov) current.
        waves: the config asks for waves (a sea state, even a calm one); the message then
            starts with ``waves:``.
    """
    cls = loop if isinstance(loop, type) else type(loop)
    name = cls.vehicle or cls.__name__
    if waves and not cls.can_feel("waves"):
        raise ValueError(f"waves: the {name} loop cannot take waves: {cls.refusal('waves')}")
    if gauss_markov and not cls.can_feel("varying_current"):
        raise ValueError(
            f"current: the {name} loop cannot take a time-varying (Gauss-Markov) current"
            + ("" if cls.can_feel("current") else " (it takes no current at all)")
        )
    if current_nonzero and not cls.can_feel("current"):
        raise ValueError(f"current: the {name} loop takes no current; set the current to zero")


def check_environment(loop, environment) -> None:
    """Refuse (``ValueError``, one line ``section: the X loop cannot take ...: reason``), before
    any work, every component of ``environment`` (a
    [`vcjax.environment.Environment`][vcjax.environment.component.Environment], or
    an iterable of components) the loop cannot feel (``Loop.feels``)."""
    cls = loop if isinstance(loop, type) else type(loop)
    name = cls.vehicle or cls.__name__
    comps = getattr(environment, "components", environment) or ()
    for c in comps:
        if not cls.can_feel(c.kind):
            words = KIND_WORDS.get(c.kind, c.kind)
            raise ValueError(
                f"{c.section}: the {name} loop cannot take {words}: {cls.refusal(c.kind)}"
            )


def make_scenario(
    loop: Loop,
    coeffs=None,
    *,
    initial: dict | None = None,
    eta0=None,
    nu0=None,
    current=(0.0, 0.0, 0.0),
    u_d=None,
    plant=None,
    design=None,
    disturbance=None,
    varpi0=None,
    sea=None,
    origin_depth=0.0,
    environment=None,
    dtype=None,
) -> Scenario:
    """A validated [`Scenario`][vcjax.loops.types.Scenario] for ``loop`` (eager; not for use under
    ``jit``).

    Args:
        coeffs: path coefficients (default: the vehicle's default path's).
        initial: values of ``loop.initial_keys`` (``*_deg`` in degrees); missing keys take the
            defaults.
        eta0, nu0: the initial pose and velocity themselves (the shapes ``initial`` would
            give, ``eta0`` in radians), instead of ``initial`` (an experiment's exact start).
        current: (2,) or (3,) water velocity in NED [m/s].
        u_d: desired speed [m/s] (default ``loop.default_speed``).
        plant, design: parameters (default ``loop.default_params()``; ``design`` defaults to
            ``plant``).
        disturbance: constant generalised disturbance (default zeros).
        varpi0: initial particle (default: the path point nearest to the start).
        sea: a [`vcjax.environment.waves.Sea`][vcjax.environment.waves.Sea] (e.g.
            [`sea_state`][vcjax.environment.waves.sea_state]) the plant feels,
            or None (no waves; refused by a loop that cannot take waves).
        origin_depth: depth of the NED origin below the sea's mean free surface [m].
        environment: a [`vcjax.environment.Environment`][vcjax.environment.component.Environment]
            (e.g. from
            [`vcjax.environment.sample`][vcjax.environment.component.sample]), or None; a component
            the loop cannot feel is
            refused by its section name.
    """
    plant = loop.default_params(dtype) if plant is None else loop.validate_params(plant, "plant")
    design = plant if design is None else loop.validate_params(design, "design")
    ftype = jnp.asarray(jax.tree_util.tree_leaves(plant)[0]).dtype
    coeffs = type(loop).default_path()[1] if coeffs is None else coeffs
    coeffs = _cast(coeffs, ftype)
    initial = dict(initial or {})
    unknown = sorted(set(initial) - set(loop.initial_keys))
    if unknown:
        raise ValueError(f"initial: unknown keys {unknown}; expected {list(loop.initial_keys)}")
    vals = {}
    for k, default in loop.initial_keys.items():
        v = float(initial.get(k, default))
        if not np.isfinite(v):
            raise ValueError(f"initial: {k}: not finite: {v}")
        vals[k] = jnp.asarray(np.radians(v) if k.endswith("_deg") else v, ftype)
    eta_i, nu_i = loop.initial_from(vals)
    if (eta0 is not None or nu0 is not None) and initial:
        raise ValueError("initial: give the initial keys or eta0/nu0, not both")
    eta0 = eta_i if eta0 is None else _state("eta0", eta0, np.shape(eta_i), ftype)
    nu0 = nu_i if nu0 is None else _state("nu0", nu0, np.shape(nu_i), ftype)
    cur = np.asarray(current, dtype=float)
    if cur.shape == (2,):
        cur = np.concatenate([cur, [0.0]])
    if cur.shape != (3,) or not np.all(np.isfinite(cur)):
        raise ValueError(f"current: expected a finite (2,) or (3,) NED velocity, got {current!r}")
    check_disturbances(loop, bool(np.any(cur != 0)), False)
    u_d = loop.default_speed if u_d is None else u_d
    if not (np.isfinite(u_d) and u_d > 0):
        raise ValueError(f"u_d: expected a finite value > 0, got {u_d!r}")
    n_nu = int(np.shape(nu0)[0])
    if disturbance is None:
        disturbance = np.zeros(n_nu)
    disturbance = np.asarray(disturbance, dtype=float)
    if disturbance.shape != (n_nu,) or not np.all(np.isfinite(disturbance)):
        raise ValueError(f"disturbance: expected a finite ({n_nu},) force, got {disturbance!r}")
    if np.any(disturbance != 0) and not loop.can_feel("force"):
        raise ValueError(f"disturbance: the {loop.vehicle} plant takes no disturbance force")
    if varpi0 is None:
        varpi0 = start_parameter(loop.path, coeffs, loop.position(eta0, design))
    if sea is not None:
        check_disturbances(loop, False, False, waves=True)
        sea = _check_sea(sea, ftype)
        if not np.isfinite(origin_depth):
            raise ValueError(f"origin_depth: expected a finite depth [m], got {origin_depth!r}")
    if environment is not None:
        if not isinstance(environment, Environment):
            raise ValueError(
                f"environment: expected a vcjax.environment.Environment, got "
                f"{type(environment).__name__}"
            )
        check_environment(loop, environment)
        environment = _cast(environment, ftype)
    return Scenario(
        eta0=eta0,
        nu0=nu0,
        current=jnp.asarray(cur, ftype),
        u_d=jnp.asarray(u_d, ftype),
        varpi0=jnp.asarray(varpi0, ftype),
        path=coeffs,
        plant=plant,
        design=design,
        disturbance=jnp.asarray(disturbance, ftype),
        sea=sea,
        origin_depth=None if sea is None else jnp.asarray(origin_depth, ftype),
        environment=environment,
    )


def _check_sea(sea, dtype):
    """A [`Sea`][vcjax.environment.waves.Sea] of five finite (N,) arrays cast to ``dtype``."""
    if not isinstance(sea, waves.Sea):
        raise ValueError(f"sea: expected a vcjax.environment.waves.Sea, got {type(sea).__name__}")
    arrs = [np.asarray(a, dtype=float) for a in sea]
    n = arrs[0].shape
    if (
        len(n) != 1
        or any(a.shape != n for a in arrs)
        or not all(np.isfinite(a).all() for a in arrs)
    ):
        raise ValueError("sea: expected five finite (N,) arrays (omega, amplitude, ...)")
    return waves.Sea(*(jnp.asarray(a, dtype) for a in arrs))


def _state(name: str, value, shape, dtype):
    """``value`` as a finite array of ``shape`` and ``dtype`` (``ValueError`` naming it)."""
    a = np.asarray(value, dtype=float)
    if a.shape != tuple(shape) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected a finite array of shape {tuple(shape)}, got {value!r}")
    return jnp.asarray(a, dtype)


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
