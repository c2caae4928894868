"""TOML configuration of a tuning run (``vcjax tune CONFIG.toml``), validated with clear errors
into the frozen :class:`~tuning.spec.TuneConfig` (its sections, defaults and key descriptions:
:mod:`tuning.spec`).

Every section and key is optional (defaults below); unknown sections or keys, wrong types and
out-of-range values raise :class:`vcjax.config.ConfigError` (the one error class of every
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
    horizon = 80.0                  # keys horizon, dt, integrator, timing, smooth, edd may
    u_d = [1.0, 1.5]                # instead be written under [problem] (the older spelling)

    [current]                       # shared with sweeps (constant model only): replaces
    speed = [0.0, 1.0]              # [scenarios] current_max = 1.0, which means exactly this
    direction_deg = [0.0, 360.0]    # speed and direction range

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
    checkpoint = false              # jax.checkpoint (long horizons under reverse mode)
    checkpoint_every = 10           # with checkpoint: segment length (1 = every step)
    edd = "paper"                   # or "implied"
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

    [model_error]                   # plant-only multiplicative errors, as in sweep configs
    relative = 0.0
    fields = []                     # the vehicle's parameter names ([] = its default set)

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
"""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path

from tuning.spec import DEFAULTS, KEY_DOCS, TuneConfig
from vcjax import loops
from vcjax.config import (
    ConfigError,
    Current,
    Simulation,
    Waves,
    as_range,
    as_seed,
    parse_section,
    read_toml,
)
from vcjax.config.scenario import loop_options, parse_scenario
from vcjax.sweep.config import check_waves, refusal
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
#: the shared [simulation] and [current] (vcjax.config.schema)
_SPECIAL = ("scenario", "initial", "simulation", "current", "waves")
#: [simulation] keys that tune configs may also write under [problem] (the older spelling)
_SIM_IN_PROBLEM = ("horizon", "dt", "integrator", "timing", "smooth", "edd")

_CHOICES = {
    ("problem", "integrator"): ("euler", "heun", "rk4"),
    ("problem", "timing"): ("continuous", "sampled"),
    ("problem", "edd"): ("paper", "implied"),
    ("problem", "risk"): ("mean", "cvar"),
    ("optimizer", "name"): ("lbfgs", "adam"),
    ("optimizer", "grad_mode"): ("reverse", "forward"),
}
# (section, key): (lower bound, strict) for numbers
_POSITIVE = {"horizon", "dt", "log_box", "box_weight", "learning_rate", "sat_width"}
_NONNEG = {"current_max", "position_offset", "heading_offset_deg", "grad_tol"}
_INT_MIN1 = {
    "size",
    "steps",
    "memory_size",
    "max_linesearch_steps",
    "max_bad_steps",
    "checkpoint_every",
}


def _type_name(v) -> str:
    return type(v).__name__


def _check_value(sec: str, key: str, v, default):
    where = f"{sec}.{key}"
    if isinstance(default, bool):
        if not isinstance(v, bool):
            raise ConfigError(f"{where}: expected true or false, got {v!r}")
        return v
    if isinstance(default, int):
        if isinstance(v, bool) or not isinstance(v, int):
            raise ConfigError(f"{where}: expected an integer, got {_type_name(v)} {v!r}")
        if key in _INT_MIN1 and v < 1:
            raise ConfigError(f"{where}: expected an integer >= 1, got {v}")
        if key == "seed":
            return as_seed(where, v)
        if key == "plot_scenarios" and v < 0:
            raise ConfigError(f"{where}: expected an integer >= 0, got {v}")
        return v
    if isinstance(default, float):
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ConfigError(f"{where}: expected a number, got {_type_name(v)} {v!r}")
        v = float(v)
        if not math.isfinite(v):
            raise ConfigError(f"{where}: expected a finite number, got {v}")
        if key in _POSITIVE and not v > 0:
            raise ConfigError(f"{where}: expected a number > 0, got {v}")
        if (key in _NONNEG or sec == "weights") and not v >= 0:
            raise ConfigError(f"{where}: expected a number >= 0, got {v}")
        if key == "relative" and not v < 1:
            raise ConfigError(f"{where}: expected a number in [0, 1), got {v}")
        if key == "alpha" and not 0 < v <= 1:
            raise ConfigError(f"{where}: expected a number in (0, 1], got {v}")
        return v
    if isinstance(default, str):
        if not isinstance(v, str):
            raise ConfigError(f"{where}: expected a string, got {_type_name(v)} {v!r}")
        choices = _CHOICES.get((sec, key))
        if choices and v not in choices:
            raise ConfigError(f"{where}: expected one of {list(choices)}, got {v!r}")
        return v
    if isinstance(default, list) and key == "force":  # disturbance.force
        if not isinstance(v, list):
            raise ConfigError(f"{where}: expected a list of ranges, got {v!r}")
        return [list(as_range(where, r)) for r in v]
    if isinstance(default, list):  # problem.tune, model_error.fields
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
            raise ConfigError(f"{where}: expected a list of names, got {v!r}")
        if len(set(v)) != len(v):
            raise ConfigError(f"{where}: duplicate names in {v}")
        return list(v)
    raise AssertionError(where)  # pragma: no cover


