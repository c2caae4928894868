"""What a sweep simulates ([`SweepSpec`][vcjax.sweep.spec.SweepSpec]), the distribution its
scenarios are drawn from
([`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec]), and the sampling
([`sample_scenarios`][vcjax.sweep.spec.sample_scenarios] ->
[`MCScenario`][vcjax.sweep.spec.MCScenario]).

Everything a scenario draws comes from ``jax.random.fold_in(PRNGKey(seed), index)``, so
scenario ``i`` is the same whatever the chunk size, the number of devices or of hosts; its sea
(``[waves]``) included.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from vcjax import loops
from vcjax.config import ConfigError, as_choice, as_int, as_number, as_range, as_seed
from vcjax.config.scenario import ScenarioChoice
from vcjax.config.schema import MIN_SPREADING
from vcjax.environment import freeze, waves
from vcjax.environment.current import current_ned

__all__ = [
    "ScenarioSpec",
    "SweepSpec",
    "MCScenario",
    "MCConfig",
    "sample_scenarios",
    "check_wave_step",
    "spec_to_dict",
    "spec_from_dict",
]

_CURRENT_MODELS = ("constant", "gauss_markov")


@dataclasses.dataclass(frozen=True)
class ScenarioSpec:
    """The distribution scenarios are drawn from (validated on construction).

    Every ``(lo, hi)`` pair is sampled uniformly (``lo == hi``: fixed). Units: speeds [m/s],
    angles [deg] (``current_direction_deg``: towards which the water flows, clockwise from
    north), the vehicle's ``[initial]`` keys in their units (``*_deg``: degrees).
    The defaults are the paper's Simulation 1 (current 0.5 m/s towards east, the vehicle's
    default start, no model error, no noise).

    Attributes:
        initial: ``((key, (lo, hi)), ...)`` over the loop's ``initial_keys`` (missing keys:
            the loop's defaults).
        model_fields: plant parameters scaled by ``1 + model_error U(-1, 1)`` (``None``: the
            loop's ``default_model_fields()``).
        noise: ``((channel, std), ...)`` sensor-noise standard deviations over the loop's
            ``noise_channels`` (``*_deg``: degrees, deg/s).
        disturbance: per component of the generalised disturbance force, a range [N, N m]
            (empty: none).
        wave_spectrum: ``"jonswap"`` or ``"pm"``: every scenario gets a random sea
            ([`sea_state`][vcjax.environment.waves.sea_state]) of ``wave_components`` components
            with its
            own ``wave_hs`` [m], ``wave_tp`` [s], ``wave_direction_deg`` (towards, clockwise from
            north) and ``wave_origin_depth`` [m] drawn from the ranges; ``None``: no waves.
        wave_gamma: JONSWAP peak enhancement; wave_spreading: ``s`` of the ``cos^2s``
            spreading (0: long-crested).
        environment: ``((section, table), ...)``: further components of
            [`vcjax.environment`][vcjax.environment] by their section name, each table checked by
            its
            component ([`vcjax.environment.freeze`][vcjax.environment.component.freeze]) and sampled
            per scenario from the
            scenario's key.
    """

    current_speed: tuple[float, float] = (0.5, 0.5)
    current_direction_deg: tuple[float, float] = (90.0, 90.0)
    current_model: str = "constant"
    current_sigma: float = 0.05
    current_tau: float = 300.0
    current_max_speed: float = 2.0
    initial: tuple[tuple[str, tuple[float, float]], ...] = ()
    u_d: tuple[float, float] | None = None
    model_error: float = 0.0
    model_fields: tuple[str, ...] | None = None
    noise: tuple[tuple[str, float], ...] = ()
    disturbance: tuple[tuple[float, float], ...] = ()
    wave_spectrum: str | None = None
    wave_hs: tuple[float, float] = (0.0, 0.0)
    wave_tp: tuple[float, float] = (8.0, 8.0)
    wave_direction_deg: tuple[float, float] = (0.0, 0.0)
    wave_gamma: float = 3.3
    wave_spreading: float = 0.0
    wave_components: int = 64
    wave_origin_depth: tuple[float, float] = (0.0, 0.0)
    environment: tuple = ()

    def __post_init__(self):
        s = object.__setattr__
        try:
            s(self, "environment", tuple(freeze(sec, t) for sec, t in self.environment))
        except ValueError as err:
            raise ConfigError(str(err)) from None
        s(self, "current_speed", as_range("current_speed", self.current_speed, lo_min=0.0))
        s(
            self,
            "current_direction_deg",
            as_range("current_direction_deg", self.current_direction_deg),
        )
        as_choice("current_model", self.current_model, _CURRENT_MODELS)
        as_number("current_sigma", self.current_sigma, lo=0.0)
        as_number("current_tau", self.current_tau, lo=0.0, lo_open=True)
        as_number("current_max_speed", self.current_max_speed, lo=0.0, lo_open=True)
        s(self, "initial", tuple((k, as_range(k, v)) for k, v in dict(self.initial).items()))
        if self.u_d is not None:
            s(self, "u_d", as_range("u_d", self.u_d, positive=True))
        as_number("model_error", self.model_error, lo=0.0, hi=1.0, hi_open=True)
        if self.model_fields is not None:
            fields = tuple(self.model_fields)
            if len(set(fields)) != len(fields):
                raise ConfigError(f"model_fields: repeated fields in {list(fields)}")
            s(self, "model_fields", fields)
        noise = tuple((k, as_number(k, v, lo=0.0)) for k, v in dict(self.noise).items())
        s(self, "noise", noise)
        s(self, "disturbance", tuple(as_range("disturbance", r) for r in self.disturbance))
        if self.wave_spectrum is not None:
            as_choice("wave_spectrum", self.wave_spectrum, waves.SPECTRA)
        s(self, "wave_hs", as_range("wave_hs", self.wave_hs, lo_min=0.0))
        s(self, "wave_tp", as_range("wave_tp", self.wave_tp, positive=True))
        s(self, "wave_direction_deg", as_range("wave_direction_deg", self.wave_direction_deg))
        s(self, "wave_origin_depth", as_range("wave_origin_depth", self.wave_origin_depth))
        as_number("wave_gamma", self.wave_gamma, lo=1.0)
        as_number("wave_spreading", self.wave_spreading, lo=0.0)
        s(self, "wave_components", as_int("wave_components", self.wave_components, 1))
        self._check_applies()

    def _check_applies(self) -> None:
        """A field that does not apply to the others' values is refused, never ignored: sea
        fields without ``wave_spectrum`` (the scenarios would be calm), ``wave_gamma`` with the
        Pierson-Moskowitz spectrum, a ``wave_spreading`` in ``(0, 1)`` (``vcjax.config.schema.
        MIN_SPREADING``), Gauss-Markov fields with a constant current."""
        default = ScenarioSpec.__dataclass_fields__
        changed = [
            f for f in default if getattr(self, f) != default[f].default and f != "wave_spectrum"
        ]
        if not self.waves:
            sea = [f for f in changed if f.startswith("wave_")]
            if sea:
                raise ConfigError(
                    f"{sea[0]}: given without wave_spectrum, so no sea would be simulated (a "
                    f'calm run); set wave_spectrum = "jonswap" or "pm" ({", ".join(sea)})'
                )
        else:  # the NED origin must lie below the mean surface
            try:
                waves.check_origin_depth(self.wave_origin_depth, "wave_origin_depth")
            except ValueError as err:
                raise ConfigError(str(err)) from None
        if self.waves and self.wave_spectrum == "pm" and "wave_gamma" in changed:
            raise ConfigError("wave_gamma: JONSWAP's peak enhancement; wave_spectrum 'pm' has none")
        if 0.0 < self.wave_spreading < MIN_SPREADING:
            raise ConfigError(
                f"wave_spreading: 0 is long-crested and s >= {MIN_SPREADING:g} spreads as cos^2s "
                f"(1 the widest), got {self.wave_spreading:g}"
            )
        if self.current_model == "constant":
            gm = [f for f in ("current_sigma", "current_tau", "current_max_speed") if f in changed]
            if gm:
                raise ConfigError(
                    f"{gm[0]}: applies to current_model 'gauss_markov' only (the current is "
                    "constant)"
                )

    def without_waves(self) -> ScenarioSpec:
        """The same distribution in calm water (every ``wave_*`` field at its default)."""
        default = ScenarioSpec.__dataclass_fields__
        calm = {f: default[f].default for f in default if f.startswith("wave_")}
        return dataclasses.replace(self, **calm)

    @property
    def waves(self) -> bool:
        """Every scenario has a sea (``wave_spectrum`` set)."""
        return self.wave_spectrum is not None

    def check_dt(self, dt: float) -> None:
        """With waves, [`check_wave_step`][vcjax.sweep.spec.check_wave_step] of the shortest
        ``wave_tp``."""
        if self.waves:
            check_wave_step(self.wave_tp[0], dt)

    def check_for(self, loop: loops.Loop) -> None:
        """The vehicle-specific keys are the loop's (raises naming the key and listing the
        valid ones)."""
        for k, _ in self.initial:
            if k not in loop.initial_keys:
                raise ConfigError(
                    f"initial: unknown key {k!r} for vehicle {loop.vehicle!r}; "
                    f"expected {list(loop.initial_keys)}"
                )
        valid = loop.param_names()
        bad = [f for f in self.model_fields or () if f not in valid]
        if bad:
            raise ConfigError(
                f"model_fields: unknown {loop.vehicle} parameters {bad}; choose among {list(valid)}"
            )
        for k, _ in self.noise:
            if k not in loop.noise_channels:
                raise ConfigError(
                    f"noise: unknown channel {k!r} for vehicle {loop.vehicle!r}; "
                    f"expected {list(loop.noise_channels)}"
                )
        if self.waves:
            try:
                loops.check_disturbances(loop, False, False, waves=True)
            except ValueError as err:
                raise ConfigError(str(err)) from None
        if self.disturbance:
            if not loop.can_feel("force"):
                raise ConfigError(f"disturbance: the {loop.vehicle} plant takes no disturbance")
            n_nu = int(np.shape(loop.initial_from(_zeros(loop))[1])[0])
            if len(self.disturbance) != n_nu:
                raise ConfigError(
                    f"disturbance: expected {n_nu} components, got {len(self.disturbance)}"
                )

    def fields_for(self, loop: loops.Loop) -> tuple[str, ...]:
        return loop.default_model_fields() if self.model_fields is None else self.model_fields

    def noise_std(self, loop: loops.Loop) -> np.ndarray:
        """Per-entry sensor-noise standard deviations (SI: ``*_deg`` channels in radians)."""
        d = {k: math.radians(v) if k.endswith("_deg") else v for k, v in self.noise}
        return loop.noise_std(d)

    @property
    def sensor_noise(self) -> bool:
        return any(v > 0 for _, v in self.noise)


def check_wave_step(tp: float, dt: float, name: str = "wave_tp") -> None:
    """The step ``dt`` [s] resolves a sea of peak period ``tp`` [s]: its shortest component
    (``tp / 4``, the top of ``vcjax.environment.waves.BAND``) with 10 steps, ``tp >= 40 dt``
    (``ConfigError`` naming ``name``)."""
    if tp < 10.0 * waves.BAND[1] * dt:
        raise ConfigError(
            f"{name}: the shortest wave period (tp / {waves.BAND[1]:g}) needs 10 steps of "
            f"dt = {dt:g} s: tp >= {10.0 * waves.BAND[1] * dt:g} s, got {tp:g}"
        )


def _zeros(loop):
    return {k: jnp.zeros(()) for k in loop.initial_keys}


@dataclasses.dataclass(frozen=True)
class SweepSpec:
    """A whole study (validated on construction); see [`vcjax.sweep`][vcjax.sweep] for the fields.

    ``choice`` says what is simulated (vehicle, path, parameter overrides, loop options; the
    default is Simulation 1's INFANTE-class craft on the line ``[10, w]``); ``variants`` are
    that vehicle's controllers, all run on the same scenarios (paired comparison).
    """

    num_scenarios: int
    scenario: ScenarioSpec = ScenarioSpec()
    variants: tuple[str, ...] = ("vcm", "vcm_integral", "ilos", "los_pid", "vcm_ilos")
    seed: int = 0
    horizon: float = 60.0
    dt: float = 0.05
    integrator: str = "rk4"
    timing: str = "continuous"
    edd: str = "paper"
    chunk_size: int = 256
    tail: float = 0.2
    diverge_e: float = 50.0
    record_points: int = 200
    choice: ScenarioChoice = ScenarioChoice()

    def __post_init__(self):
        as_int("num_scenarios", self.num_scenarios, 1)
        object.__setattr__(self, "seed", as_seed("seed", self.seed))
        as_int("chunk_size", self.chunk_size, 1)
        as_int("record_points", self.record_points, 0)
        variants = tuple(self.variants)
        if not variants or len(set(variants)) != len(variants):
            raise ConfigError(f"variants: expected distinct variants, got {list(variants)}")
        ctrls = loops.controllers(self.choice.vehicle)
        for v in variants:
            as_choice("variants", v, ctrls)
        object.__setattr__(self, "variants", variants)
        as_number("horizon", self.horizon, lo=0.0, lo_open=True)
        as_number("dt", self.dt, lo=0.0, lo_open=True, hi=self.horizon)
        as_choice("integrator", self.integrator, ("euler", "heun", "rk4"))
        as_choice("timing", self.timing, ("continuous", "sampled"))
        as_choice("edd", self.edd, ("paper", "implied"))
        as_number("tail", self.tail, lo=0.0, lo_open=True, hi=1.0)
        as_number("diverge_e", self.diverge_e, lo=0.0, lo_open=True)
        if not isinstance(self.scenario, ScenarioSpec):
            raise ConfigError("scenario: expected a ScenarioSpec")
        self.scenario.check_dt(self.dt)
        self.scenario.check_for(self.loop(variants[0]))

    def loop(self, variant: str) -> loops.Loop:
        """The loop of ``variant`` (``edd`` applies to loops that have that option)."""
        cls = loops.loop_class(self.choice.vehicle)
        opts = {}
        if "edd" in {f.name for f in dataclasses.fields(cls)} and "edd" not in dict(
            self.choice.options
        ):
            opts["edd"] = self.edd
        return self.choice.loop(variant, **opts)

    @property
    def num_steps(self) -> int:
        return max(1, int(round(self.horizon / self.dt)))

    def mc_config(self) -> MCConfig:
        """The static part of the batched rollout."""
        n = self.num_steps
        stride = 0 if self.record_points == 0 else max(1, -(-n // self.record_points))
        return MCConfig(
            num_steps=n,
            integrator=self.integrator,
            timing=self.timing,
            current_model=self.scenario.current_model,
            sensor_noise=self.scenario.sensor_noise,
            model_fields=self.scenario.fields_for(self.loop(self.variants[0])),
            tail=self.tail,
            record_stride=stride,
            environment=self.scenario.environment,
        )


@dataclasses.dataclass(frozen=True)
class MCConfig:
    """Static settings of a batched Monte-Carlo rollout.

    Attributes:
        num_steps: rollout steps N; integrator, timing: as
            [`RolloutConfig`][vcjax.rollout.RolloutConfig].
        current_model: ``"constant"`` or ``"gauss_markov"``.
        sensor_noise: add measurement noise (``MCScenario.noise_std``) to what the controller
            sees; False skips the noise code entirely.
        model_fields: plant fields scaled by ``MCScenario.model_factors`` (same order).
        tail: steady-state window (last fraction of the run).
        record_stride: keep every ``record_stride``-th sample of ``e`` and the path (0: none).
        environment: ``((section, table), ...)`` further environment components
            (``ScenarioSpec.environment``).
        checkpoint: rematerialise each streamed segment in the backward pass (a gradient
            through the rollout, e.g. [`vcjax.search.falsify`][vcjax.search.core.falsify]; no effect
            on the values).
    """

    num_steps: int
    integrator: str = "rk4"
    timing: str = "continuous"
    current_model: str = "constant"
    sensor_noise: bool = False
    model_fields: tuple[str, ...] = ()
    tail: float = 0.2
    record_stride: int = 0
    environment: tuple = ()
    checkpoint: bool = False

    @property
    def trace_steps(self) -> np.ndarray:
        """Step indices whose ``e`` and position are recorded."""
        if self.record_stride == 0:
            return np.zeros(0, dtype=np.int64)
        return np.arange(0, self.num_steps, self.record_stride)


class MCScenario(NamedTuple):
    """One sampled scenario (traced; a batch stacks every field along a leading axis).

    Attributes:
        index: () int32 scenario number (its draws come from ``fold_in(PRNGKey(seed), index)``).
        eta0: (n_eta,) initial pose; nu0: (n_nu,) initial velocity (the loop's
            ``initial_from`` of the sampled ``[initial]`` values).
        u_d: () desired speed [m/s].
        current_speed: () mean current speed [m/s].
        current_direction: () [rad, towards, clockwise from north].
        current: (3,) mean water velocity in NED [m/s].
        current_sigma: () Gauss–Markov standard deviation [m/s] (unused by a constant current).
        current_tau: () Gauss–Markov time constant [s] (the same).
        current_max_speed: () Gauss–Markov speed bound [m/s] (the same).
        model_factors: (F,) multiplicative factors of the plant fields ``MCConfig.model_fields``.
        noise_std: (S,) sensor-noise standard deviations (SI).
        disturbance: (n_nu,) constant generalised disturbance force.
        key: (2,) uint32 PRNG key of the scenario's random processes (current, noise).
        wave_hs: () significant wave height [m] (``None`` without waves, as the next four).
        wave_tp: () peak period [s].
        wave_direction_deg: () direction the waves travel towards [deg, clockwise from north].
        wave_origin_depth: () depth of the NED origin below the mean free surface [m].
        sea: the scenario's [`vcjax.environment.waves.Sea`][vcjax.environment.waves.Sea] ((N,)
            arrays), drawn from its own
            key.
    """

    index: Any
    eta0: Any
    nu0: Any
    u_d: Any
    current_speed: Any
    current_direction: Any
    current: Any
    current_sigma: Any
    current_tau: Any
    current_max_speed: Any
    model_factors: Any
    noise_std: Any
    disturbance: Any
    key: Any
    wave_hs: Any = None
    wave_tp: Any = None
    wave_direction_deg: Any = None
    wave_origin_depth: Any = None
    sea: Any = None


def _spec_arrays(spec: ScenarioSpec, loop: loops.Loop, dtype):
    """The continuous part of ``spec`` as arrays (traced: new values do not recompile)."""
    deg = math.pi / 180.0
    init = dict(spec.initial)
    ranges = [spec.current_speed, tuple(a * deg for a in spec.current_direction_deg)]
    for k, default in loop.initial_keys.items():
        r = init.get(k, (default, default))
        ranges.append(tuple(a * deg for a in r) if k.endswith("_deg") else r)
    ranges.append(spec.u_d or (loop.default_speed,) * 2)
    f = lambda x: jnp.asarray(np.asarray(x, dtype=np.float64), dtype)
    gm = (spec.current_sigma, spec.current_tau, spec.current_max_speed)
    n_nu = int(np.shape(loop.initial_from(_zeros(loop))[1])[0])
    dist = spec.disturbance or ((0.0, 0.0),) * n_nu
    wave = (spec.wave_hs, spec.wave_tp, spec.wave_direction_deg, spec.wave_origin_depth)
    return (
        f(ranges),
        f(spec.model_error),
        f(gm),
        f(spec.noise_std(loop)),
        f(np.asarray(dist).reshape(-1, 2)),
        f(wave),
    )


def _wave_static(spec: ScenarioSpec):
    """The static part of a spec's sea (spectrum, components, gamma, spreading), or None."""
    if not spec.waves:
        return None
    return (spec.wave_spectrum, spec.wave_components, spec.wave_gamma, spec.wave_spreading)


