"""Batch Monte-Carlo studies of any registered closed loop: ``vmap`` over scenarios, chunks,
devices, hosts.

A sweep runs every controller variant of a vehicle's loop ([`vcjax.loops`][vcjax.loops]; default:
Simulation 1's INFANTE-class craft with ``vcm``, ``vcm_integral``, ``ilos``, ``los_pid``,
``vcm_ilos`` on the line ``[10, w]``) on the *same* batch of sampled scenarios (paired
comparison). A scenario draws:

* the ocean current: mean speed [m/s] and direction [deg, towards which the water flows,
  clockwise from north]; constant, or slowly varying as a first-order Gauss–Markov process
  around that mean ([`vcjax.environment.current`][vcjax.environment.current], exact discretisation,
  clipped to a
  maximum speed);
* the initial state: the vehicle's ``[initial]`` keys (INFANTE-class: position ``x, y`` [m],
  ``heading_deg``, surge ``speed`` [m/s]); and the desired speed ``u_d`` [m/s];
* multiplicative model errors: each listed plant parameter is multiplied by
  ``1 + relative * U(-1, 1)`` (independently per field); the controllers keep the nominal
  design parameters;
* sensor noise: white Gaussian noise on what the controller measures, drawn per step from
  ``jax.random.fold_in(key, k)`` (held over the step), standard deviations fixed by the study;
* a constant disturbance force (vehicles whose plant takes one, e.g. ODIN-class);
* a random sea (``[waves]``; loops whose plant feels one, REMUS 100 and ODIN-class):
  significant height ``hs`` [m], peak period ``tp`` [s], direction [deg, towards which the
  waves travel] and the depth of the NED origin below the mean surface [m], then the sea's
  frequencies, phases and directions ([`sea_state`][vcjax.environment.waves.sea_state]).

Everything a scenario draws comes from ``jax.random.fold_in(PRNGKey(seed), index)``, so scenario
``i`` is the same whatever the chunk size, the number of devices or of hosts.

Modules, by job:

* [`vcjax.sweep.spec`][vcjax.sweep.spec]: [`SweepSpec`][vcjax.sweep.spec.SweepSpec],
[`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec],
[`sample_scenarios`][vcjax.sweep.spec.sample_scenarios]
  -> [`MCScenario`][vcjax.sweep.spec.MCScenario];
* [`vcjax.sweep.run`][vcjax.sweep.run]: [`simulate_scenario`][vcjax.sweep.run.simulate_scenario]
(one scenario, pure; ``jax.vmap`` it),
  [`scenario_metrics`][vcjax.sweep.run.scenario_metrics]
  ([`vcjax.metrics.run_metrics`][vcjax.metrics.run_metrics] of its trajectory),
  [`streamed_metrics`][vcjax.sweep.run.streamed_metrics] (the same without storing the trajectory:
  the rollout folds its
  record into the metrics segment by segment,
  [`vcjax.rollout.rollout_reduce`][vcjax.rollout.rollout_reduce]),
  [`run_batch`][vcjax.sweep.run.run_batch] (jitted ``vmap`` of the streamed metrics, one compile per
  loop and static
  [`MCConfig`][vcjax.sweep.spec.MCConfig]), [`run_sweep`][vcjax.sweep.run.run_sweep] (fixed-size
  chunks, the last one padded, the scenario axis sharded over the local devices, a progress bar;
  in a multi-process run each process takes its share of chunks);
* [`vcjax.sweep.results`][vcjax.sweep.results]: [`summarize`][vcjax.sweep.results.summarize],
[`save_results`][vcjax.sweep.results.save_results],
[`load_results`][vcjax.sweep.results.load_results],
  [`merge_results`][vcjax.sweep.results.merge_results];
* [`vcjax.sweep.config`][vcjax.sweep.config]:
[`run_sweep_config`][vcjax.sweep.config.run_sweep_config]: TOML file -> ``summary.json``,
  ``results.npz`` and figures.

TOML schema (every key optional unless marked; a value written ``range`` is either a number
(fixed) or a two-element list ``[lo, hi]`` sampled uniformly)::

    [scenario]                  # what is simulated (vcjax.config.scenario); default: Simulation 1
    vehicle = "infante"         # "infante" | "odin" | "arm" | any registered vehicle
    controller = "vcm_integral" # optional: one controller (else [sweep] variants)
    params = "model.json"       # optional: parameter overrides, plant and design model
    plant_params = "plant.json" # optional: overrides of the plant only (after params)
                                # + the loop class's static options (errors list them)
    [scenario.path]
    kind = "circle"             # "line" | "circle" | "helix" | "waypoints" (+ their keys)
    radius = 40.0

    [sweep]
    num_scenarios = 64          # int >= 1 (required)
    seed = 0                    # int >= 0
    variants = ["vcm", "vcm_integral", "ilos", "los_pid"]   # the vehicle's controllers
    chunk_size = 256            # int >= 1, scenarios per compiled batch (rounded up to a
                                # multiple of the device count)

    [simulation]
    horizon = 60.0              # s, > 0
    dt = 0.05                   # s, > 0, <= horizon
    integrator = "rk4"          # "euler" | "heun" | "rk4"
    timing = "continuous"       # "continuous" | "sampled"
    u_d = 2.0                   # range, m/s, desired speed (> 0; default: the vehicle's)
    gains = "gains.json"        # optional gains file (the vehicle's gains JSON, e.g. what
                                # vcjax tune writes), relative to the config file

    [current]
    model = "constant"          # "constant" | "gauss_markov"
    speed = [0.0, 1.0]          # range, m/s (mean speed), >= 0
    direction_deg = [0, 360]    # range, deg, towards which the current flows
    sigma = 0.05                # m/s, stationary std of each fluctuation component (GM only)
    tau = 300.0                 # s, correlation time (GM only)
    max_speed = 2.0             # m/s, speed bound of the current handed to the plant (GM only)

    [waves]                     # optional: a random sea per scenario (vcjax.environment.waves)
    spectrum = "jonswap"        # "jonswap" | "pm" (Pierson-Moskowitz)
    hs = [0.5, 3.0]             # range, m, significant wave height (required)
    tp = [5.0, 12.0]            # range, s, peak period (required; tp >= 40 dt)
    direction_deg = [0, 360]    # range, deg, towards which the waves travel
    gamma = 3.3                 # JONSWAP peak enhancement (>= 1)
    spreading = 0.0             # s of the cos^2s spreading (0: long-crested)
    components = 64             # int >= 1, regular components per sea
    origin_depth = [2.0, 10.0]  # range, m, depth of the NED origin below the mean surface

    [initial]                   # the vehicle's keys (loop.initial_keys), each a range
    x = 0.0                     # INFANTE-class: x, y [m], heading_deg, speed [m/s]
    y = 0.0
    heading_deg = 90.0
    speed = 2.0

    [model_error]
    relative = 0.0              # in [0, 1): factor 1 + relative * U(-1, 1) per field
    fields = [...]              # the vehicle's parameter names (loop.param_names())

    [sensor_noise]              # the vehicle's channels (loop.noise_channels)
    position_std = 0.0          # INFANTE-class: m (x and y)
    heading_std_deg = 0.0       # deg
    velocity_std = 0.0          # m/s (u and v)
    yaw_rate_std_deg = 0.0      # deg/s

    [disturbance]
    force = [0.0, [0.0, 5.0], 0.0]   # one range per generalised force component [N, N m]

    [metrics]
    tail = 0.2                  # in (0, 1]: steady-state window, last fraction of the run
    diverge_e = 50.0            # m, > 0: a run with max |e| above it (or a non-finite state, or one
                                # beyond the rollout's bound, 1e9) counts as diverged

    [output]
    record_points = 200         # int >= 0: cross-track error / path samples kept per run
                                # (0: none; the envelope and path figures then are skipped)
    figures = true

Metrics (per scenario and variant; [`vcjax.metrics.metric_names`][vcjax.metrics.metric_names]),
evaluated on the *true*
state (with sensor noise the controller's own error signals differ): see
[`vcjax.metrics`][vcjax.metrics].
Summaries use the runs that did not diverge.

Precision follows JAX's default float (the CLI enables float64 unless told otherwise).
"""

from vcjax.config import ConfigError
from vcjax.metrics import FLAGS, METRICS
from vcjax.sweep.config import load_config, run_sweep_config
from vcjax.sweep.results import (
    SweepResult,
    load_results,
    merge_results,
    save_results,
    summarize,
)
from vcjax.sweep.run import (
    nominal,
    perturb_params,
    run_batch,
    run_sweep,
    scenario_metrics,
    simulate_scenario,
    streamed_metrics,
    to_scenario,
)
from vcjax.sweep.spec import MCConfig, MCScenario, ScenarioSpec, SweepSpec, sample_scenarios

__all__ = [
    "ConfigError",
    "FLAGS",
    "METRICS",
    "MCConfig",
    "MCScenario",
    "ScenarioSpec",
    "SweepResult",
    "SweepSpec",
    "load_config",
    "load_results",
    "merge_results",
    "nominal",
    "perturb_params",
    "run_batch",
    "run_sweep",
    "run_sweep_config",
    "sample_scenarios",
    "save_results",
    "scenario_metrics",
    "simulate_scenario",
    "streamed_metrics",
    "summarize",
    "to_scenario",
]
