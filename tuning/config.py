"""TOML configuration of a tuning run (``vcjax tune CONFIG.toml``), validated with clear errors
into the frozen [`TuneConfig`][tuning.spec.TuneConfig] (its sections, defaults and key descriptions:
[`tuning.spec`][tuning.spec]).

Every section and key is optional (defaults below); unknown sections or keys, wrong types and
out-of-range values raise [`vcjax.config.ConfigError`][vcjax.config.values.ConfigError] (the one
error class of every
command) naming the file and the offending ``section.key``::

    [scenario]                      # what is tuned (vcjax.config.scenario; shared with sweeps):
    vehicle = "infante"             # a registered vehicle; default: Simulation 1
    controller = "vcm_integral"     # one of its controllers
    params = "model.json"           # optional parameter overrides (plant and design model)
    plant_params = "plant.json"     # optional overrides of the plant only
    [scenario.path]                 # optional; default: the vehicle's default path
    kind = "circle"
    radius = 40.0

    [simulation]                    # shared with sweeps (vcjax.config.schema.Simulation); the
    horizon = 80.0                  # keys horizon, dt, integrator, timing, smooth may
    u_d = [1.0, 1.5]                # instead be written under [problem] (the older spelling)

    [current]                       # shared with sweeps (constant model only): replaces
    speed = [0.0, 1.0]              # [scenarios] current_max = 1.0, which means exactly this
    direction_deg = [0.0, 360.0]    # speed and direction range. Without speed and
                                    # direction_deg the current is current_max's; with one
                                    # of them, the other takes its section default (0.5 m/s,
                                    # 90 deg); run.json records both as they ran

    [problem]                       # what is tuned and how a rollout is simulated
    variant = ""                    # the controller ("" = [scenario] controller, else the
                                    # vehicle's default: vcm_integral for INFANTE-class)
    tune = []                       # gain groups of that controller ([] = all of them), e.g.
                                    # ["P_G", "P_Phi", "Delta", "sigma", "P_int"]
    initial_gains = ""              # the vehicle's gains JSON (what vcjax tune writes; "" =
                                    # defaults), relative to the config file
    horizon = 80.0                  # [s]
    dt = 0.1                        # [s] RK4 step
    integrator = "rk4"
    timing = "continuous"           # or "sampled"
    smooth = true                   # tanh actuator saturation while training (gradients pass)
    checkpoint = true               # jax.checkpoint: reverse mode recomputes each segment
                                    # (faster and smaller; false stores every step's tape)
    checkpoint_every = 1            # with checkpoint: segment length (1 = every step)
    risk = "mean"                   # or "cvar"
    alpha = 0.2                     # CVaR level (fraction of worst scenarios)
    log_box = 3.0                   # gains kept within e^log_box of the initial ones (penalty)
    box_weight = 10.0

    [weights]                       # loss weights (tuning/loss.py)
    eps = 1.0
    u_tilde = 1.0
    psi_tilde = 1.0
    sat_excess = 1.0
    sat_time = 5.0
    effort = 0.0
    unhealthy = 1000.0
    sat_width = 0.05
    depth = 0.0                     # the depth error of 3-D loops (1/m^2)

    [scenarios]                     # distribution of the random scenarios
    current_max = 1.0               # [m/s], uniform speed, uniform direction
    position_offset = 5.0           # [m], uniform on each of the vehicle's x, y initial keys
    heading_offset_deg = 45.0       # [deg], uniform (vehicles with a heading_deg key)

    [initial]                       # optional ranges of the vehicle's initial keys (override
    q1_deg = [20.0, 40.0]           # the offsets above), as in sweep configs

    [waves]                         # optional, shared with sweeps (vcjax.config.schema.Waves):
    hs = [0.5, 2.0]                 # a random sea per scenario (loops that take waves: REMUS
    tp = [6.0, 10.0]                # 100, ODIN-class); hs, tp required, then spectrum,
    direction_deg = [0.0, 360.0]    # gamma, spreading, components, origin_depth

    [disturbance]
    force = []                      # optional: one range per generalised force component

    [gauss_markov]                  # optional: any section of a vcjax.environment component
    sigma = 0.05                    # (vcjax.environment.register; not the shared ones above),
                                    # checked and sampled per scenario by its component, as
                                    # in sweeps (loops that cannot feel it refuse it)

    [model_error]                   # plant-only multiplicative errors, as in sweep configs
    relative = 0.0
    # fields = [...]                # the vehicle's parameter names (omitted: its default set)

    [train]
    size = 16
    seed = 0

    [heldout]
    size = 64
    seed = 1001
    smooth = false                  # evaluate with the hard-clipped plant (as `vcjax simulate`)

    [optimizer]
    name = "lbfgs"                  # or "adam"
    steps = 40
    learning_rate = 0.05            # adam only
    memory_size = 10                # lbfgs
    max_linesearch_steps = 15       # lbfgs
    grad_mode = "reverse"           # or "forward" (jax.jacfwd)
    max_bad_steps = 5
    grad_tol = 1e-8

    [report]
    plot_scenarios = 4              # held-out scenarios drawn in the before/after figures

    [robust]                        # optional: robust tuning (tuning/robust.py); its presence
    adversarial_every = 5           # switches it on: every K steps a search for the worst
    adversarial_count = 4           # scenarios against the current gains fills the batch's
    budget = 10                     # adversarial slot (ascent steps of each search)
    starts = 8
    step_size = 0.1
    metric = "tuning_loss"          # or a sweep metric
    seed = 7
    compare = false                 # also tune without [robust] (summary: robust.nominal)
    check_starts = 16               # the independent worst-case search at the end
    check_budget = 20
    check_seed = 1007
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from tuning.spec import (
    _OPTIONAL,
    _SECTIONS,
    DEFAULTS,
    KEY_DOCS,
    LOSS_NAMES,
    TuneConfig,
    TuneSimulation,
)
from vcjax import loops
from vcjax.config import (
    SECTIONS,
    ConfigError,
    Current,
    Simulation,
    Waves,
    as_range,
    closest,
    parse_section,
    read_toml,
    unknown_key,
)
from vcjax.config.aliases import moved_values, note_old_spellings, take_moved
from vcjax.config.frozen import freeze
from vcjax.config.scenario import loop_options, parse_scenario
from vcjax.config.schema import registered
from vcjax.environment import check_for_loop, lookup
from vcjax.sweep.config import environment_sections, refusal
from vcjax.sweep.spec import check_wave_step

__all__ = [
    "ConfigError",
    "DEFAULTS",
    "KEY_DOCS",
    "TuneConfig",
    "load_config",
    "validate_config",
]


#: sections parsed on their own: [scenario] (vcjax.config.scenario), [initial] (vehicle keys),
#: the shared [simulation], [current] and [waves] (vcjax.config.schema)
_SPECIAL = ("scenario", "initial", "simulation", "current", "waves")
#: [simulation] keys that tune configs may also write under [problem] (the older spelling)
_SIM_IN_PROBLEM = ("horizon", "dt", "integrator", "timing", "smooth")
#: the sections that are not an environment component's here (the tune's own, the shared ones)
_NOT_COMPONENTS = (*_SECTIONS, *_SPECIAL, *SECTIONS)


def _sections(raw: dict) -> dict:
    """The sections declared in [`tuning.spec`][tuning.spec] (the tune's own and the shared
    ``[disturbance]``, ``[model_error]``), parsed by the one validator
    ([`vcjax.config.parse_section`][vcjax.config.schema.parse_section]); unknown sections suggest
    the closest."""
    added = registered()
    known = sorted([*_SECTIONS, *_SPECIAL, *added, *_OPTIONAL])
    for name, table in raw.items():
        if name not in known:
            raise ConfigError(
                f"unknown section [{name}]{closest(name, known)}; expected one of {known}"
            )
        if not isinstance(table, dict):
            raise ConfigError(f"[{name}]: expected a table, got {type(table).__name__} {table!r}")
    for name, cls in added.items():  # sections added by vcjax.config.register_section
        parse_section(cls, raw.get(name), name)
    sec = {name: parse_section(cls, raw.get(name), name) for name, cls in _SECTIONS.items()}
    for name, cls in _OPTIONAL.items():  # [robust]: None where not given
        sec[name] = parse_section(cls, raw[name], name) if name in raw else None
    return sec


def _simulation(raw: dict, sec: dict):
    """Fold ``[simulation]`` into ``sec["problem"]`` (its keys horizon, dt, integrator, timing,
    smooth may instead be written under ``[problem]``, the older spelling; both at once is
    refused) and return ``u_d``."""
    sim_raw = raw.get("simulation", {})
    sim = parse_section(Simulation, sim_raw, "simulation")
    over = {}
    for k in sim_raw:
        if k in raw.get("problem", {}) and k in _SIM_IN_PROBLEM:
            raise ConfigError(
                f"[simulation] {k}: also given as [problem] {k} (its older spelling); write it once"
            )
        if k in _SIM_IN_PROBLEM:
            over[k] = getattr(sim, k)
    p = dataclasses.replace(sec["problem"], **over)
    if p.horizon / p.dt < 1:
        raise ConfigError(f"[simulation] horizon: must be >= dt ({p.dt:g} s), got {p.horizon:g}")
    sec["problem"] = p
    return sim.u_d


def _current_and_waves(raw: dict, sec: dict) -> tuple[Current, Waves | None]:
    """``[current]`` and ``[waves]`` (``None`` without it: the section's presence is the switch).

    Without ``[current] speed`` and ``direction_deg`` the current is ``[scenarios]
    current_max``'s: speed ``[0, current_max]`` in any direction ``[0, 360]``; writing either
    key switches to ``[current]``, whose other key then takes its section default (0.5 m/s,
    90 deg). ``model = "constant"`` (the default, and the only model a tune samples)."""
    cur_raw = raw.get("current", {})
    cur = parse_section(Current, cur_raw, "current")
    if {"speed", "direction_deg"} & set(cur_raw) and "current_max" in raw.get("scenarios", {}):
        raise ConfigError(
            "[current] speed: also given as [scenarios] current_max (its older spelling); "
            "give [current] or [scenarios] current_max, not both"
        )
    if cur.model != "constant":
        raise ConfigError("[current] model: vcjax tune samples constant currents only")
    if "speed" not in cur_raw and "direction_deg" not in cur_raw:
        m = float(sec["scenarios"].current_max)
        cur = dataclasses.replace(cur, speed=(0.0, m), direction_deg=(0.0, 360.0))
    if "waves" not in raw:
        return cur, None
    wav = parse_section(Waves, raw["waves"], "waves")
    check_wave_step(wav.tp[0], sec["problem"].dt, "[waves] tp")
    return cur, wav


def _controller(sec: dict, choice):
    """The controller (``[problem] variant`` is the older spelling of ``[scenario] controller``;
    disagreeing spellings are refused naming both), and ``choice`` recording it and every loop
    option with an older spelling as it runs (``run.json`` records what runs)."""
    p = sec["problem"]
    cls = loops.loop_class(choice.vehicle)
    ctrl = p.variant or choice.controller or cls.default_controller or cls.controllers[0]
    if ctrl not in cls.controllers:
        raise ConfigError(
            f"[problem] variant: vehicle {choice.vehicle!r} supports {list(cls.controllers)}, "
            f"got {ctrl!r}"
        )
    if choice.controller and p.variant and p.variant != choice.controller:
        raise ConfigError(
            f"[problem] variant: {p.variant!r} contradicts [scenario] controller "
            f"{choice.controller!r} (its newer spelling); give one of them"
        )
    given = dict(choice.options)
    ran = {k: v for k, v in moved_values(choice).items() if k in loop_options(cls)}
    options = (*choice.options, *((k, v) for k, v in ran.items() if k not in given))
    sec["problem"] = dataclasses.replace(p, variant=ctrl)
    return dataclasses.replace(choice, controller=ctrl, options=options)


def _vehicle_keys(raw: dict, sec: dict, loop, current: Current, waves, env) -> dict:
    """The keys whose valid names are the vehicle's (gain groups, parameter names, initial
    keys) and the disturbances it can feel; returns the ``[initial]`` ranges."""
    names = [g.name for g in loop.gain_specs()]
    bad = [t for t in sec["problem"].tune if t not in names]
    if bad:
        raise ConfigError(
            f"[problem] tune: unknown gains {bad} for {loop.describe()}; choose from {names}"
        )
    valid = loop.param_names()
    bad = [f for f in sec["model_error"].fields or () if f not in valid]
    if bad:
        raise ConfigError(
            f"[model_error] fields: unknown {loop.vehicle} parameters {bad}; valid: {list(valid)}"
        )
    init = {}
    for k, v in raw.get("initial", {}).items():
        if k not in loop.initial_keys:
            note = f"for vehicle {loop.vehicle!r}"
            raise ConfigError(unknown_key("initial", k, loop.initial_keys, note))
        init[k] = as_range(f"[initial] {k}", v)
    try:  # a current, a sea or a component the loop cannot take is refused, never ignored
        loops.check_disturbances(loop, max(current.speed) > 0, False, waves=waves is not None)
        loops.check_environment(loop, [lookup(s) for s, _ in env])
    except ValueError as err:
        raise ConfigError(refusal(err)) from None
    try:  # each component as it is for this loop (e.g. its number of forces)
        check_for_loop(loop, env)
    except ValueError as err:
        raise ConfigError(str(err)) from None
    return init


def _check_robust(rob) -> None:
    """Cross-checks of ``[robust]`` (the one validator checked each key): ``starts >=
    adversarial_count``; the metric one of the tuning loss's names or a sweep metric's (an
    actuator's ``max_abs_<name>`` is checked against the loop's when the search is built)."""
    if rob.starts < rob.adversarial_count:
        raise ConfigError(
            f"[robust] starts: must be >= adversarial_count ({rob.adversarial_count}), "
            f"got {rob.starts}"
        )
    from vcjax.metrics import METRICS
    from vcjax.search import ALIASES

    known = [*LOSS_NAMES, *METRICS, *ALIASES]
    if rob.metric not in known and not rob.metric.startswith("max_abs_"):
        raise ConfigError(
            f"[robust] metric: unknown metric {rob.metric!r}{closest(rob.metric, known)}; "
            f"expected one of {known} (or max_abs_<actuator>)"
        )


def validate_config(raw: dict, config_path=None) -> TuneConfig:
    """Defaults filled in, every value checked; returns the frozen
    [`TuneConfig`][tuning.spec.TuneConfig].

    ``cfg.scenario`` is the parsed ``[scenario]``, ``cfg.initial`` the ``[initial]`` ranges,
    ``cfg.environment`` the sections of [`vcjax.environment`][vcjax.environment] components
    (checked by their component, as in sweeps); ``config_path`` resolves the files a config
    names (default: the working directory).

    Raises:
        ConfigError: ``[section] key: message`` for an unknown section/key (the closest valid
            one suggested), a wrong type, a value out of range, a controller or gain the
            vehicle does not have, two spellings of one setting that disagree.
    """
    if not isinstance(raw, dict):
        raise ConfigError("config: expected a table of sections")
    raw, older = take_moved(raw)  # loop options in their older spellings
    where = config_path or Path("config")
    choice = parse_scenario(raw.get("scenario"), "scenario", where, older)  # may register
    raw, env = environment_sections(raw, _NOT_COMPONENTS, "")
    sec = _sections(raw)
    u_d = _simulation(raw, sec)
    current, waves = _current_and_waves(raw, sec)
    choice = _controller(sec, choice)
    loop = choice.loop(sec["problem"].variant)
    init = _vehicle_keys(raw, sec, loop, current, waves, env)
    if sec["robust"] is not None:
        _check_robust(sec["robust"])
    return TuneConfig(
        **sec,
        simulation=TuneSimulation(u_d=u_d),
        current=current,
        waves=waves,
        initial=freeze(init),
        environment=env,
        scenario=choice,
    )


def load_config(path) -> TuneConfig:
    """Read and validate a TOML file (the frozen [`TuneConfig`][tuning.spec.TuneConfig]); files it
    names are
    resolved against its folder."""
    path = Path(path)
    raw = read_toml(path)
    try:
        cfg = validate_config(raw, path)
        note_old_spellings(raw, str(path))
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None
    g = cfg.problem.initial_gains
    if g:
        gp = Path(g)
        g = str(gp if gp.is_absolute() else path.parent / gp)
        cfg = dataclasses.replace(cfg, problem=dataclasses.replace(cfg.problem, initial_gains=g))
    return cfg
