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
from vcjax.config import (
    ConfigError,
    Current,
    Disturbance,
    Initial,
    ModelError,
    SensorNoise,
    Simulation,
    Waves,
    as_choice,
    as_int,
    as_number,
    as_seed,
    parse_section,
    unknown_key,
)
from vcjax.config.aliases import moved_values
from vcjax.config.scenario import ScenarioChoice, loop_options
from vcjax.config.schema import check_value
from vcjax.environment import ConstantCurrent, check_for_loop, draw_unit, freeze, waves
from vcjax.environment import Waves as WavesComponent
from vcjax.runtime import compiler

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

#: the sections a [`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec] holds, by TOML name
SECTIONS = {
    "current": Current,
    "waves": Waves,
    "initial": Initial,
    "model_error": ModelError,
    "sensor_noise": SensorNoise,
    "disturbance": Disturbance,
}
#: the flat keywords of the Python API (``ScenarioSpec(current_speed=...)``) and of the
#: ``summary.json``/``run.json`` record: keyword -> (section, key); ``u_d`` is ``[simulation]``'s
FLAT: dict[str, tuple[str, str]] = {
    **{f"current_{f.name}": ("current", f.name) for f in dataclasses.fields(Current)},
    "initial": ("initial", "values"),
    "u_d": ("simulation", "u_d"),
    "model_error": ("model_error", "relative"),
    "model_fields": ("model_error", "fields"),
    "noise": ("sensor_noise", "values"),
    "disturbance": ("disturbance", "force"),
    **{f"wave_{f.name}": ("waves", f.name) for f in dataclasses.fields(Waves)},
}
#: what the flat keywords meant for the two ``[waves]`` keys without a default
_FLAT_WAVES = {"hs": (0.0, 0.0), "tp": (8.0, 8.0)}


def _table(section) -> dict:
    """The keys of a parsed section that differ from their defaults (a TOML-like table)."""
    fields = dataclasses.fields(section)
    if len(fields) == 1 and "open_keys" in fields[0].metadata:
        return dict(getattr(section, fields[0].name))
    return {
        f.name: getattr(section, f.name) for f in fields if getattr(section, f.name) != f.default
    }


def _flat_default(sec: str, key: str):
    if sec == "waves" and key in _FLAT_WAVES:
        return _FLAT_WAVES[key]
    return next(f.default for f in dataclasses.fields(SECTIONS[sec]) if f.name == key)


def _same(a, b) -> bool:
    """Equal, a list reading as the tuple it was written from."""
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    return a == b


def _flat_sections(given: dict, flat: dict) -> dict:
    """The sections of ``given`` with the flat keywords ``flat`` written in: each touched section
    parsed again by the one validator ([`parse_section`][vcjax.config.schema.parse_section])."""
    tables: dict[str, dict] = {}
    for name, v in flat.items():
        sec, key = FLAT[name]
        if sec == "simulation":
            given["u_d"] = v
            continue
        if sec not in tables:
            old = given.get(sec)
            tables[sec] = {} if old is None else _table(old)
            if isinstance(old, Waves):  # a sea's spectrum is its switch, default or not
                tables[sec]["spectrum"] = old.spectrum
        if key == "values":
            tables[sec] = dict(v)
        elif key != "spectrum" and _same(
            v, _flat_default(sec, key)
        ):  # a default means the key was not given
            tables[sec].pop(key, None)
        else:
            tables[sec][key] = v
    if "waves" in tables:
        calm = {f.name: f.default for f in dataclasses.fields(Waves)} | _FLAT_WAVES
        sea = [f"wave_{k}" for k, v in tables["waves"].items() if k != "spectrum" and calm[k] != v]
        if tables["waves"].get("spectrum") is None and sea:
            raise ConfigError(
                f"{sea[0]}: given without wave_spectrum, so no sea would be simulated (a "
                f'calm run); set wave_spectrum = "jonswap" or "pm" ({", ".join(sea)})'
            )
        given["waves"] = None
        table = tables.pop("waves")
        if table.get("spectrum") is not None:
            tables["waves"] = _FLAT_WAVES | table
    for sec, table in tables.items():
        given[sec] = parse_section(SECTIONS[sec], table, sec)
    return given


_U_D = next(f for f in dataclasses.fields(Simulation) if f.name == "u_d")