def _draw_sea(wave_static, wave_ranges, key):
    """``(hs, tp, direction_deg, origin_depth, sea)`` of one scenario from its own key."""
    spectrum, components, gamma, spreading = wave_static
    k_par, k_sea = jax.random.split(key)
    u = jax.random.uniform(k_par, (4,), wave_ranges.dtype)
    hs, tp, direction_deg, origin_depth = (
        wave_ranges[:, 0] + (wave_ranges[:, 1] - wave_ranges[:, 0]) * u
    )  # lo == hi: exactly lo
    sea = waves.sea_state(
        k_sea,
        hs,
        tp,
        direction_deg * (math.pi / 180.0),
        spectrum=spectrum,
        gamma=gamma,
        spreading=spreading,
        components=components,
    )
    return hs, tp, direction_deg, origin_depth, sea


def _sample_one(loop, arrays, seed, index, nf: int, wave_static=None) -> MCScenario:
    ranges, model_error, gm, noise_std, dist, wave_ranges = arrays
    dtype = ranges.dtype
    key = jax.random.fold_in(jax.random.PRNGKey(seed), index)
    ks = jax.random.split(key, 9)
    u = jax.random.uniform(ks[0], (ranges.shape[0],), dtype)
    vals = ranges[:, 0] + (ranges[:, 1] - ranges[:, 0]) * u  # lo == hi: exactly lo
    speed, direction = vals[0], vals[1]
    init = {k: vals[2 + i] for i, k in enumerate(loop.initial_keys)}
    u_d = vals[-1]
    eta0, nu0 = loop.initial_from(init)
    factors = 1.0 + model_error * jax.random.uniform(ks[1], (nf,), dtype, -1.0, 1.0)
    ud = jax.random.uniform(ks[3], (dist.shape[0],), dtype)
    wave = (None,) * 5
    if wave_static is not None:
        wave = _draw_sea(wave_static, wave_ranges, ks[4])
    return MCScenario(
        index=jnp.asarray(index, jnp.int32),
        eta0=eta0,
        nu0=nu0,
        u_d=u_d,
        current_speed=speed,
        current_direction=direction,
        current=current_ned(speed, direction),
        current_sigma=gm[0],
        current_tau=gm[1],
        current_max_speed=gm[2],
        model_factors=factors,
        noise_std=noise_std,
        disturbance=dist[:, 0] + (dist[:, 1] - dist[:, 0]) * ud,
        key=ks[2],
        wave_hs=wave[0],
        wave_tp=wave[1],
        wave_direction_deg=wave[2],
        wave_origin_depth=wave[3],
        sea=wave[4],
    )


