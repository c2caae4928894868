"""The closed-loop abstraction: :class:`Loop`, :class:`Scenario`, :class:`Signals`, disturbances.

A :class:`Loop` is *static* (a frozen, hashable dataclass: vehicle, controller, path kind and the
static options of the law), so jitted rollouts compile once per loop; everything continuous is
traced: the :class:`Scenario` (initial state, path coefficients, current, desired speed, plant and
design parameters) and the loop's gains (a NamedTuple pytree). :func:`simulate` rolls any loop
out, optionally inside a :class:`Disturbances` wrapper (time-varying current, sensor noise),
through :func:`vcjax.rollout.rollout`'s exogenous hook.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any, ClassVar, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import paths
from vcjax.currents import GaussMarkovCurrent, gm_init, gm_step, gm_value
from vcjax.rollout import Reduction, RolloutConfig, Trajectory, rollout, rollout_reduce

__all__ = [
    "Scenario",
    "GainSpec",
    "Signals",
    "Loop",
    "Disturbances",
    "DisturbanceParams",
    "gauss_markov_params",
    "simulate",
    "start_parameter",
    "path_polyline",
    "param_names",
    "get_param",
    "replace_params",
    "gains_to_json",
    "gains_from_json",
]


class Scenario(NamedTuple):
    """Traced data of one run, the same container for every loop.

    Attributes:
        eta0: (n_eta,) initial generalised position (a craft's pose ``[x, y, psi]`` or
            ``[x, y, z, phi, theta, psi]``; a manipulator's joint angles) [m, rad].
        nu0: (n_nu,) initial generalised velocity (a craft's body velocity over ground).
        current: (3,) the water's velocity in NED [m/s] (the one current convention of vcjax;
            planar craft use its first two components; ignored by loops without water).
        u_d: () desired speed along the path [m/s].
        varpi0: () initial path-particle parameter.
        path: coefficients of the loop's path (kind: :attr:`Loop.path`).
        plant: parameters of the simulated plant (the vehicle's parameter NamedTuple).
        design: parameters the *controller* believes (its design model and actuator map come
            from them); equal to ``plant`` unless a study perturbs the plant (model error).
        disturbance: (n_nu,) constant generalised disturbance force on the plant (body frame
            for craft) [N, N m]; zeros where the plant takes none.
    """

    eta0: Any
    nu0: Any
    current: Any
    u_d: Any
    varpi0: Any
    path: Any
    plant: Any
    design: Any
    disturbance: Any


class GainSpec(NamedTuple):
    """One tunable gain group of a loop (static; :mod:`tuning` builds its parameter vector
    from these).

    Attributes:
        name: the name configs use (``[problem] tune = [...]``), e.g. ``"P_G"``, ``"depth"``.
        size: number of entries.
        get: ``get(gains) -> (size,)`` the group's value (``()`` arrays are returned as (1,)).
        set: ``set(gains, value (size,)) -> gains`` (pure; traced values allowed).
        bound: ``None`` for a positive gain (tuned as ``exp(theta)``), or ``bound(gains) ->
            (size,)``: an upper bound that depends on the *other* gains (e.g. a Routh–Hurwitz
            limit on integral gains); the gain is tuned as a fraction of it in ``[0, bound)``.
    """

    name: str
    size: int
    get: Callable
    set: Callable
    bound: Callable | None = None


class Signals(NamedTuple):
    """What the one metrics function (:func:`vcjax.metrics.run_metrics`) and the tuning loss
    read from a run: N per-step samples (the state at the start of each step), true values
    (not what a noisy sensor told the controller).

    Attributes:
        eps: (N, 2) path errors ``[s, e]`` (along-, cross-track) [m].
        pos: (N, 3) NED position of what follows the path (:meth:`Loop.position`) [m].
        p_err: (N, 3) position minus the path particle's point ``p_p(varpi)``, NED [m].
        u_err: (N,) speed error [m/s].
        psi_err: (N,) heading (or attitude) error [rad]; zeros where the law has none.
        depth_err: (N,) depth error [m]; zeros for planar loops.
        cmd_ratio: (N, A) actuator commands divided by their limits (|.| > 1: beyond).
        sat: (N,) bool, some actuator commanded at or beyond its limit.
        act: dict ``name -> (M,)`` actuator magnitudes reported as ``max_abs_<name>``.
    """

    eps: Any
    pos: Any
    p_err: Any
    u_err: Any
    psi_err: Any
    depth_err: Any
    cmd_ratio: Any
    sat: Any
    act: Any


# --------------------------------------------------------------------------------------------
# Parameter NamedTuples: flat (dotted) names, lookup, replacement
# --------------------------------------------------------------------------------------------


def param_names(params, prefix: str = "") -> tuple[str, ...]:
    """Names of every array field of a (nested) parameter NamedTuple, dotted for nesting
    (``"mass"``, ``"body.W"``)."""
    out = []
    for k, v in params._asdict().items():
        if hasattr(v, "_asdict"):
            out += param_names(v, f"{prefix}{k}.")
        else:
            out.append(prefix + k)
    return tuple(out)


def get_param(params, name: str):
    for part in name.split("."):
        params = getattr(params, part)
    return params


def replace_params(params, values: dict):
    """``params`` with the (dotted) fields of ``values`` replaced (pure; traced values ok)."""
    nested: dict[str, dict] = {}
    flat = {}
    for k, v in values.items():
        head, _, rest = k.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = v
        else:
            flat[head] = v
    for head, sub in nested.items():
        flat[head] = replace_params(getattr(params, head), sub)
    return params._replace(**flat)


# --------------------------------------------------------------------------------------------
# Gains <-> JSON (any NamedTuple of arrays / NamedTuples)
# --------------------------------------------------------------------------------------------


def gains_to_json(gains) -> dict:
    """Plain-JSON form of a gains NamedTuple (nested NamedTuples become nested objects)."""
    out = {}
    for k, v in gains._asdict().items():
        out[k] = gains_to_json(v) if hasattr(v, "_asdict") else np.asarray(v).tolist()
    return out


def gains_from_json(d: dict, default, where: str = "gains file"):
    """A gains NamedTuple like ``default`` with the entries of ``d`` (validated shapes; missing
    entries keep the default). Raises ``ValueError`` naming the entry."""
    if not isinstance(d, dict):
        raise ValueError(f"{where}: expected an object, got {type(d).__name__}")
    unknown = sorted(set(d) - set(default._fields))
    if unknown:
        raise ValueError(f"{where}: unknown entries {unknown}; expected {list(default._fields)}")
    vals = {}
    for k, v in d.items():
        ref = getattr(default, k)
        if hasattr(ref, "_asdict"):
            vals[k] = gains_from_json(v, ref, f"{where}: {k}")
            continue
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: {k}: expected numbers, got {v!r}") from None
        if a.shape != np.shape(ref):
            raise ValueError(f"{where}: {k}: expected shape {np.shape(ref)}, got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{where}: {k}: not finite: {v!r}")
        vals[k] = jnp.asarray(a, dtype=jnp.asarray(ref).dtype)
    return default._replace(**vals)


# --------------------------------------------------------------------------------------------
# The loop
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Loop:
    """A closed loop: vehicle (plant, design model, actuator map) x controller x path kind.

    Static and hashable (a new gain, current or start never recompiles). Subclasses define the
    class attributes and the methods marked *required*; see :mod:`vcjax.loops` for a walk-through.

    Attributes:
        controller: the law's name (one of :attr:`controllers`).
        path: the static path kind (:class:`vcjax.paths.Path`); coefficients live in
            :attr:`Scenario.path`.
        smooth: smooth (``tanh``) actuator saturation in the plant, so gradients pass.
    """

    controller: str
    path: paths.Path
    smooth: bool = False

    #: registry name of the vehicle ("infante", "odin", "arm", ...)
    vehicle: ClassVar[str] = ""
    #: the controllers this vehicle's loop supports
    controllers: ClassVar[tuple[str, ...]] = ()
    #: the controller a config means when it names none
    default_controller: ClassVar[str] = ""
    #: [initial] keys of sweeps/tuning: name -> default value (sampled ranges set by configs)
    initial_keys: ClassVar[dict[str, float]] = {}
    #: sensor-noise channels: name -> number of entries (see :meth:`measure`)
    noise_channels: ClassVar[dict[str, int]] = {}
    #: True when the plant takes a constant disturbance force (:attr:`Scenario.disturbance`)
    takes_disturbance: ClassVar[bool] = False
    #: desired speed of the nominal scenario [m/s]
    default_speed: ClassVar[float] = 1.0

    def __post_init__(self):
        if self.controller not in self.controllers:
            raise ValueError(
                f"controller: vehicle {self.vehicle!r} supports {list(self.controllers)}, "
                f"got {self.controller!r}"
            )
        if not isinstance(self.path, paths.Path):
            raise ValueError(f"path: expected a vcjax.paths.Path, got {type(self.path).__name__}")

    # ---------------------------------------------------------------- required
    @classmethod
    def default_path(cls):
        """``(Path, coeffs)``: the vehicle's default path."""
        raise NotImplementedError

    def position(self, eta, params):
        """(3,) NED point that must follow the path (the craft; an end effector) [m]."""
        raise NotImplementedError

    def default_params(self, dtype=None):
        """The vehicle's nominal parameters (a NamedTuple of arrays)."""
        raise NotImplementedError

    def validate_params(self, params, name: str = "plant"):
        """Eagerly check vehicle parameters however they were built (e.g. ``_replace``d);
        raise ``ValueError`` naming ``name.field``. Default: the parameters must be of the type
        :meth:`default_params` returns; a vehicle overrides it with its module's ``validate``."""
        kind = type(self.default_params())
        if not isinstance(params, kind):
            raise ValueError(f"{name}: expected {kind.__name__}, got {type(params).__name__}")
        return params

    def default_gains(self):
        """The controller's default gains (a NamedTuple pytree)."""
        raise NotImplementedError

    def gain_specs(self) -> tuple[GainSpec, ...]:
        """The tunable gain groups of :attr:`controller`."""
        raise NotImplementedError

    def plant(self, t, x, u, args):
        """Vector field ``x_dot = f(t, x, u, args)`` (args from :meth:`plant_args`)."""
        raise NotImplementedError

    def control(self, t, x, z, ctrl):
        """Controller ``(u, z_dot, aux)`` (ctrl from :meth:`ctrl_params`)."""
        raise NotImplementedError

    def plant_args(self, sc: Scenario, current, current_dot):
        """The plant's traced arguments for plant parameters ``sc.plant`` and a current (3,)
        NED [m/s] with its rate (3,) [m/s^2]."""
        raise NotImplementedError

    def ctrl_params(self, gains, sc: Scenario):
        """The controller's traced parameters (design model from ``sc.design``)."""
        raise NotImplementedError

    def initial_state(self, sc: Scenario):
        """``(x0, z0)``: plant and controller states at ``t = 0``."""
        raise NotImplementedError

    def signals(self, traj: Trajectory, sc: Scenario) -> Signals:
        """Per-step signals of a run for metrics and losses (true values)."""
        raise NotImplementedError

    def initial_from(self, values: dict):
        """``(eta0, nu0)`` from the :attr:`initial_keys` values (traced scalars, SI units:
        keys ending in ``_deg`` are given here already in radians)."""
        raise NotImplementedError

    # ---------------------------------------------------------------- optional
    def param_names(self) -> tuple[str, ...]:
        """Plant/design parameter names accepted by ``[model_error]`` and parameter files."""
        return param_names(self.default_params())

    def default_model_fields(self) -> tuple[str, ...]:
        """Parameters a ``[model_error]`` perturbs when it names none."""
        return self.param_names()

    def symmetric_pairs(self) -> tuple[tuple[str, int, str, int], ...]:
        """Gain entries ``(group_a, i, group_b, j)`` the loop depends on only through their sum
        and product (Baumgarte pairs ``p_G``, ``p_Phi`` of one holonomic row), so that a tuner
        starting with them equal is at a critical point (see ``tuning.params``)."""
        return ()

    def measure(self, x, noise):
        """The state the controller sees: ``x`` with ``noise`` (concatenated
        :attr:`noise_channels`, SI units) added. Default: no sensors modelled."""
        raise NotImplementedError(f"{type(self).__name__}: no sensor-noise model")

    def noise_std(self, stds: dict) -> np.ndarray:
        """Concatenated standard deviations from a ``{channel: std}`` dict (SI units)."""
        parts = [np.full(n, float(stds.get(k, 0.0))) for k, n in self.noise_channels.items()]
        return np.concatenate(parts) if parts else np.zeros(0)

    def with_current(self, args, current, current_dot):
        """``args`` with a new current (3,) and rate (3,) (time-varying currents)."""
        raise NotImplementedError(f"{type(self).__name__}: no time-varying current")

    def gains_to_json(self, gains) -> dict:
        return gains_to_json(gains)

    def gains_from_json(self, d: dict, base=None):
        """Gains from a JSON object (entries missing keep ``base``, default the defaults)."""
        return gains_from_json(d, self.default_gains() if base is None else base)

    def describe(self) -> str:
        return f"{self.vehicle} / {self.controller} on a {self.path.name}"


def _search_range(path: paths.Path, coeffs, w_range):
    """Where to look for the nearest point: one turn of a circle, two of a helix, the
    waypoints' span; else ``w_range``."""
    if isinstance(coeffs, paths.CircleCoeffs):
        return 0.0 * coeffs.radius, 2 * jnp.pi * coeffs.radius
    if isinstance(coeffs, paths.HelixCoeffs):
        return -2 * jnp.pi * coeffs.T, 2 * jnp.pi * coeffs.T
    if isinstance(coeffs, paths.SplineCoeffs):
        return coeffs.knots[0], coeffs.knots[-1]
    if isinstance(coeffs, paths.LawnmowerCoeffs):
        n = coeffs.n_legs
        return 0.0 * n, n * coeffs.leg + (n - 1.0) * jnp.pi * coeffs.radius
    return w_range


def path_polyline(path: paths.Path, coeffs, points=None, num: int = 400):
    """(num, 3) points of the path for figures: one turn of a circle, two of a helix, the
    waypoints' or survey's span; a line over the projections of ``points`` (M, 2 or 3) ±10 m
    (default ``[-50, 50]``)."""
    if isinstance(coeffs, paths.LineCoeffs) and points is not None:
        pts = jnp.asarray(points)
        pts = jnp.concatenate([pts, jnp.zeros(pts.shape[:-1] + (3 - pts.shape[-1],))], axis=-1)
        w = (pts - coeffs.origin) @ coeffs.direction
        lo, hi = jnp.min(w) - 10.0, jnp.max(w) + 10.0
    else:
        lo, hi = _search_range(path, coeffs, (-50.0, 50.0))
    w = lo + (hi - lo) * jnp.linspace(0.0, 1.0, num)
    return jax.vmap(lambda w_: paths.path_point(path, coeffs, w_))(w)


def start_parameter(path: paths.Path, coeffs, point, w_range=(-50.0, 50.0), num: int = 512):
    """() path parameter of the point of the path nearest to ``point`` (3,) (jit/vmap-safe).

    Exact for a line (projection onto it). Otherwise: the nearest of ``num`` samples over one
    turn of a circle, two turns of a helix, the span of a waypoint spline, or ``w_range`` for
    other kinds, refined by three Newton steps on ``(p(w) - point) . p'(w) = 0``.
    """
    point = jnp.asarray(point)
    if isinstance(coeffs, paths.LineCoeffs):
        return jnp.dot(point - coeffs.origin, coeffs.direction)
    lo, hi = _search_range(path, coeffs, w_range)
    w = jnp.linspace(0.0, 1.0, num, dtype=point.dtype)
    w = lo + (hi - lo) * w
    p = jax.vmap(lambda w_: paths.path_point(path, coeffs, w_))(w)
    w0 = w[jnp.argmin(jnp.sum((p - point) ** 2, axis=1))]

    def g(w_):
        p_, dp = jax.jvp(lambda v: paths.path_point(path, coeffs, v), (w_,), (jnp.ones_like(w_),))
        return jnp.dot(p_ - point, dp)

    def newton(w_, _):
        val, slope = jax.jvp(g, (w_,), (jnp.ones_like(w_),))
        step = jnp.where(slope > 0, val / jnp.where(slope > 0, slope, 1.0), 0.0)
        return jnp.clip(w_ - step, lo, hi), None

    return jax.lax.scan(newton, w0, None, length=3)[0]


# --------------------------------------------------------------------------------------------
# Disturbances that wrap any loop
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Disturbances:
    """Static choice of the disturbances wrapped around a loop.

    Attributes:
        gauss_markov: the horizontal current is the Gauss–Markov process of
            :mod:`vcjax.currents` around ``Scenario.current`` (per-step, exact discretisation,
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
        current: :class:`~vcjax.currents.GaussMarkovCurrent` (mean: the horizontal part of
            ``Scenario.current``); noise_std: (n,) sensor-noise standard deviations;
        key: (2,) PRNG key of the run's random processes.
    """

    current: Any
    noise_std: Any
    key: Any


@dataclasses.dataclass(frozen=True)
class _Wrapped:
    loop: Loop
    dist: Disturbances

    def exogenous(self, k, t, s, plant_params, ctrl_params):
        args, gm_p, key_steps, dt, vertical = plant_params
        ctrl, noise_std, key_noise = ctrl_params
        if self.dist.gauss_markov:
            # current on [t_k, t_k + dt]: linear between the exact GM samples, its rate the slope
            d_next = gm_step(gm_p, s, dt, jax.random.fold_in(key_steps, k))
            V0, V1 = gm_value(gm_p, s), gm_value(gm_p, d_next)
            dV = (V1 - V0) / dt
            args = (args, jnp.concatenate([V0, vertical]), jnp.concatenate([dV, 0 * vertical]))
            s = d_next
        n = None
        if self.dist.sensor_noise:
            n = noise_std * jax.random.normal(
                jax.random.fold_in(key_noise, k), noise_std.shape, noise_std.dtype
            )
        return s, (args, t), (ctrl, n)

    def plant(self, t, x, u, params):
        args, t_k = params
        if self.dist.gauss_markov:
            args, V, dV = args
            args = self.loop.with_current(args, V + (t - t_k) * dV, dV)
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
    are traced. Without disturbances this is one :func:`vcjax.rollout.rollout` of
    ``loop.plant`` / ``loop.control``; with them the same loop gets a Gauss–Markov current
    and/or measurement noise through the rollout's ``exogenous`` hook.

    Returns the :class:`~vcjax.rollout.Trajectory`; with a ``reduction``
    (:class:`~vcjax.rollout.Reduction`) the record is folded segment by segment instead
    (:func:`~vcjax.rollout.rollout_reduce`) and ``(acc, outs)`` is returned.
    """
    run = rollout if reduction is None else functools.partial(rollout_reduce, reduction=reduction)
    x0, z0 = loop.initial_state(sc)
    ctrl = loop.ctrl_params(gains, sc)
    dtype = sc.eta0.dtype
    if not dist.active:
        args = loop.plant_args(sc, sc.current, jnp.zeros(3, dtype))
        return run(loop.plant, loop.control, config, args, ctrl, x0, z0, dt)
    if dist_params is None:
        raise ValueError("dist_params: required with disturbances")
    dt = jnp.asarray(dt, dtype)
    w = _Wrapped(loop, dist)
    k_init, k_steps, k_noise = _process_keys(dist_params.key)
    gm_p = dist_params.current
    s0 = gm_init(gm_p, k_init) if dist.gauss_markov else None
    args = loop.plant_args(sc, sc.current, jnp.zeros(3, dtype))
    plant_params = (args, gm_p, k_steps, dt, sc.current[2:])
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