@dataclasses.dataclass(frozen=True, init=False)
class ScenarioSpec:
    """The distribution scenarios are drawn from: the parsed sections of a config, as they are.

    Every ``(lo, hi)`` pair is sampled uniformly (``lo == hi``: fixed); the sections and their
    units are [`vcjax.config.schema`][vcjax.config.schema]'s. The defaults are the paper's
    Simulation 1 (current 0.5 m/s towards east, the vehicle's default start, no model error, no
    noise, no sea).

    Attributes:
        current: `Current` (``[current]``).
        waves: `Waves` (``[waves]``: every scenario gets a random
            sea, [`sea_state`][vcjax.environment.waves.sea_state]); ``None``: no waves.
        initial: [`Initial`][vcjax.config.schema.Initial] over the loop's ``initial_keys``
            (missing keys: the loop's defaults).
        model_error: [`ModelError`][vcjax.config.schema.ModelError] (``fields`` ``None``: the
            loop's ``default_model_fields()``).
        sensor_noise: [`SensorNoise`][vcjax.config.schema.SensorNoise] over the loop's
            ``noise_channels`` (``*_deg``: degrees, deg/s).
        disturbance: [`Disturbance`][vcjax.config.schema.Disturbance] (empty: none).
        u_d: ``[simulation] u_d`` range [m/s] (``None``: the loop's speed).
        environment: ``((section, table), ...)``: further components of
            [`vcjax.environment`][vcjax.environment] by their section name, each table checked by
            its component ([`vcjax.environment.freeze`][vcjax.environment.component.freeze]) and
            sampled per scenario from the scenario's key.

    The Python API may also write the keys flat (``ScenarioSpec(current_speed=(0, 1),
    wave_spectrum="pm", wave_hs=(1, 2), model_error=0.1)``, the names of ``FLAT``): a thin
    constructor that writes them into the sections; ``spec.current_speed`` and the other flat
    names read them back.
    """

    current: Current = Current()
    waves: Waves | None = None
    initial: Initial = Initial()
    model_error: ModelError = ModelError()
    sensor_noise: SensorNoise = SensorNoise()
    disturbance: Disturbance = Disturbance()
    u_d: tuple[float, float] | None = None
    environment: tuple = ()

    def __init__(self, **kw):
        given = {f.name: f.default for f in dataclasses.fields(self)}
        flat = {}
        for k, v in kw.items():
            cls = SECTIONS.get(k)
            if k in ("u_d", "environment") or (cls is not None and isinstance(v, cls)):
                given[k] = v
            elif k == "waves" and v is None:
                given[k] = None
            elif k in FLAT:
                flat[k] = v
            else:
                raise TypeError(f"ScenarioSpec: unexpected keyword {k!r}")
        for k, v in _flat_sections(given, flat).items():
            object.__setattr__(self, k, v)
        self.__post_init__()

    def __getattr__(self, name):
        if name not in FLAT:
            raise AttributeError(name)
        return self.flat(name)

    def flat(self, name: str):
        """The value of the flat keyword ``name`` (``FLAT``)."""
        sec, key = FLAT[name]
        if sec == "simulation":
            return self.u_d
        section = getattr(self, sec)
        if section is None:  # no sea: the flat keywords' defaults
            return _FLAT_WAVES.get(key, getattr(Waves(), key))
        return getattr(section, key)

    def __post_init__(self):
        s = object.__setattr__
        try:
            s(self, "environment", tuple(freeze(sec, t) for sec, t in self.environment))
        except ValueError as err:
            raise ConfigError(str(err)) from None
        if self.u_d is not None:
            s(self, "u_d", check_value("u_d", self.u_d, _U_D.metadata))
        if self.waves is not None:  # a section built in Python: the component's own check
            _WAVES.check(tuple((k, v) for k, v in _checked(self.waves).items() if v is not None))

    def without_waves(self) -> ScenarioSpec:
        """The same distribution in calm water."""
        return dataclasses.replace(self, waves=None)

    def check_dt(self, dt: float) -> None:
        """With waves, [`check_wave_step`][vcjax.sweep.spec.check_wave_step] of the shortest
        ``tp``."""
        if self.waves:
            check_wave_step(self.waves.tp[0], dt, "[waves] tp")

    def check_for(self, loop: loops.Loop) -> None:
        """The vehicle-specific keys are the loop's (raises naming the key and listing the
        valid ones)."""
        for k, _ in self.initial.values:
            if k not in loop.initial_keys:
                note = f"for vehicle {loop.vehicle!r}"
                raise ConfigError(unknown_key("initial", k, loop.initial_keys, note))
        valid = loop.param_names()
        bad = [f for f in self.model_error.fields or () if f not in valid]
        if bad:
            raise ConfigError(
                f"[model_error] fields: unknown {loop.vehicle} parameters {bad}; choose among "
                f"{list(valid)}"
            )
        for k, _ in self.sensor_noise.values:
            if k not in loop.noise_channels:
                note = f"(channel) for vehicle {loop.vehicle!r}"
                raise ConfigError(unknown_key("sensor_noise", k, loop.noise_channels, note))
        try:  # each component as it is for this loop
            check_for_loop(loop, self.environment)
        except ValueError as err:
            raise ConfigError(str(err)) from None
        if self.waves:
            try:
                loops.check_disturbances(loop, False, False, waves=True)
            except ValueError as err:
                raise ConfigError(str(err)) from None
        force = self.disturbance.force
        if force:
            if not loop.can_feel("force"):
                raise ConfigError(f"[disturbance]: the {loop.vehicle} plant takes no disturbance")
            n_nu = int(np.shape(loop.initial_from(_zeros(loop))[1])[0])
            if len(force) != n_nu:
                raise ConfigError(f"[disturbance]: expected {n_nu} components, got {len(force)}")

    def fields_for(self, loop: loops.Loop) -> tuple[str, ...]:
        fields = self.model_error.fields
        return loop.default_model_fields() if fields is None else fields

    def noise_std(self, loop: loops.Loop) -> np.ndarray:
        """Per-entry sensor-noise standard deviations (SI: ``*_deg`` channels in radians)."""
        d = {k: math.radians(v) if k.endswith("_deg") else v for k, v in self.sensor_noise.values}
        return loop.noise_std(d)

    @property
    def noisy(self) -> bool:
        """Some sensor-noise standard deviation is positive."""
        return any(v > 0 for _, v in self.sensor_noise.values)


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
        as_number("tail", self.tail, lo=0.0, lo_open=True, hi=1.0)
        as_number("diverge_e", self.diverge_e, lo=0.0, lo_open=True)
        if not isinstance(self.scenario, ScenarioSpec):
            raise ConfigError("scenario: expected a ScenarioSpec")
        self.scenario.check_dt(self.dt)
        self.scenario.check_for(self.loop(variants[0]))

    def loop(self, variant: str) -> loops.Loop:
        """The loop of ``variant`` (with ``choice``'s path and options)."""
        return self.choice.loop(variant)

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
            current_model=self.scenario.current.model,
            sensor_noise=self.scenario.noisy,
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


