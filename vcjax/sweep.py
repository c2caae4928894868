"""Batch Monte-Carlo studies of Simulation 1: ``vmap`` over scenarios, chunks, devices, hosts.

A sweep runs every controller variant of :mod:`vcjax.sim1` (``vcm``, ``vcm_integral``, ``ilos``,
``los_pid``) on the *same* batch of sampled scenarios (paired comparison). A scenario draws:

* the ocean current: mean speed [m/s] and direction [deg, towards which the water flows,
  clockwise from north]; constant, or slowly varying as a first-order Gauss–Markov process
  around that mean (:mod:`vcjax.currents`, exact discretisation, clipped to a maximum speed);
* the initial state: position ``x0, y0`` [m], heading [deg], surge speed [m/s]; and the desired
  speed ``u_d`` [m/s];
* multiplicative model errors: each listed :class:`~vcjax.vehicles.infante.InfanteParams` field
  of the *plant* is multiplied by ``1 + relative * U(-1, 1)`` (independently per field); the
  controllers keep the nominal ``design_vehicle``;
* sensor noise: white Gaussian noise on the measured ``eta``/``nu`` the controller sees, drawn per
  step from ``jax.random.fold_in(key, k)`` (held over the step), standard deviations fixed by the
  study.

Everything a scenario draws comes from ``jax.random.fold_in(PRNGKey(seed), index)``, so scenario
``i`` is the same whatever the chunk size, the number of devices or of hosts.

Layers (each usable on its own):

* :func:`sample_scenarios` -> :class:`MCScenario` (batched arrays);
* :func:`simulate_scenario` (one scenario, pure; ``jax.vmap`` it) and :func:`scenario_metrics`
  (the Simulation 1 metrics and health flags, in JAX);
* :func:`run_batch`: jitted ``vmap`` of both over a batch (one compile per variant and static
  :class:`MCConfig`);
* :func:`run_sweep`: a whole :class:`SweepSpec` in fixed-size chunks (last one padded, so one
  compile), the scenario axis sharded over the local devices, a progress bar on stderr; in a
  multi-process run each process takes its share of chunks;
* :func:`summarize`, :func:`save_results`, :func:`load_results`, :func:`merge_results`;
* :func:`run_sweep_config`: TOML file -> ``summary.json``, ``results.npz`` and figures.

TOML schema (every key optional unless marked; a value written ``range`` is either a number
(fixed) or a two-element list ``[lo, hi]`` sampled uniformly)::

    [sweep]
    num_scenarios = 64          # int >= 1 (required)
    seed = 0                    # int >= 0
    variants = ["vcm", "vcm_integral", "ilos", "los_pid"]
    chunk_size = 256            # int >= 1, scenarios per compiled batch (rounded up to a
                                # multiple of the device count)

    [simulation]
    horizon = 60.0              # s, > 0
    dt = 0.05                   # s, > 0, <= horizon
    integrator = "rk4"          # "euler" | "heun" | "rk4"
    timing = "continuous"       # "continuous" | "sampled"
    edd = "paper"               # VCM e_ddot mode: "paper" | "implied"
    u_d = 2.0                   # range, m/s, desired surge speed (> 0)
    gains = "gains.json"        # optional gains file (vcjax simulate --gains format),
                                # relative to the config file

    [current]
    model = "constant"          # "constant" | "gauss_markov"
    speed = [0.0, 1.0]          # range, m/s (mean speed), >= 0
    direction_deg = [0, 360]    # range, deg, towards which the current flows
    sigma = 0.05                # m/s, stationary std of each fluctuation component (GM only)
    tau = 300.0                 # s, correlation time (GM only)
    max_speed = 2.0             # m/s, speed bound of the current handed to the plant (GM only)

    [initial]
    x = 0.0                     # range, m (the path is the line x = 10 m, heading east)
    y = 0.0                     # range, m
    heading_deg = 90.0          # range, deg
    speed = 2.0                 # range, m/s, initial surge speed

    [model_error]
    relative = 0.0              # in [0, 1): factor 1 + relative * U(-1, 1) per field
    fields = [...]              # InfanteParams scalar fields (default: DEFAULT_MODEL_FIELDS)

    [sensor_noise]
    position_std = 0.0          # m (x and y)
    heading_std_deg = 0.0       # deg
    velocity_std = 0.0          # m/s (u and v)
    yaw_rate_std_deg = 0.0      # deg/s

    [metrics]
    tail = 0.2                  # in (0, 1]: steady-state window, last fraction of the run
    diverge_e = 50.0            # m, > 0: a run with max |e| above it counts as diverged

    [output]
    record_points = 200         # int >= 0: cross-track error / path samples kept per run
                                # (0: none; the envelope and path figures then are skipped)
    figures = true

Metrics (per scenario and variant; :data:`METRICS`), evaluated on the *true* state (with sensor
noise the controller's own error signals differ): ``ss_abs_e``, ``ss_abs_s``, ``ss_abs_u_err``
(mean |.| over the last ``tail`` of the run [m, m, m/s]), ``iae_e`` [m s], ``max_abs_e`` [m],
``max_abs_tau_u`` [N], ``max_abs_rudder_deg`` [deg], ``sat_fraction``; health flags
``nonfinite`` (a step produced NaN/inf: the rollout froze the state) and ``diverged``
(``nonfinite`` or ``max_abs_e > diverge_e``). Summaries use the runs that did not diverge.

Precision follows JAX's default float (the CLI enables float64 unless told otherwise).
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from vcjax import paths, sim1
from vcjax.currents import GaussMarkovCurrent, current_vector, gm_init, gm_step, gm_value
from vcjax.linalg import rot2
from vcjax.progress import ProgressBar
from vcjax.rollout import RolloutConfig, Trajectory, rollout
from vcjax.vehicles import infante

__all__ = [
    "DEFAULT_MODEL_FIELDS",
    "METRICS",
    "FLAGS",
    "ScenarioSpec",
    "SweepSpec",
    "MCScenario",
    "MCConfig",
    "SweepResult",
    "SweepConfigError",
    "sample_scenarios",
    "perturb_vehicle",
    "simulate_scenario",
    "scenario_metrics",
    "run_batch",
    "run_sweep",
    "summarize",
    "save_results",
    "load_results",
    "merge_results",
    "load_config",
    "run_sweep_config",
]

#: Plant fields perturbed by default: inertia, added mass, hydrodynamic and rudder coefficients.
DEFAULT_MODEL_FIELDS = infante.INERTIA_FIELDS + infante.HYDRODYNAMIC_FIELDS
_SCALAR_FIELDS = tuple(f for f in infante.InfanteParams._fields if f != "cf_x")

#: Per-scenario metrics (float), see the module docstring.
METRICS = (
    "ss_abs_e",
    "ss_abs_s",
    "ss_abs_u_err",
    "iae_e",
    "max_abs_e",
    "max_abs_tau_u",
    "max_abs_rudder_deg",
    "sat_fraction",
)
#: Per-scenario health flags (bool).
FLAGS = ("nonfinite", "diverged")

_CURRENT_MODELS = ("constant", "gauss_markov")


class SweepConfigError(ValueError):
    """An invalid sweep specification or TOML file (the message names the key)."""


# --------------------------------------------------------------------------------------------
# Static specification
# --------------------------------------------------------------------------------------------


def _range(name, v, lo_min=None, positive=False) -> tuple[float, float]:
    if isinstance(v, bool) or not isinstance(v, int | float | tuple | list):
        raise SweepConfigError(f"{name}: expected a number or [lo, hi], got {v!r}")
    if isinstance(v, int | float):
        v = (v, v)
    if len(v) != 2 or any(isinstance(a, bool) or not isinstance(a, int | float) for a in v):
        raise SweepConfigError(f"{name}: expected a number or a list [lo, hi], got {list(v)!r}")
    lo, hi = float(v[0]), float(v[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise SweepConfigError(f"{name}: expected finite lo <= hi, got [{lo}, {hi}]")
    if lo_min is not None and lo < lo_min:
        raise SweepConfigError(f"{name}: values must be >= {lo_min}, got [{lo}, {hi}]")
    if positive and lo <= 0:
        raise SweepConfigError(f"{name}: values must be > 0, got [{lo}, {hi}]")
    return lo, hi


def _number(name, v, lo=None, lo_open=False, hi=None, hi_open=False) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise SweepConfigError(f"{name}: expected a finite number, got {v!r}")
    v = float(v)
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise SweepConfigError(f"{name}: expected a value {'>' if lo_open else '>='} {lo}, got {v}")
    if hi is not None and (v >= hi if hi_open else v > hi):
        raise SweepConfigError(f"{name}: expected a value {'<' if hi_open else '<='} {hi}, got {v}")
    return v


def _int(name, v, lo) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise SweepConfigError(f"{name}: expected an integer, got {v!r}")
    if v < lo:
        raise SweepConfigError(f"{name}: expected an integer >= {lo}, got {v}")
    return v


def _choice(name, v, choices) -> str:
    if v not in choices:
        raise SweepConfigError(f"{name}: expected one of {list(choices)}, got {v!r}")
    return v


@dataclasses.dataclass(frozen=True)
class ScenarioSpec:
    """The distribution scenarios are drawn from (validated on construction).

    Every ``(lo, hi)`` pair is sampled uniformly (``lo == hi``: fixed). Units: speeds [m/s],
    positions [m], angles [deg] (``direction_deg``: towards which the current flows, clockwise
    from north), noise standard deviations in the unit of the signal (``*_deg``: deg, deg/s).
    The defaults are the paper's Simulation 1 (current 0.5 m/s towards east, start at the
    origin heading east at 2 m/s, no model error, no noise).
    """

    current_speed: tuple[float, float] = (0.5, 0.5)
    current_direction_deg: tuple[float, float] = (90.0, 90.0)
    current_model: str = "constant"
    current_sigma: float = 0.05
    current_tau: float = 300.0
    current_max_speed: float = 2.0
    x0: tuple[float, float] = (0.0, 0.0)
    y0: tuple[float, float] = (0.0, 0.0)
    heading0_deg: tuple[float, float] = (90.0, 90.0)
    speed0: tuple[float, float] = (2.0, 2.0)
    u_d: tuple[float, float] = (2.0, 2.0)
    model_error: float = 0.0
    model_fields: tuple[str, ...] = DEFAULT_MODEL_FIELDS
    position_noise_std: float = 0.0
    heading_noise_std_deg: float = 0.0
    velocity_noise_std: float = 0.0
    yaw_rate_noise_std_deg: float = 0.0

    def __post_init__(self):
        s = object.__setattr__
        s(self, "current_speed", _range("current_speed", self.current_speed, lo_min=0.0))
        for name in ("current_direction_deg", "x0", "y0", "heading0_deg", "speed0"):
            s(self, name, _range(name, getattr(self, name)))
        _choice("current_model", self.current_model, _CURRENT_MODELS)
        _number("current_sigma", self.current_sigma, lo=0.0)
        _number("current_tau", self.current_tau, lo=0.0, lo_open=True)
        _number("current_max_speed", self.current_max_speed, lo=0.0, lo_open=True)
        s(self, "u_d", _range("u_d", self.u_d, positive=True))
        _number("model_error", self.model_error, lo=0.0, hi=1.0, hi_open=True)
        fields = tuple(self.model_fields)
        bad = [f for f in fields if f not in _SCALAR_FIELDS]
        if bad or len(set(fields)) != len(fields):
            raise SweepConfigError(
                f"model_fields: unknown or repeated InfanteParams fields {bad or fields}; "
                f"choose among {list(_SCALAR_FIELDS)}"
            )
        s(self, "model_fields", fields)
        for name in (
            "position_noise_std",
            "heading_noise_std_deg",
            "velocity_noise_std",
            "yaw_rate_noise_std_deg",
        ):
            _number(name, getattr(self, name), lo=0.0)

    @property
    def noise_std(self) -> np.ndarray:
        """(6,) sensor-noise standard deviations on ``[x, y, psi, u, v, r]`` (SI units)."""
        p, v = self.position_noise_std, self.velocity_noise_std
        h, r = math.radians(self.heading_noise_std_deg), math.radians(self.yaw_rate_noise_std_deg)
        return np.array([p, p, h, v, v, r])

    @property
    def sensor_noise(self) -> bool:
        return bool(np.any(self.noise_std > 0))


@dataclasses.dataclass(frozen=True)
class SweepSpec:
    """A whole study (validated on construction); see the module docstring for the fields."""

    num_scenarios: int
    scenario: ScenarioSpec = ScenarioSpec()
    variants: tuple[str, ...] = sim1.VARIANTS
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

    def __post_init__(self):
        _int("num_scenarios", self.num_scenarios, 1)
        _int("seed", self.seed, 0)
        _int("chunk_size", self.chunk_size, 1)
        _int("record_points", self.record_points, 0)
        variants = tuple(self.variants)
        if not variants or len(set(variants)) != len(variants):
            raise SweepConfigError(f"variants: expected distinct variants, got {list(variants)}")
        for v in variants:
            _choice("variants", v, sim1.VARIANTS)
        object.__setattr__(self, "variants", variants)
        _number("horizon", self.horizon, lo=0.0, lo_open=True)
        _number("dt", self.dt, lo=0.0, lo_open=True, hi=self.horizon)
        _choice("integrator", self.integrator, ("euler", "heun", "rk4"))
        _choice("timing", self.timing, ("continuous", "sampled"))
        _choice("edd", self.edd, ("paper", "implied"))
        _number("tail", self.tail, lo=0.0, lo_open=True, hi=1.0)
        _number("diverge_e", self.diverge_e, lo=0.0, lo_open=True)
        if not isinstance(self.scenario, ScenarioSpec):
            raise SweepConfigError("scenario: expected a ScenarioSpec")

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
            edd=self.edd,
            current_model=self.scenario.current_model,
            sensor_noise=self.scenario.sensor_noise,
            model_fields=self.scenario.model_fields,
            tail=self.tail,
            record_stride=stride,
        )


# --------------------------------------------------------------------------------------------
# Scenarios
# --------------------------------------------------------------------------------------------


class MCScenario(NamedTuple):
    """One sampled scenario (traced; a batch stacks every field along a leading axis).

    Attributes:
        index: () int32 scenario number (its draws come from ``fold_in(PRNGKey(seed), index)``).
        eta0: (3,) initial pose ``[x, y, psi]`` [m, m, rad]; nu0: (3,) initial ``[u, 0, 0]``.
        u_d: () desired surge speed [m/s].
        current_speed: () mean current speed [m/s]; current_direction: () [rad, towards,
            clockwise from north]; V_c: (2,) mean current in NED [m/s].
        current_sigma, current_tau, current_max_speed: () Gauss–Markov parameters
            [m/s, s, m/s] (unused by a constant current).
        model_factors: (F,) multiplicative factors of the plant fields ``MCConfig.model_fields``.
        noise_std: (6,) sensor-noise standard deviations on ``[x, y, psi, u, v, r]`` (SI).
        key: (2,) uint32 PRNG key of the scenario's random processes (current, noise).
    """

    index: Any
    eta0: Any
    nu0: Any
    u_d: Any
    current_speed: Any
    current_direction: Any
    V_c: Any
    current_sigma: Any
    current_tau: Any
    current_max_speed: Any
    model_factors: Any
    noise_std: Any
    key: Any


def _spec_arrays(spec: ScenarioSpec, dtype):
    """The continuous part of ``spec`` as arrays (traced: new values do not recompile)."""
    deg = math.pi / 180.0
    ranges = [
        spec.current_speed,
        tuple(a * deg for a in spec.current_direction_deg),
        spec.x0,
        spec.y0,
        tuple(a * deg for a in spec.heading0_deg),
        spec.speed0,
        spec.u_d,
    ]
    f = lambda x: jnp.asarray(np.asarray(x, dtype=np.float64), dtype)
    gm = (spec.current_sigma, spec.current_tau, spec.current_max_speed)
    return f(ranges), f(spec.model_error), f(gm), f(spec.noise_std)


def _sample_one(arrays, seed, index, nf: int) -> MCScenario:
    ranges, model_error, gm, noise_std = arrays
    dtype = ranges.dtype
    key = jax.random.fold_in(jax.random.PRNGKey(seed), index)
    ks = jax.random.split(key, 9)
    u = jax.random.uniform(ks[0], (ranges.shape[0],), dtype)
    vals = ranges[:, 0] + (ranges[:, 1] - ranges[:, 0]) * u  # lo == hi: exactly lo
    speed, direction, x0, y0, psi0, speed0, u_d = (vals[i] for i in range(7))
    zero = jnp.zeros((), dtype)
    factors = 1.0 + model_error * jax.random.uniform(ks[1], (nf,), dtype, -1.0, 1.0)
    return MCScenario(
        index=jnp.asarray(index, jnp.int32),
        eta0=jnp.stack([x0, y0, psi0]),
        nu0=jnp.stack([speed0, zero, zero]),
        u_d=u_d,
        current_speed=speed,
        current_direction=direction,
        V_c=current_vector(speed, direction),
        current_sigma=gm[0],
        current_tau=gm[1],
        current_max_speed=gm[2],
        model_factors=factors,
        noise_std=noise_std,
        key=ks[2],
    )


@functools.partial(jax.jit, static_argnames=("nf",))
def _sample(arrays, seed, indices, nf):
    return jax.vmap(lambda i: _sample_one(arrays, seed, i, nf))(indices)


def sample_scenarios(spec: ScenarioSpec, seed: int, indices, dtype=None) -> MCScenario:
    """Draw scenarios ``indices`` (int array (B,)) of the study ``(spec, seed)``.

    Scenario ``i`` depends only on ``(spec, seed, i)``. ``dtype``: float dtype (default: JAX's
    default float). Returns an :class:`MCScenario` with a leading batch axis B.
    """
    if not isinstance(spec, ScenarioSpec):
        raise SweepConfigError(f"spec: expected ScenarioSpec, got {type(spec).__name__}")
    dtype = jnp.asarray(0.0).dtype if dtype is None else jnp.dtype(dtype)
    indices = jnp.asarray(indices, dtype=jnp.int32)
    arrays = _spec_arrays(spec, dtype)
    return _sample(arrays, jnp.asarray(seed, jnp.uint32), indices, len(spec.model_fields))


# --------------------------------------------------------------------------------------------
# One scenario: closed loop and metrics (pure; vmap them)
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class MCConfig:
    """Static settings of a batched Monte-Carlo rollout.

    Attributes:
        num_steps: rollout steps N; integrator, timing: as :class:`~vcjax.rollout.RolloutConfig`.
        edd: VCM ``e_ddot`` mode; smooth: smooth actuator saturation (for gradients).
        current_model: ``"constant"`` or ``"gauss_markov"``.
        sensor_noise: add measurement noise (``MCScenario.noise_std``) to what the controller
            sees; False skips the noise code entirely.
        model_fields: plant fields scaled by ``MCScenario.model_factors`` (same order).
        tail: steady-state window (last fraction of the run).
        record_stride: keep every ``record_stride``-th sample of ``e`` and the path (0: none).
    """

    num_steps: int
    integrator: str = "rk4"
    timing: str = "continuous"
    edd: str = "paper"
    smooth: bool = False
    current_model: str = "constant"
    sensor_noise: bool = False
    model_fields: tuple[str, ...] = ()
    tail: float = 0.2
    record_stride: int = 0

    @property
    def rollout_config(self) -> RolloutConfig:
        return RolloutConfig(
            num_steps=self.num_steps, integrator=self.integrator, timing=self.timing
        )

    @property
    def trace_steps(self) -> np.ndarray:
        """Step indices whose ``e`` and position are recorded."""
        if self.record_stride == 0:
            return np.zeros(0, dtype=np.int64)
        return np.arange(0, self.num_steps, self.record_stride)


def perturb_vehicle(nominal: infante.InfanteParams, fields: tuple[str, ...], factors):
    """Plant parameters with ``nominal.<fields[j]> * factors[j]`` (pure, traced ``factors``)."""
    return nominal._replace(**{f: getattr(nominal, f) * factors[j] for j, f in enumerate(fields)})


@dataclasses.dataclass(frozen=True)
class _MCLoop:
    plant: Callable
    controller: Callable
    exogenous: Callable


@functools.cache
def _mc_loop(variant: str, edd: str, smooth: bool, gm: bool, noise: bool) -> _MCLoop:
    """Simulation 1's loop with a per-step current and measurement noise (cached: one trace)."""
    base = sim1.closed_loop(variant, edd, smooth)

    def exogenous(k, t, s, plant_params, ctrl_params):
        args, gm_p, key_steps, dt = plant_params
        ctrl, noise_std, key_noise = ctrl_params
        if gm:
            # current on [t_k, t_k + dt]: linear between the exact GM samples, V_c_dot its slope
            d_next = gm_step(gm_p, s, dt, jax.random.fold_in(key_steps, k))
            V0, V1 = gm_value(gm_p, s), gm_value(gm_p, d_next)
            args = args._replace(V_c=V0, V_c_dot=(V1 - V0) / dt)
            s = d_next
        n = None
        if noise:
            n = noise_std * jax.random.normal(
                jax.random.fold_in(key_noise, k), (6,), noise_std.dtype
            )
        return s, (args, t), (ctrl, n)

    def plant(t, x, u, params):
        args, t_k = params
        if gm:
            args = args._replace(V_c=args.V_c + (t - t_k) * args.V_c_dot)
        return base.plant(t, x, u, args)

    def controller(t, x, z, params):
        ctrl, n = params
        if noise:
            x = x._replace(eta=x.eta + n[:3], nu=x.nu + n[3:])
        return base.controller(t, x, z, ctrl)

    return _MCLoop(plant=plant, controller=controller, exogenous=exogenous)


