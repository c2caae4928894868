"""The envelope a falsification searches: scenario parameters by name (config units) with their
``(lo, hi)`` boxes ([`Envelope`][vcjax.search.envelope.Envelope]), the static rest of the problem
([`Setting`][vcjax.search.envelope.Setting]), and
the one function that turns a parameter vector into a traced scenario
([`scenario_from`][vcjax.search.envelope.scenario_from]).

Parameter names (config units, the sweep's [`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec] fields):

* ``current_speed`` [m/s, >= 0], ``current_direction_deg`` [deg, towards, clockwise from north];
* ``u_d`` [m/s, > 0], the desired speed;
* ``initial.<key>``: the loop's ``initial_keys`` in their units (``*_deg`` in degrees);
* ``wave_hs`` [m, >= 0], ``wave_tp`` [s, >= 40 dt], ``wave_direction_deg`` [deg, towards],
  ``wave_spreading`` (``s`` of ``cos^2s``; > 0 when searched), ``wave_origin_depth`` [m]: the
  sea (any of them given: the scenario has a sea);
* ``model.<field>``: a multiplicative factor (> 0) of a plant parameter (the controller keeps the
  nominal design model);
* ``disturbance.<i>``: component ``i`` of a constant generalised disturbance force [N, N m].

Everything random about a scenario (the sea's frequencies, phases and spreading draws, a
Gauss-Markov current's path, sensor noise) comes from ``fold_in(PRNGKey(seed), index)`` exactly
as scenario ``index`` of a sweep with that seed; the search holds it fixed per start and moves
only the parameters.

This module is the seam to the environment components: a new disturbance component adds its
names here and its part of [`scenario_from`][vcjax.search.envelope.scenario_from]; the search itself
sees only a vector.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import loops
from vcjax.environment import waves
from vcjax.environment.current import current_ned
from vcjax.sweep.spec import MCConfig, MCScenario, ScenarioSpec, SweepSpec, check_wave_step

__all__ = [
    "Envelope",
    "Setting",
    "SettingOptions",
    "make_setting",
    "scenario_from",
    "setting_from_spec",
    "envelope_from_spec",
    "envelope_from_scenario",
]

_WAVE = ("wave_hs", "wave_tp", "wave_direction_deg", "wave_spreading", "wave_origin_depth")
_PLAIN = ("current_speed", "current_direction_deg", "u_d")


@dataclasses.dataclass(frozen=True)
class Setting:
    """What a falsification holds fixed (static, hashable except the arrays in ``nominal``).

    Attributes:
        loop: the closed loop; config: [`MCConfig`][vcjax.sweep.spec.MCConfig] (horizon, integrator,
            model fields, window); dt: step [s]; diverge_e: cross-track bound of ``diverged``.
        nominal: ``(plant, design, coeffs)`` ([`vcjax.sweep.nominal`][vcjax.sweep.run.nominal]).
        sea: ``(spectrum, components, gamma)`` or None (no waves).
        current_gm: ``(sigma, tau, max_speed)`` of a Gauss-Markov current (``config``'s
            ``current_model``); noise_std: (S,) sensor-noise standard deviations (SI).
        seed: the scenarios' random keys are ``fold_in(PRNGKey(seed), index)``.
    """

    loop: Any
    config: MCConfig
    dt: float
    nominal: Any = dataclasses.field(compare=False, hash=False)
    diverge_e: float = 50.0
    sea: tuple | None = None
    current_gm: tuple = (0.05, 300.0, 2.0)
    noise_std: tuple = ()
    seed: int = 0


@dataclasses.dataclass(frozen=True)
class Envelope:
    """Named boxes ``(lo, hi)`` in config units (``lo == hi``: held fixed), in a fixed order.

    Build it with ``build`` (checks the names and the ranges); ``names``, ``lo``, ``hi`` are
    the full parameter vector a scenario needs, the fixed ones included.
    """

    names: tuple[str, ...]
    lo: tuple[float, ...]
    hi: tuple[float, ...]

    @property
    def searched(self) -> tuple[str, ...]:
        """The names whose box has width (what the search moves)."""
        return tuple(n for n, a, b in zip(self.names, self.lo, self.hi, strict=True) if b > a)

    def as_dict(self) -> dict:
        return {n: [a, b] for n, a, b in zip(self.names, self.lo, self.hi, strict=True)}

    def project(self, x):
        """``x`` (..., P) clipped into the box (jnp)."""
        lo = jnp.asarray(self.lo, jnp.asarray(x).dtype)
        hi = jnp.asarray(self.hi, jnp.asarray(x).dtype)
        return jnp.clip(x, lo, hi)

    def to_unit(self, x):
        """Config units -> ``[0, 1]`` coordinates (0 for fixed parameters)."""
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        w = np.where(hi > lo, hi - lo, 1.0)
        return (np.asarray(x) - lo) / w * (hi > lo)

    def from_unit(self, z):
        """``[0, 1]`` coordinates -> config units in ``z``'s dtype (fixed parameters at
        ``lo``): a NumPy array stays on the host and is mapped with NumPy (the search's own
        arithmetic: eager JAX would compile a kernel per operation), anything else with jnp
        (traced inside the search's program)."""
        xp = np if isinstance(z, np.ndarray) else jnp
        z = xp.asarray(z)
        lo = xp.asarray(self.lo, z.dtype)
        hi = xp.asarray(self.hi, z.dtype)
        return lo + (hi - lo) * z

    def params(self, x) -> dict:
        """``{name: float}`` of a parameter vector."""
        return {n: float(v) for n, v in zip(self.names, np.asarray(x), strict=True)}

    def vector(self, params: dict, where: str = "params") -> np.ndarray:
        """The vector of ``params`` (every name of the envelope; unknown names refused)."""
        unknown = sorted(set(params) - set(self.names))
        missing = [n for n in self.names if n not in params]
        if unknown or missing:
            raise ValueError(
                f"{where}: expected the envelope's parameters {list(self.names)}; "
                f"unknown {unknown}, missing {missing}"
            )
        return np.asarray([float(params[n]) for n in self.names])

    @classmethod
    def build(cls, loop, ranges: dict, *, dt: float | None = None, model_fields=()) -> Envelope:
        """The envelope of ``ranges`` (name -> number or ``(lo, hi)``) for ``loop``; every
        parameter the scenario needs and ``ranges`` does not give takes its default (current
        0 towards north, the loop's ``default_speed`` and ``initial_keys``, factor 1, no
        disturbance; a sea's direction 0, spreading 0 (long-crested), origin depth 0).

        Raises:
            ValueError: one line naming the parameter: an unknown name, ``lo > hi``, a
                non-finite bound, a value outside the physically valid range (negative speed,
                Hs or factor, ``u_d <= 0``, ``wave_tp < 40 dt``, a searched ``wave_spreading``
                reaching 0), waves without ``wave_hs`` and ``wave_tp``, or a current, sea or
                disturbance the loop cannot take.
        """
        ranges = dict(ranges)
        fields = tuple(model_fields)
        n_nu = int(np.shape(loop.initial_from(_zeros(loop))[1])[0])
        default = {"current_speed": 0.0, "current_direction_deg": 0.0, "u_d": loop.default_speed}
        default |= {f"initial.{k}": float(v) for k, v in loop.initial_keys.items()}
        default |= {f"model.{f}": 1.0 for f in fields}
        if loop.can_feel("force"):
            default |= {f"disturbance.{i}": 0.0 for i in range(n_nu)}
        valid_model = set(loop.param_names())
        has_waves = any(k in ranges for k in _WAVE)
        if has_waves:
            default |= {"wave_direction_deg": 0.0, "wave_spreading": 0.0, "wave_origin_depth": 0.0}
        known = set(default) | set(_WAVE)
        for k in ranges:
            if k.startswith("model.") and k[6:] in valid_model and k not in default:
                default[k] = 1.0
                fields += (k[6:],)
        unknown = sorted(set(ranges) - known)
        if unknown:
            raise ValueError(
                f"envelope: unknown parameters {unknown}; expected among "
                f"{sorted(known)} (model.<field>: {sorted(valid_model)})"
            )
        if has_waves:
            for k in ("wave_hs", "wave_tp"):
                if k not in ranges:
                    raise ValueError(f"envelope: {k}: a sea needs wave_hs and wave_tp")
            try:
                loops.check_disturbances(loop, False, False, waves=True)
            except ValueError as err:
                raise ValueError(f"envelope: {err}") from None
        box = {}
        for k, v in {**default, **ranges}.items():
            lo, hi = _pair(k, v)
            _check_valid(k, lo, hi, dt)
            box[k] = (lo, hi)
        cur = box["current_speed"]
        if cur[1] > 0 and not loop.can_feel("current"):
            raise ValueError(f"envelope: current_speed: the {loop.vehicle} loop takes no current")
        names = tuple(default) + tuple(k for k in _WAVE if k in box and k not in default)
        return cls(names, tuple(box[k][0] for k in names), tuple(box[k][1] for k in names))

    @property
    def model_fields(self) -> tuple[str, ...]:
        return tuple(n[6:] for n in self.names if n.startswith("model."))

    @property
    def has_waves(self) -> bool:
        return "wave_hs" in self.names


def _pair(k, v) -> tuple[float, float]:
    if isinstance(v, bool):
        raise ValueError(f"envelope: {k}: expected a number or [lo, hi], got {v!r}")
    if isinstance(v, int | float):
        v = (v, v)
    try:
        lo, hi = (float(a) for a in v)
    except (TypeError, ValueError):
        raise ValueError(f"envelope: {k}: expected a number or [lo, hi], got {v!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ValueError(f"envelope: {k}: bounds must be finite, got [{lo:g}, {hi:g}]")
    if lo > hi:
        raise ValueError(f"envelope: {k}: lo > hi: [{lo:g}, {hi:g}]")
    return lo, hi


def _check_valid(k: str, lo: float, hi: float, dt) -> None:
    """The physically valid range of each parameter (one line naming it)."""
    if k in ("current_speed", "wave_hs", "wave_spreading") and lo < 0:
        raise ValueError(f"envelope: {k}: must be >= 0, got lo = {lo:g}")
    if (k in ("u_d", "wave_tp") or k.startswith("model.")) and lo <= 0:
        raise ValueError(f"envelope: {k}: must be > 0, got lo = {lo:g}")
    if k == "wave_spreading" and hi > lo and lo <= 0:
        raise ValueError("envelope: wave_spreading: a searched spreading must stay > 0 (lo > 0)")
    if k == "wave_tp" and dt is not None:
        check_wave_step(lo, dt, "envelope: wave_tp")


def _zeros(loop):
    return {k: jnp.zeros(()) for k in loop.initial_keys}


def scenario_from(x, index, env: Envelope, setting: Setting) -> MCScenario:
    """The traced scenario of parameter vector ``x`` (P,) (config units, ``env.names`` order)
    with the random draws of scenario ``index`` of seed ``setting.seed`` (pure; differentiable
    in ``x``; ``vmap`` it over starts)."""
    loop = setting.loop
    v = dict(zip(env.names, [x[i] for i in range(len(env.names))], strict=True))
    dtype = x.dtype
    deg = math.pi / 180.0
    key = jax.random.fold_in(jax.random.PRNGKey(jnp.asarray(setting.seed, jnp.uint32)), index)
    ks = jax.random.split(key, 9)  # the sweep's streams (vcjax.sweep.spec._sample_one)
    init = {
        k: v[f"initial.{k}"] * deg if k.endswith("_deg") else v[f"initial.{k}"]
        for k in loop.initial_keys
    }
    eta0, nu0 = loop.initial_from(init)
    n_nu = nu0.shape[0]
    if loop.can_feel("force"):
        dist = jnp.stack([v[f"disturbance.{i}"] for i in range(n_nu)])
    else:
        dist = jnp.zeros((n_nu,), dtype)
    factors = jnp.stack([v[f"model.{f}"] for f in env.model_fields]) if env.model_fields else None
    factors = jnp.zeros((0,), dtype) if factors is None else factors
    wave = (None,) * 5
    if setting.sea is not None:
        spectrum, components, gamma = setting.sea
        _, k_sea = jax.random.split(ks[4])
        spreading = v["wave_spreading"]
        i = env.names.index("wave_spreading")
        if env.hi[i] == env.lo[i]:
            spreading = env.lo[i]  # concrete: 0 means long-crested
        sea = waves.sea_state(
            k_sea,
            v["wave_hs"],
            v["wave_tp"],
            v["wave_direction_deg"] * deg,
            spectrum=spectrum,
            gamma=gamma,
            spreading=spreading,
            components=components,
            dtype=dtype,
        )
        wave = (v["wave_hs"], v["wave_tp"], v["wave_direction_deg"], v["wave_origin_depth"], sea)
    gm = jnp.asarray(setting.current_gm, dtype)
    return MCScenario(
        index=jnp.asarray(index, jnp.int32),
        eta0=eta0,
        nu0=nu0,
        u_d=v["u_d"],
        current_speed=v["current_speed"],
        current_direction=v["current_direction_deg"] * deg,
        current=current_ned(v["current_speed"], v["current_direction_deg"] * deg),
        current_sigma=gm[0],
        current_tau=gm[1],
        current_max_speed=gm[2],
        model_factors=factors,
        noise_std=jnp.asarray(setting.noise_std, dtype),
        disturbance=dist,
        key=ks[2],
        wave_hs=wave[0],
        wave_tp=wave[1],
        wave_direction_deg=wave[2],
        wave_origin_depth=wave[3],
        sea=wave[4],
    )


def envelope_from_spec(spec: SweepSpec) -> Envelope:
    """The envelope of a sweep spec's scenario ranges (every ``[lo, hi]`` searched, every
    number fixed; ``[model_error] relative = r``: each field's factor in ``[1 - r, 1 + r]``)."""
    return envelope_from_scenario(spec.scenario, spec.loop(spec.variants[0]), spec.dt)


def envelope_from_scenario(sc: ScenarioSpec, loop, dt: float | None = None) -> Envelope:
    """The envelope of a [`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec]'s ranges for ``loop``
    (as [`envelope_from_spec`][vcjax.search.envelope.envelope_from_spec]; e.g. the scenario
    distribution of a tune, ``tuning.robust``)."""
    r = {
        "current_speed": sc.current.speed,
        "current_direction_deg": sc.current.direction_deg,
        "u_d": sc.u_d or (loop.default_speed,) * 2,
    }
    r |= {f"initial.{k}": v for k, v in sc.initial.values}
    rel = sc.model_error.relative
    if rel > 0:
        r |= {f"model.{f}": (1 - rel, 1 + rel) for f in sc.fields_for(loop)}
    r |= {f"disturbance.{i}": v for i, v in enumerate(sc.disturbance.force)}
    if sc.waves:
        r |= {
            "wave_hs": sc.waves.hs,
            "wave_tp": sc.waves.tp,
            "wave_direction_deg": sc.waves.direction_deg,
            "wave_spreading": sc.waves.spreading,
            "wave_origin_depth": sc.waves.origin_depth,
        }
    return Envelope.build(loop, r, dt=dt)


def setting_from_spec(spec: SweepSpec, env: Envelope, variant: str | None = None) -> Setting:
    """The [`Setting`][vcjax.search.envelope.Setting] of a sweep spec (its first variant unless
    named), gradient
    checkpointed per streamed segment."""
    from vcjax.sweep import nominal

    loop = spec.loop(variant or spec.variants[0])
    sc = spec.scenario
    config = dataclasses.replace(
        spec.mc_config(), model_fields=env.model_fields, record_stride=0, checkpoint=True
    )
    w = sc.waves
    sea = None if w is None else (w.spectrum, w.components, w.gamma)
    return Setting(
        loop=loop,
        config=config,
        dt=spec.dt,
        nominal=nominal(spec),
        diverge_e=spec.diverge_e,
        sea=sea,
        current_gm=(sc.current.sigma, sc.current.tau, sc.current.max_speed),
        noise_std=tuple(float(a) for a in np.asarray(sc.noise_std(loop)).ravel()),
        seed=spec.seed,
    )


@dataclasses.dataclass(frozen=True)
class SettingOptions:
    """What [`make_setting`][vcjax.search.envelope.make_setting] builds a
    [`Setting`][vcjax.search.envelope.Setting] from.

    Attributes:
        horizon, dt: simulated time and step [s].
        integrator: the rollout's integrator; tail: fraction of the horizon of the tail
            metrics; diverge_e: cross-track error [m] counted as diverged.
        seed: the random draws' seed.
        spectrum, components, gamma: the sea, when the envelope has one.
        nominal: ``(plant, design, coeffs)`` (default: the loop's default plant as design model,
            and its vehicle's default path coefficients).
        dtype: floating-point type of the default plant.
    """

    horizon: float = 60.0
    dt: float = 0.05
    integrator: str = "rk4"
    tail: float = 0.2
    diverge_e: float = 50.0
    seed: int = 0
    spectrum: str = "jonswap"
    components: int = 64
    gamma: float = 3.3
    nominal: Any = None
    dtype: Any = None


def make_setting(loop, env: Envelope, options: SettingOptions | None = None, **kwargs) -> Setting:
    """A [`Setting`][vcjax.search.envelope.Setting] for ``loop`` by hand: its default plant, design
    model and path
    coefficients unless ``nominal = (plant, design, coeffs)`` is given; a sea (``spectrum``,
    ``components``, ``gamma``) when the envelope has one; gradient checkpointed per segment.
    ``options``: [`SettingOptions`][vcjax.search.envelope.SettingOptions]; its fields are also
    accepted by name (``horizon=2.0``, ``dt=0.05``, ...)."""
    from vcjax._checks import with_options

    o = with_options(SettingOptions, options, kwargs, "make_setting")
    nominal, horizon, dt = o.nominal, o.horizon, o.dt
    if nominal is None:
        path, coeffs = type(loop).default_path()
        if path != loop.path:
            raise ValueError("nominal: the loop's path is not its vehicle's default; give coeffs")
        plant = loop.default_params(o.dtype)
        dt_ = jnp.asarray(jax.tree_util.tree_leaves(plant)[0]).dtype
        coeffs = jax.tree_util.tree_map(
            lambda a: (
                jnp.asarray(a, dt_) if jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating) else a
            ),
            coeffs,
        )
        nominal = (plant, plant, coeffs)
    if not (math.isfinite(horizon) and math.isfinite(dt) and 0 < dt <= horizon):
        raise ValueError(f"horizon, dt: expected 0 < dt <= horizon, got {horizon!r}, {dt!r}")
    config = MCConfig(
        num_steps=max(1, int(round(horizon / dt))),
        integrator=o.integrator,
        tail=o.tail,
        model_fields=env.model_fields,
        checkpoint=True,
    )
    if env.has_waves:
        check_wave_step(env.lo[env.names.index("wave_tp")], dt, "envelope: wave_tp")
    sea = (o.spectrum, int(o.components), float(o.gamma)) if env.has_waves else None
    noise = tuple(float(a) for a in np.asarray(loop.noise_std({})).ravel())  # none (zeros)
    return Setting(
        loop, config, float(dt), nominal, float(o.diverge_e), sea, noise_std=noise, seed=int(o.seed)
    )