#: the components that draw a scenario's current and sea (their sections are declared there)
_CURRENT = ConstantCurrent()
_WAVES = WavesComponent()


def _checked(section) -> dict:
    """A parsed section as the checked table its component samples from."""
    return {f.name: getattr(section, f.name) for f in dataclasses.fields(section)}


def _sample_one(loop, spec: ScenarioSpec, dtype, seed, index) -> MCScenario:
    """One scenario of ``spec``: every draw from ``fold_in(PRNGKey(seed), index)``.

    The scenario's first stream holds one uniform number per sampled start value: the current's
    speed and direction (drawn by the ``[current]`` component), each initial key, the desired
    speed; the others hold the model error, the process key, the disturbance, the sea (drawn
    by the ``[waves]`` component) and the current component's own key (further keys of
    ``[current]``)."""
    key = jax.random.fold_in(jax.random.PRNGKey(seed), index)
    ks = jax.random.split(key, 9)
    n_init = len(loop.initial_keys)
    u = jax.random.uniform(ks[0], (3 + n_init,), dtype)
    current = _checked(spec.current)
    speed, direction, velocity = _CURRENT.draw_mean(u[:2], ks[5], current)
    given = dict(spec.initial.values)
    init = {}
    for i, (k, default) in enumerate(loop.initial_keys.items()):
        r = given.get(k, (default, default))
        r = tuple(a * (math.pi / 180.0) for a in r) if k.endswith("_deg") else tuple(r)
        init[k] = draw_unit(u[2 + i], r, dtype)
    u_d = draw_unit(u[-1], tuple(spec.u_d or (loop.default_speed,) * 2), dtype)
    eta0, nu0 = loop.initial_from(init)
    nf = len(spec.fields_for(loop))
    relative = jnp.asarray(spec.model_error.relative, dtype)
    factors = 1.0 + relative * jax.random.uniform(ks[1], (nf,), dtype, -1.0, 1.0)
    n_nu = int(np.shape(nu0)[0])
    dist = jnp.asarray(np.asarray(spec.disturbance.force or ((0.0, 0.0),) * n_nu), dtype)
    ud = jax.random.uniform(ks[3], (dist.shape[0],), dtype)
    sea = None
    if spec.waves is not None:
        sea = _WAVES.sample(ks[4], _checked(spec.waves), dtype)
    f = lambda x: jnp.asarray(x, dtype)
    cur = spec.current
    return MCScenario(
        index=jnp.asarray(index, jnp.int32),
        eta0=eta0,
        nu0=nu0,
        u_d=u_d,
        current_speed=speed,
        current_direction=direction,
        current=velocity,
        current_sigma=f(cur.sigma),
        current_tau=f(cur.tau),
        current_max_speed=f(cur.max_speed),
        model_factors=factors,
        noise_std=f(spec.noise_std(loop)),
        disturbance=dist[:, 0] + (dist[:, 1] - dist[:, 0]) * ud,
        key=ks[2],
        wave_hs=None if sea is None else sea.hs,
        wave_tp=None if sea is None else sea.tp,
        wave_direction_deg=None if sea is None else sea.direction_deg,
        wave_origin_depth=None if sea is None else sea.origin_depth,
        sea=None if sea is None else sea.sea,
    )