def _process_keys(key):
    """(current init, current steps, noise) keys of a scenario (see ``gm_sample_path``)."""
    k_cur, k_noise = jax.random.split(key)
    k_init, k_steps = jax.random.split(k_cur)
    return k_init, k_steps, k_noise


def _sim1_scenario(nominal, sc: MCScenario, config: MCConfig) -> sim1.Sim1Scenario:
    vehicle = perturb_vehicle(nominal, config.model_fields, sc.model_factors)
    return sim1.Sim1Scenario(
        eta0=sc.eta0,
        nu0=sc.nu0,
        V_c=sc.V_c,
        u_d=sc.u_d,
        vehicle=vehicle,
        path=sim1.path_coeffs(sc.eta0.dtype),
        design_vehicle=nominal,
    )


def simulate_scenario(
    variant: str, gains: sim1.Sim1Gains, nominal, sc: MCScenario, config: MCConfig, dt
) -> Trajectory:
    """Closed-loop rollout of one controller on one sampled scenario (pure, not jitted).

    ``variant`` and ``config`` are static; ``gains``, ``nominal`` (the design vehicle, an
    :class:`~vcjax.vehicles.infante.InfanteParams`), ``sc`` and ``dt`` [s] are traced. With a
    constant current and no sensor noise this *is* :func:`vcjax.sim1.simulate` on the equivalent
    :class:`~vcjax.sim1.Sim1Scenario`; otherwise the same loop gets a Gauss–Markov current and/or
    measurement noise through :func:`~vcjax.rollout.rollout`'s ``exogenous`` hook.
    """
    s1 = _sim1_scenario(nominal, sc, config)
    rcfg = config.rollout_config
    gm = config.current_model == "gauss_markov"
    if not gm and not config.sensor_noise:
        return sim1.simulate(variant, gains, s1, rcfg, dt, config.edd, config.smooth)

    dtype = sc.eta0.dtype
    dt = jnp.asarray(dt, dtype)
    loop = _mc_loop(variant, config.edd, config.smooth, gm, config.sensor_noise)
    k_init, k_steps, k_noise = _process_keys(sc.key)
    gm_p = GaussMarkovCurrent(sc.V_c, sc.current_sigma, sc.current_tau, sc.current_max_speed)
    s0 = gm_init(gm_p, k_init) if gm else None
    x0 = infante.InfanteState(eta=sc.eta0, nu=sc.nu0, act=jnp.zeros(2, dtype))
    z0 = sim1.initial_controller_state(variant, s1)
    args = infante.PlantArgs(vehicle=s1.vehicle, V_c=sc.V_c, V_c_dot=jnp.zeros(2, dtype))
    ctrl = (sim1.controller_params(variant, gains, s1), nominal)
    return rollout(
        loop.plant,
        loop.controller,
        rcfg,
        (args, gm_p, k_steps, dt),
        (ctrl, sc.noise_std, k_noise),
        x0,
        z0,
        dt,
        exogenous=loop.exogenous,
        s0=s0,
    )