def _tune_current(cur: Current, table: dict, current_max: float) -> dict:
    """The current a tune samples, both keys resolved (what ``run.json`` records is what runs).

    Without ``[current] speed`` and ``direction_deg`` the current is ``[scenarios]
    current_max``'s: speed ``[0, current_max]`` in any direction ``[0, 360]``; writing either
    key switches to ``[current]``, whose other key then takes its section default (0.5 m/s,
    90 deg). ``model = "constant"`` (the default, and the only model a tune samples) changes
    nothing: a default means the same written or omitted.
    """
    if "speed" not in table and "direction_deg" not in table:
        return {"speed": [0.0, float(current_max)], "direction_deg": [0.0, 360.0]}
    return {"speed": list(cur.speed), "direction_deg": list(cur.direction_deg)}


def _shared_sections(raw: dict, cfg: dict) -> None:
    """Fold the shared ``[simulation]`` and ``[current]`` (vcjax.config.schema) into ``cfg``.

    ``[simulation] horizon/dt/integrator/timing/smooth/edd`` land in ``cfg["problem"]`` (the
    older spelling; both at once is refused), ``[simulation] u_d`` in ``cfg["simulation"]``;
    ``[current]`` replaces ``[scenarios] current_max`` (``cfg["current"]``: the keys given).
    """
    sim_raw = raw.get("simulation", {})
    if not isinstance(sim_raw, dict):
        raise ConfigError(f"simulation: expected a table ([simulation]), got {sim_raw!r}")
    edd = sim_raw.get("edd")
    sim = parse_section(Simulation, {k: v for k, v in sim_raw.items() if k != "edd"}, "simulation")
    for k in sim_raw:
        if k in raw.get("problem", {}) and k in _SIM_IN_PROBLEM:
            raise ConfigError(f"simulation.{k}: also given as problem.{k}; write it once")
        if k == "edd":
            cfg["problem"]["edd"] = _check_value("simulation", "edd", edd, "paper")
        elif k in _SIM_IN_PROBLEM:
            cfg["problem"][k] = getattr(sim, k)
    cfg["simulation"] = {"u_d": None if sim.u_d is None else list(sim.u_d)}
    cur_raw = raw.get("current", {})
    cur = parse_section(Current, cur_raw, "current")
    if {"speed", "direction_deg"} & set(cur_raw) and "current_max" in raw.get("scenarios", {}):
        raise ConfigError(
            "[current] speed: also given as [scenarios] current_max (its older spelling); "
            "give [current] or [scenarios] current_max, not both"
        )
    if cur.model != "constant":
        raise ConfigError("[current] model: vcjax tune samples constant currents only")
    cfg["current"] = _tune_current(cur, cur_raw, cfg["scenarios"]["current_max"])
    cfg["waves"] = None
    if "waves" in raw:  # every key, the defaults filled in (the section's presence is the switch)
        wav_raw = raw["waves"]
        wav = parse_section(Waves, wav_raw, "waves")
        check_waves(wav_raw)
        cfg["waves"] = {
            k: list(v) if isinstance(v, tuple) else v for k, v in dataclasses.asdict(wav).items()
        }