# light: it runs once per chunk and compiles in a fifth of the time, drawing the same bits
# (vcjax.runtime.compiler's docstring; tests/test_compiler.py)
@functools.partial(compiler.jit, static_argnames=("loop", "spec", "dtype"), light=True)
def _sample(loop, spec, dtype, seed, indices):
    return jax.vmap(lambda i: _sample_one(loop, spec, jnp.dtype(dtype), seed, i))(indices)


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
    seed = jnp.asarray(as_seed("seed", seed), jnp.uint32)  # the one seed bound (SEED_MAX)
    return _sample(loop, spec, dtype.name, seed, indices)


def _thaw(v):
    if isinstance(v, tuple):
        return [_thaw(a) for a in v]
    return v


def scenario_record(sc: ScenarioSpec) -> dict:
    """The flat record of a [`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec] (``FLAT`` names, as
    ``summary.json`` and ``run.json`` have always written it)."""
    d = {name: _thaw(sc.flat(name)) for name in FLAT}
    d["initial"] = {k: list(v) for k, v in sc.initial.values}
    d["noise"] = dict(sc.sensor_noise.values)
    d["wave_spectrum"] = None if sc.waves is None else sc.waves.spectrum
    d["environment"] = _thaw(sc.environment)
    return d


def spec_to_dict(spec: SweepSpec) -> dict:
    """Plain-JSON form of a [`SweepSpec`][vcjax.sweep.spec.SweepSpec] (the loop options that
    moved to ``[scenario]`` recorded at the top as well, where they were)."""
    d = {f.name: getattr(spec, f.name) for f in dataclasses.fields(spec)}
    d["scenario"] = scenario_record(spec.scenario)
    d["choice"] = spec.choice.to_dict()
    d |= moved_values(spec.choice)
    return json.loads(json.dumps(d, default=list))


def spec_from_dict(d: dict) -> SweepSpec:
    """Inverse of [`spec_to_dict`][vcjax.sweep.spec.spec_to_dict]."""
    d = dict(d)
    sc = dict(d.pop("scenario"))
    sc["initial"] = tuple((k, tuple(v)) for k, v in sc["initial"].items())
    sc["noise"] = tuple(sc["noise"].items())
    sc["disturbance"] = tuple(tuple(r) for r in sc["disturbance"])
    sc["environment"] = tuple((s, tuple(map(tuple, t))) for s, t in sc.get("environment", ()))
    for k, v in sc.items():
        if isinstance(v, list):
            sc[k] = tuple(v)
    d["variants"] = tuple(d["variants"])
    choice = ScenarioChoice.from_dict(d["choice"])
    moved = {k: d.pop(k) for k in moved_values(choice) if k in d}
    opts = loop_options(loops.loop_class(choice.vehicle))
    given = dict(choice.options)
    older = {k: v for k, v in moved.items() if k in opts and k not in given}
    older = {k: v for k, v in older.items() if v != opts[k]["default"]}
    d["choice"] = dataclasses.replace(choice, options=(*choice.options, *older.items()))
    return SweepSpec(scenario=ScenarioSpec(**sc), **d)