def scenario_metrics(traj: Trajectory, sc: MCScenario, vehicle, config: MCConfig, diverge_e):
    """Simulation 1 metrics and health flags of one run, in JAX (vmap/jit-safe).

    Errors are those of the *true* pose: with sensor noise they are recomputed from the pose and
    the path particle (the controller's own ``aux.eps`` contains the noise), without it they are
    the controller's ``aux.eps`` and ``aux.u_tilde`` (as :func:`vcjax.sim1.tracking_metrics`).

    Args:
        traj: the rollout; sc: its scenario (``u_d``); vehicle: the plant's parameters
            (actuator limits); config: static :class:`MCConfig`; diverge_e: () [m].

    Returns:
        ``(metrics, traces)``: ``metrics`` maps :data:`METRICS` and :data:`FLAGS` to () arrays;
        ``traces`` maps ``"e"`` (P,) and ``"xy"`` (P, 2) to float32 samples at
        ``config.trace_steps``.
    """
    n = traj.u.shape[0]
    eta = traj.x.eta[:n]
    if config.sensor_noise:
        coeffs = sim1.path_coeffs(eta.dtype)
        frames = jax.vmap(lambda w: paths.path_frame(sim1.PATH, coeffs, w))(traj.z.varpi[:n])
        eps = jax.vmap(lambda psi_p, p_bar, xy: rot2(psi_p).T @ (xy - p_bar))(
            frames.psi_p, frames.p_bar, eta[:, :2]
        )
        u_err = traj.x.nu[:n, 0] - sc.u_d
    else:  # the controller saw the true state: its errors are the true ones
        eps, u_err = traj.aux.eps, traj.aux.u_tilde
    k0 = int(math.floor((1.0 - config.tail) * n))
    dt = traj.t[1] - traj.t[0]
    abs_e = jnp.abs(eps[:, 1])
    act, cmd = traj.x.act, traj.u
    sat = (jnp.abs(cmd[:, 0]) > vehicle.thrust_max) | (jnp.abs(cmd[:, 1]) > vehicle.rudder_max)
    max_abs_e = jnp.max(abs_e)
    nonfinite = ~jnp.all(traj.finite)
    m = {
        "ss_abs_e": jnp.mean(abs_e[k0:]),
        "ss_abs_s": jnp.mean(jnp.abs(eps[k0:, 0])),
        "ss_abs_u_err": jnp.mean(jnp.abs(u_err[k0:])),
        "iae_e": jnp.sum(abs_e) * dt,
        "max_abs_e": max_abs_e,
        "max_abs_tau_u": jnp.max(jnp.abs(act[:, 0])),
        "max_abs_rudder_deg": jnp.degrees(jnp.max(jnp.abs(act[:, 1]))),
        "sat_fraction": jnp.mean(sat.astype(abs_e.dtype)),
        "nonfinite": nonfinite,
    }
    m["diverged"] = nonfinite | ~(max_abs_e <= diverge_e)  # NaN counts as diverged
    idx = config.trace_steps
    traces = {
        "e": eps[idx, 1].astype(jnp.float32),
        "xy": eta[idx, :2].astype(jnp.float32),
    }
    return m, traces