@functools.partial(jax.jit, static_argnames=("loop", "nf", "wave_static"))
def _sample(loop, arrays, seed, indices, nf, wave_static):
    return jax.vmap(lambda i: _sample_one(loop, arrays, seed, i, nf, wave_static))(indices)


def sample_scenarios(
    spec: ScenarioSpec, seed: int, indices, dtype=None, loop: loops.Loop | None = None
) -> MCScenario:
    """Draw scenarios ``indices`` (int array (B,)) of the study ``(spec, seed)`` for ``loop``
    (default: Simulation 1's INFANTE-class loop; any loop of the same vehicle gives the same
    draws).

    Scenario ``i`` depends only on ``(spec, seed, i)``; ``seed`` is an integer in
    ``0 .. vcjax.config.SEED_MAX`` (``ConfigError`` otherwise). ``dtype``: float dtype
    (default: JAX's default float). Returns an [`MCScenario`][vcjax.sweep.spec.MCScenario] with a
    leading batch axis B.
    """
    if not isinstance(spec, ScenarioSpec):
        raise ConfigError(f"spec: expected ScenarioSpec, got {type(spec).__name__}")
    loop = loops.make_loop("infante", "vcm") if loop is None else loop
    spec.check_for(loop)
    dtype = jnp.asarray(0.0).dtype if dtype is None else jnp.dtype(dtype)
    indices = jnp.asarray(indices, dtype=jnp.int32)
    arrays = _spec_arrays(spec, loop, dtype)
    nf = len(spec.fields_for(loop))
    seed = jnp.asarray(as_seed("seed", seed), jnp.uint32)  # the one seed bound (SEED_MAX)
    return _sample(loop, arrays, seed, indices, nf, _wave_static(spec))