def validate_config(raw: dict, config_path=None) -> TuneConfig:
    """Defaults filled in, every value checked; returns the frozen :class:`TuneConfig`.

    ``cfg.scenario`` is the parsed ``[scenario]``, ``cfg.initial`` the ``[initial]`` ranges;
    ``config_path`` resolves the files a config names (default: the working directory).

    Raises:
        ConfigError: unknown section/key, wrong type, value out of range, a controller or gain
            the vehicle does not have.
    """
    if not isinstance(raw, dict):
        raise ConfigError("config: expected a table of sections")
    unknown = sorted(set(raw) - set(DEFAULTS) - set(_SPECIAL))
    if unknown:
        raise ConfigError(
            f"config: unknown sections {unknown}; expected {sorted([*DEFAULTS, *_SPECIAL])}"
        )
    cfg = copy.deepcopy(DEFAULTS)
    for sec, table in raw.items():
        if not isinstance(table, dict):
            raise ConfigError(f"{sec}: expected a table ([{sec}]), got {_type_name(table)}")
        if sec in _SPECIAL:
            continue
        bad = sorted(set(table) - set(DEFAULTS[sec]))
        if bad:
            known = sorted(DEFAULTS[sec])
            raise ConfigError(f"{sec}: unknown keys {bad}; expected some of {known}")
        for key, v in table.items():
            cfg[sec][key] = _check_value(sec, key, v, DEFAULTS[sec][key])
    p = cfg["problem"]
    _shared_sections(raw, cfg)
    if p["horizon"] / p["dt"] < 1:
        raise ConfigError(f"problem.horizon: must be >= problem.dt, got {p['horizon']}")
    if cfg["waves"] is not None:
        check_wave_step(cfg["waves"]["tp"][0], p["dt"], "[waves] tp")
    choice = parse_scenario(raw.get("scenario"), "scenario", config_path or Path("config"))
    cls = loops.loop_class(choice.vehicle)
    ctrl = p["variant"] or choice.controller or cls.default_controller or cls.controllers[0]
    if ctrl not in cls.controllers:
        raise ConfigError(
            f"problem.variant: vehicle {choice.vehicle!r} supports {list(cls.controllers)}, "
            f"got {ctrl!r}"
        )
    if choice.controller and p["variant"] and p["variant"] != choice.controller:
        raise ConfigError(
            f"problem.variant: {p['variant']!r} contradicts [scenario] controller "
            f"{choice.controller!r}"
        )
    p["variant"] = ctrl
    if "edd" in loop_options(cls):  # [problem]/[simulation] edd: older spellings of [scenario] edd
        given = dict(choice.options)
        old = [f"[{sec}] edd" for sec in ("problem", "simulation") if "edd" in raw.get(sec, {})]
        if "edd" in given and old and given["edd"] != p["edd"]:
            raise ConfigError(
                f"{old[0]}: {p['edd']!r} contradicts [scenario] edd {given['edd']!r} (its newer "
                "spelling); give one of them"
            )
        if "edd" in given:
            p["edd"] = given["edd"]  # what runs is what run.json records
        else:
            choice = dataclasses.replace(choice, options=(*choice.options, ("edd", p["edd"])))
    loop = choice.loop(ctrl)
    try:  # a sea the loop cannot take is refused, never silently ignored
        loops.check_disturbances(loop, False, False, waves=cfg["waves"] is not None)
    except ValueError as err:
        raise ConfigError(refusal(err)) from None
    names = [g.name for g in loop.gain_specs()]
    bad = [t for t in p["tune"] if t not in names]
    if bad:
        raise ConfigError(
            f"problem.tune: unknown gains {bad} for {loop.describe()}; choose from {names}"
        )
    valid = loop.param_names()
    bad = [f for f in cfg["model_error"]["fields"] if f not in valid]
    if bad:
        raise ConfigError(
            f"model_error.fields: unknown {choice.vehicle} parameters {bad}; valid: {list(valid)}"
        )
    init = raw.get("initial", {})
    for k, v in init.items():
        if k not in loop.initial_keys:
            raise ConfigError(
                f"initial.{k}: unknown key for vehicle {choice.vehicle!r}; "
                f"expected one of {list(loop.initial_keys)}"
            )
        init[k] = list(as_range(f"initial.{k}", v))
    cfg["initial"] = dict(init)
    cfg["scenario"] = choice.to_dict()
    return TuneConfig.from_dict(cfg)


def load_config(path) -> TuneConfig:
    """Read and validate a TOML file (the frozen :class:`TuneConfig`); files it names are
    resolved against its folder."""
    path = Path(path)
    raw = read_toml(path)
    try:
        cfg = validate_config(raw, path)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None
    g = cfg.problem.initial_gains
    if g:
        gp = Path(g)
        g = str(gp if gp.is_absolute() else path.parent / gp)
        cfg = dataclasses.replace(cfg, problem=dataclasses.replace(cfg.problem, initial_gains=g))
    return cfg