@functools.partial(jax.jit, static_argnames=("variant", "config"))
def _run_batch(variant, gains, nominal, scenarios, config, dt, diverge_e):
    def one(sc):
        traj = simulate_scenario(variant, gains, nominal, sc, config, dt)
        vehicle = perturb_vehicle(nominal, config.model_fields, sc.model_factors)
        return scenario_metrics(traj, sc, vehicle, config, diverge_e)

    return jax.vmap(one)(scenarios)


def run_batch(variant, gains, nominal, scenarios: MCScenario, config: MCConfig, dt, diverge_e):
    """Jitted ``vmap`` of :func:`simulate_scenario` + :func:`scenario_metrics` over a batch.

    ``variant`` and ``config`` are static (one compile each); a batch of the same size with new
    values reuses the compiled program (``dt`` [s] and ``diverge_e`` [m] are converted to
    arrays of the vehicle's dtype first, so a Python float and an array hit the same cache
    entry). If ``scenarios`` is sharded along its batch axis, the computation runs sharded and
    so are the outputs. Returns ``(metrics, traces)`` with a leading batch axis.
    """
    dtype = jnp.asarray(nominal.mass).dtype
    dt = jnp.asarray(dt, dtype) if not isinstance(dt, jax.Array) else dt
    diverge_e = jnp.asarray(diverge_e, dtype) if not isinstance(diverge_e, jax.Array) else diverge_e
    return _run_batch(variant, gains, nominal, scenarios, config, dt, diverge_e)