def spec_to_dict(spec: SweepSpec) -> dict:
    """Plain-JSON form of a [`SweepSpec`][vcjax.sweep.spec.SweepSpec]."""
    d = {f.name: getattr(spec, f.name) for f in dataclasses.fields(spec)}
    sc = spec.scenario
    d["scenario"] = {f.name: getattr(sc, f.name) for f in dataclasses.fields(sc)}
    d["scenario"]["initial"] = {k: list(v) for k, v in sc.initial}
    d["scenario"]["noise"] = dict(sc.noise)
    d["choice"] = spec.choice.to_dict()
    return json.loads(json.dumps(d, default=list))


def spec_from_dict(d: dict) -> SweepSpec:
    """Inverse of [`spec_to_dict`][vcjax.sweep.spec.spec_to_dict]."""
    d = dict(d)
    sc = dict(d.pop("scenario"))
    sc["initial"] = tuple((k, tuple(v)) for k, v in sc["initial"].items())
    sc["noise"] = tuple(sc["noise"].items())
    sc["disturbance"] = tuple(tuple(r) for r in sc["disturbance"])
    for k, v in sc.items():
        if isinstance(v, list):
            sc[k] = tuple(v)
    d["variants"] = tuple(d["variants"])
    d["choice"] = ScenarioChoice.from_dict(d["choice"])
    return SweepSpec(scenario=ScenarioSpec(**sc), **d)