# --------------------------------------------------------------------------------------------
# Whole sweeps: chunks, devices, processes
# --------------------------------------------------------------------------------------------


@dataclasses.dataclass
class SweepResult:
    """Per-scenario results of a sweep (host numpy arrays, aligned with ``index``).

    Attributes:
        spec: the :class:`SweepSpec`.
        index: (n,) scenario numbers (sorted; all of them unless this is one process's share).
        scenarios: sampled parameters, e.g. ``"eta0"`` (n, 3), ``"current_speed"`` (n,),
            ``"model_factors"`` (n, F) (columns: ``spec.scenario.model_fields``).
        metrics: ``metrics[variant][name]`` (n,) for :data:`METRICS` and :data:`FLAGS`.
        traces: ``traces[variant]["e"]`` (n, P) cross-track error [m], ``["xy"]`` (n, P, 2)
            position [m] at times ``trace_t`` (P,) [s] (float32).
        trace_t: (P,) [s].
        wall_s: wall time of the sweep [s]; devices: number of devices used (per process).
    """

    spec: SweepSpec
    index: np.ndarray
    scenarios: dict
    metrics: dict
    traces: dict
    trace_t: np.ndarray
    wall_s: float = 0.0
    devices: int = 1


_SCENARIO_FIELDS = tuple(f for f in MCScenario._fields if f not in ("index", "key"))


def _mesh(devices) -> Mesh:
    return Mesh(np.asarray(devices), ("scenarios",))


def _progress_bar(total: int, progress) -> ProgressBar | None:
    """``progress``: True (bar on stderr), a callable (one line per update) or False."""
    if not progress:
        return None
    sink = progress if callable(progress) else None
    return ProgressBar(total, "sweep ", sink=sink)


def run_sweep(
    spec: SweepSpec,
    gains: sim1.Sim1Gains | None = None,
    *,
    progress: bool | Callable[[str], Any] = True,
    devices=None,
    process_index: int | None = None,
    process_count: int | None = None,
) -> SweepResult:
    """Run every variant of ``spec`` on its scenarios, chunk by chunk.

    Chunks hold ``chunk_size`` scenarios rounded up to a multiple of the device count (the last
    chunk is padded with copies of its last scenario, and the copies dropped), so each variant
    compiles once. Each chunk is sharded along the scenario axis over ``devices`` (default: this
    process's local devices; one device: no sharding). With several processes (default:
    ``jax.process_index()`` / ``jax.process_count()``), process ``p`` runs chunks
    ``p, p + P, p + 2P, ...`` on its own devices and returns only those scenarios; combine the
    parts with :func:`merge_results`.

    Args:
        spec: the study; gains: controller gains (default :func:`vcjax.sim1.default_gains`).
        progress: True: a bar on stderr; a callable: receives a line per chunk; False: silent.
        devices: devices to shard over (default ``jax.local_devices()``).
        process_index, process_count: this process's share (default from JAX).
    """
    t_start = time.perf_counter()
    gains = sim1.default_gains() if gains is None else gains
    devices = list(jax.local_devices() if devices is None else devices)
    p_idx = jax.process_index() if process_index is None else int(process_index)
    p_cnt = jax.process_count() if process_count is None else int(process_count)
    if not 0 <= p_idx < p_cnt:
        raise SweepConfigError(f"process_index: expected 0 <= index < {p_cnt}, got {p_idx}")
    n_dev = len(devices)
    chunk = -(-spec.chunk_size // n_dev) * n_dev
    chunk = min(chunk, -(-spec.num_scenarios // n_dev) * n_dev)
    n_chunks = -(-spec.num_scenarios // chunk)
    mine = list(range(p_idx, n_chunks, p_cnt))

    nominal = infante.infante_params()
    dtype = nominal.mass.dtype
    config = spec.mc_config()
    dt = jnp.asarray(spec.dt, dtype)
    diverge_e = jnp.asarray(spec.diverge_e, dtype)
    if n_dev == 1 and devices[0] == jax.devices()[0]:
        put_batch = put_repl = lambda tree: tree  # no sharding: same program as run_batch
    else:
        mesh = _mesh(devices)
        batch_sh = NamedSharding(mesh, PartitionSpec("scenarios"))
        repl = NamedSharding(mesh, PartitionSpec())
        put_batch = lambda tree: jax.device_put(tree, batch_sh)
        put_repl = lambda tree: jax.device_put(tree, repl)
    gains_d, nominal_d, dt_d, div_d = put_repl((gains, nominal, dt, diverge_e))

    bar = _progress_bar(len(mine) * len(spec.variants), progress)
    parts_idx, parts_sc = [], []
    parts_m = {v: [] for v in spec.variants}
    parts_tr = {v: [] for v in spec.variants}
    for c in mine:
        lo = c * chunk
        n_valid = min(chunk, spec.num_scenarios - lo)
        idx = np.arange(lo, lo + chunk)
        idx[n_valid:] = lo + n_valid - 1  # pad with copies of the last scenario
        sc = sample_scenarios(spec.scenario, spec.seed, idx, dtype)
        sc_d = put_batch(sc)
        parts_idx.append(idx[:n_valid])
        host_sc = jax.device_get(sc)
        parts_sc.append({f: np.asarray(getattr(host_sc, f))[:n_valid] for f in _SCENARIO_FIELDS})
        for v in spec.variants:
            m, tr = run_batch(v, gains_d, nominal_d, sc_d, config, dt_d, div_d)
            m, tr = jax.device_get((m, tr))
            parts_m[v].append({k: np.asarray(a)[:n_valid] for k, a in m.items()})
            parts_tr[v].append({k: np.asarray(a)[:n_valid] for k, a in tr.items()})
            if bar is not None:
                bar.update(f"chunk {c + 1}/{n_chunks} {v}")

    def cat(parts, key):
        arrs = [p[key] for p in parts]
        return np.concatenate(arrs) if arrs else np.zeros((0,))

    index = np.concatenate(parts_idx) if parts_idx else np.zeros(0, dtype=np.int64)
    scenarios = {f: cat(parts_sc, f) for f in _SCENARIO_FIELDS}
    metrics = {v: {k: cat(parts_m[v], k) for k in (*METRICS, *FLAGS)} for v in spec.variants}
    traces = {v: {k: cat(parts_tr[v], k) for k in ("e", "xy")} for v in spec.variants}
    trace_t = config.trace_steps * spec.dt
    return SweepResult(
        spec=spec,
        index=index,
        scenarios=scenarios,
        metrics=metrics,
        traces=traces,
        trace_t=trace_t,
        wall_s=time.perf_counter() - t_start,
        devices=n_dev,
    )


def merge_results(parts: list[SweepResult]) -> SweepResult:
    """Combine the per-process parts of one sweep (sorted by scenario index)."""
    if not parts:
        raise ValueError("parts: nothing to merge")
    spec = parts[0].spec
    if any(p.spec != spec for p in parts):
        raise ValueError("parts: results of different sweeps")
    devices = sum(p.devices for p in parts)
    parts = [p for p in parts if p.index.size] or parts[:1]  # a process may have had no chunk
    index = np.concatenate([p.index for p in parts])
    order = np.argsort(index, kind="stable")
    if len(np.unique(index)) != len(index):
        raise ValueError("parts: overlapping scenario indices")

    def cat(get):
        return np.concatenate([get(p) for p in parts])[order]

    return SweepResult(
        spec=spec,
        index=index[order],
        scenarios={k: cat(lambda p, k=k: p.scenarios[k]) for k in parts[0].scenarios},
        metrics={
            v: {k: cat(lambda p, v=v, k=k: p.metrics[v][k]) for k in parts[0].metrics[v]}
            for v in parts[0].metrics
        },
        traces={
            v: {k: cat(lambda p, v=v, k=k: p.traces[v][k]) for k in parts[0].traces[v]}
            for v in parts[0].traces
        },
        trace_t=parts[0].trace_t,
        wall_s=max(p.wall_s for p in parts),
        devices=devices,
    )


def _stats(x: np.ndarray) -> dict:
    if x.size == 0:
        return {k: None for k in ("mean", "std", "p5", "p50", "p95", "min", "max")}
    p5, p50, p95 = np.percentile(x, [5, 50, 95])
    vals = dict(mean=x.mean(), std=x.std(), p5=p5, p50=p50, p95=p95, min=x.min(), max=x.max())
    return {k: (float(v) if np.isfinite(v) else None) for k, v in vals.items()}


def summarize(result: SweepResult) -> dict:
    """JSON-ready summary: per variant, failure counts and per-metric statistics.

    ``summary["variants"][v]``: ``n``, ``n_diverged``, ``n_nonfinite`` and, for every metric,
    ``mean``, ``std``, ``p5``, ``p50``, ``p95``, ``min``, ``max`` over the runs that did not
    diverge (``None`` where there are none).
    """
    out = {}
    for v, m in result.metrics.items():
        ok = ~m["diverged"].astype(bool)
        entry = {
            "n": int(ok.size),
            "n_diverged": int((~ok).sum()),
            "n_nonfinite": int(m["nonfinite"].astype(bool).sum()),
        }
        entry["metrics"] = {k: _stats(np.asarray(m[k], dtype=np.float64)[ok]) for k in METRICS}
        out[v] = entry
    spec = result.spec
    return {
        "num_scenarios": int(result.index.size),
        "wall_s": round(result.wall_s, 3),
        "devices": result.devices,
        "spec": _spec_to_dict(spec),
        "variants": out,
    }


def _spec_to_dict(spec: SweepSpec) -> dict:
    d = dataclasses.asdict(spec)
    return json.loads(json.dumps(d, default=list))


def _spec_from_dict(d: dict) -> SweepSpec:
    d = dict(d)
    sc = d.pop("scenario")
    sc = {k: tuple(v) if isinstance(v, list) else v for k, v in sc.items()}
    d["variants"] = tuple(d["variants"])
    return SweepSpec(scenario=ScenarioSpec(**sc), **d)


def save_results(result: SweepResult, path: Path) -> Path:
    """Write ``result`` to an ``.npz`` file (no pickles).

    Keys: ``index``; ``scenario.<field>`` (see :class:`MCScenario`; ``model_factors`` columns
    are ``model_fields``); ``<variant>.<metric>``; ``<variant>.trace_e`` (n, P),
    ``<variant>.trace_xy`` (n, P, 2); ``trace_t``; ``spec_json``.
    """
    path = Path(path)
    arrays = {"index": result.index, "trace_t": result.trace_t}
    arrays["model_fields"] = np.array(result.spec.scenario.model_fields, dtype=str)
    arrays["spec_json"] = np.array(json.dumps(_spec_to_dict(result.spec)))
    arrays["meta_json"] = np.array(json.dumps({"wall_s": result.wall_s, "devices": result.devices}))
    for k, a in result.scenarios.items():
        arrays[f"scenario.{k}"] = a
    for v in result.metrics:
        for k, a in result.metrics[v].items():
            arrays[f"{v}.{k}"] = a
        for k, a in result.traces[v].items():
            arrays[f"{v}.trace_{k}"] = a
    np.savez_compressed(path, **arrays)
    return path


def load_results(path: Path) -> SweepResult:
    """Inverse of :func:`save_results`."""
    with np.load(Path(path), allow_pickle=False) as z:
        spec = _spec_from_dict(json.loads(str(z["spec_json"])))
        meta = json.loads(str(z["meta_json"]))
        scen = {k[9:]: z[k] for k in z.files if k.startswith("scenario.")}
        metrics = {v: {k: z[f"{v}.{k}"] for k in (*METRICS, *FLAGS)} for v in spec.variants}
        traces = {v: {k: z[f"{v}.trace_{k}"] for k in ("e", "xy")} for v in spec.variants}
        return SweepResult(
            spec, z["index"], scen, metrics, traces, z["trace_t"], meta["wall_s"], meta["devices"]
        )


# --------------------------------------------------------------------------------------------
# TOML configuration
# --------------------------------------------------------------------------------------------

_SCHEMA: dict[str, tuple[str, ...]] = {
    "sweep": ("num_scenarios", "seed", "variants", "chunk_size"),
    "simulation": ("horizon", "dt", "integrator", "timing", "edd", "u_d", "gains"),
    "current": ("model", "speed", "direction_deg", "sigma", "tau", "max_speed"),
    "initial": ("x", "y", "heading_deg", "speed"),
    "model_error": ("relative", "fields"),
    "sensor_noise": ("position_std", "heading_std_deg", "velocity_std", "yaw_rate_std_deg"),
    "metrics": ("tail", "diverge_e"),
    "output": ("record_points", "figures"),
}
# (section, key) -> SweepSpec / ScenarioSpec field
_SPEC_KEYS = {
    ("sweep", "num_scenarios"): "num_scenarios",
    ("sweep", "seed"): "seed",
    ("sweep", "variants"): "variants",
    ("sweep", "chunk_size"): "chunk_size",
    ("simulation", "horizon"): "horizon",
    ("simulation", "dt"): "dt",
    ("simulation", "integrator"): "integrator",
    ("simulation", "timing"): "timing",
    ("simulation", "edd"): "edd",
    ("metrics", "tail"): "tail",
    ("metrics", "diverge_e"): "diverge_e",
    ("output", "record_points"): "record_points",
}
_SCENARIO_KEYS = {
    ("simulation", "u_d"): "u_d",
    ("current", "model"): "current_model",
    ("current", "speed"): "current_speed",
    ("current", "direction_deg"): "current_direction_deg",
    ("current", "sigma"): "current_sigma",
    ("current", "tau"): "current_tau",
    ("current", "max_speed"): "current_max_speed",
    ("initial", "x"): "x0",
    ("initial", "y"): "y0",
    ("initial", "heading_deg"): "heading0_deg",
    ("initial", "speed"): "speed0",
    ("model_error", "relative"): "model_error",
    ("model_error", "fields"): "model_fields",
    ("sensor_noise", "position_std"): "position_noise_std",
    ("sensor_noise", "heading_std_deg"): "heading_noise_std_deg",
    ("sensor_noise", "velocity_std"): "velocity_noise_std",
    ("sensor_noise", "yaw_rate_std_deg"): "yaw_rate_noise_std_deg",
}


def _check_list_of_str(name, v):
    if not isinstance(v, list) or not all(isinstance(a, str) for a in v):
        raise SweepConfigError(f"{name}: expected a list of strings, got {v!r}")
    return tuple(v)


def load_config(config_path) -> tuple[SweepSpec, dict]:
    """Read and validate a sweep TOML file (schema: module docstring).

    Returns:
        ``(spec, extras)``: the :class:`SweepSpec` and ``extras = {"gains": path or None,
        "figures": bool}``.

    Raises:
        SweepConfigError: naming the file, section and key (unknown section or key, wrong type,
            out-of-range value, missing ``[sweep] num_scenarios``).
    """
    config_path = Path(config_path)
    try:
        raw = tomllib.loads(config_path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise SweepConfigError(f"{config_path}: not valid TOML: {err}") from None
    where = str(config_path)
    for sec, body in raw.items():
        if sec not in _SCHEMA:
            raise SweepConfigError(f"{where}: unknown section [{sec}]; expected {list(_SCHEMA)}")
        if not isinstance(body, dict):
            raise SweepConfigError(f"{where}: [{sec}] must be a table, got {body!r}")
        for key in body:
            if key not in _SCHEMA[sec]:
                raise SweepConfigError(
                    f"{where}: unknown key [{sec}] {key!r}; expected one of {list(_SCHEMA[sec])}"
                )
    if "num_scenarios" not in raw.get("sweep", {}):
        raise SweepConfigError(f"{where}: [sweep] num_scenarios is required")

    spec_kw, sc_kw = {}, {}
    try:
        for (sec, key), field in _SPEC_KEYS.items():
            if key in raw.get(sec, {}):
                v = raw[sec][key]
                if field == "variants":
                    v = _check_list_of_str(f"[{sec}] {key}", v)
                spec_kw[field] = v
        for (sec, key), field in _SCENARIO_KEYS.items():
            if key in raw.get(sec, {}):
                v = raw[sec][key]
                if field == "model_fields":
                    v = _check_list_of_str(f"[{sec}] {key}", v)
                sc_kw[field] = v
        gains = raw.get("simulation", {}).get("gains")
        if gains is not None and not isinstance(gains, str):
            raise SweepConfigError(f"[simulation] gains: expected a file path, got {gains!r}")
        figures = raw.get("output", {}).get("figures", True)
        if not isinstance(figures, bool):
            raise SweepConfigError(f"[output] figures: expected true or false, got {figures!r}")
        spec = SweepSpec(scenario=ScenarioSpec(**sc_kw), **spec_kw)
    except SweepConfigError as err:
        raise SweepConfigError(f"{where}: {_toml_name(str(err))}") from None
    gains_path = None if gains is None else (config_path.parent / gains)
    if gains_path is not None and not gains_path.is_file():
        raise SweepConfigError(f"{where}: [simulation] gains: no such file {gains_path}")
    return spec, {"gains": gains_path, "figures": figures}


def _toml_name(msg: str) -> str:
    """Rewrite a spec field name at the start of ``msg`` into its ``[section] key``."""
    head, sep, rest = msg.partition(":")
    for (sec, key), field in (*_SPEC_KEYS.items(), *_SCENARIO_KEYS.items()):
        if head == field:
            return f"[{sec}] {key}{sep}{rest}"
    return msg


def run_sweep_config(config_path, out_dir, progress: bool | Callable[[str], Any] = True) -> dict:
    """Run the sweep described by a TOML file and write its results (the ``vcjax sweep`` CLI).

    Writes into ``out_dir``: ``summary.json`` (:func:`summarize`), ``results.npz``
    (:func:`save_results`) and, unless ``[output] figures = false``, the figures of
    :func:`vcjax.sweep_plots.sweep_figures`. In a multi-process run (after
    ``jax.distributed.initialize``) every process runs its share of chunks and writes
    ``results.part<p>-of-<P>.npz`` into the (shared) ``out_dir``; process 0 waits for the others,
    merges the parts and writes the outputs.

    Args:
        config_path: the TOML file; out_dir: output folder (created).
        progress: True: a bar on stderr; a callable: one line per chunk; False: silent.

    Returns:
        ``{"summary": dict, "files": [Path, ...]}`` (on processes other than 0: the part file
        only, and ``summary`` None).
    """
    spec, extras = load_config(config_path)
    gains = None
    if extras["gains"] is not None:
        gains = sim1.gains_from_json(json.loads(Path(extras["gains"]).read_text()))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = run_sweep(spec, gains, progress=progress)

    p_cnt, p_idx = jax.process_count(), jax.process_index()
    if p_cnt > 1:
        from jax.experimental import multihost_utils

        part = save_results(result, out / f"results.part{p_idx}-of-{p_cnt}.npz")
        multihost_utils.sync_global_devices("vcjax.sweep: parts written")
        if p_idx != 0:
            return {"summary": None, "files": [part]}
        result = merge_results(
            [load_results(out / f"results.part{i}-of-{p_cnt}.npz") for i in range(p_cnt)]
        )
    summary = summarize(result)
    files = [save_results(result, out / "results.npz")]
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    files.append(out / "summary.json")
    if extras["figures"]:
        from vcjax import sweep_plots

        files += sweep_plots.sweep_figures(result, out)
    return {"summary": summary, "files": files}
