"""TOML configuration of a tuning run (``vcjax tune CONFIG.toml``), validated with clear errors.

Every section and key is optional (defaults below); unknown sections or keys, wrong types and
out-of-range values raise :class:`ConfigError` naming the offending ``section.key``::

    [problem]                       # what is tuned and how a rollout is simulated
    variant = "vcm_integral"        # or "vcm", "vcm_ilos"
    tune = ["P_G", "P_Phi", "Delta", "sigma", "P_int"]
    initial_gains = ""              # gains JSON (sim1.gains_to_json format); "" = defaults
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

    [scenarios]                     # distribution of the random scenarios
    current_max = 1.0               # [m/s], uniform speed, uniform direction
    position_offset = 5.0           # [m], uniform on each of x, y
    heading_offset_deg = 45.0       # [deg], uniform

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
import math
import tomllib
from pathlib import Path
from typing import Any

from tuning.params import GAIN_NAMES

__all__ = ["ConfigError", "DEFAULTS", "load_config", "validate_config"]


class ConfigError(ValueError):
    """A tuning configuration is invalid (the message names ``section.key``)."""


DEFAULTS: dict[str, dict[str, Any]] = {
    "problem": {
        "variant": "vcm_integral",
        "tune": ["P_G", "P_Phi", "Delta", "sigma", "P_int"],
        "initial_gains": "",
        "horizon": 80.0,
        "dt": 0.1,
        "integrator": "rk4",
        "timing": "continuous",
        "smooth": True,
        "checkpoint": False,
        "checkpoint_every": 10,
        "edd": "paper",
        "risk": "mean",
        "alpha": 0.2,
        "log_box": 3.0,
        "box_weight": 10.0,
    },
    "weights": {
        "eps": 1.0,
        "u_tilde": 1.0,
        "psi_tilde": 1.0,
        "sat_excess": 1.0,
        "sat_time": 5.0,
        "effort": 0.0,
        "unhealthy": 1000.0,
        "sat_width": 0.05,
    },
    "scenarios": {"current_max": 1.0, "position_offset": 5.0, "heading_offset_deg": 45.0},
    "train": {"size": 16, "seed": 0},
    "heldout": {"size": 64, "seed": 1001, "smooth": False},
    "optimizer": {
        "name": "lbfgs",
        "steps": 40,
        "learning_rate": 0.05,
        "memory_size": 10,
        "max_linesearch_steps": 15,
        "grad_mode": "reverse",
        "max_bad_steps": 5,
        "grad_tol": 1e-8,
    },
    "report": {"plot_scenarios": 4},
}

_CHOICES = {
    ("problem", "variant"): ("vcm", "vcm_integral", "vcm_ilos"),
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
        if key == "seed" and v < 0:
            raise ConfigError(f"{where}: expected an integer >= 0, got {v}")
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
    if isinstance(default, list):  # problem.tune
        if not isinstance(v, list) or not all(isinstance(x, str) for x in v) or not v:
            raise ConfigError(f"{where}: expected a non-empty list of names, got {v!r}")
        bad = [x for x in v if x not in GAIN_NAMES]
        if bad:
            raise ConfigError(f"{where}: unknown gains {bad}; choose from {list(GAIN_NAMES)}")
        if len(set(v)) != len(v):
            raise ConfigError(f"{where}: duplicate names in {v}")
        return list(v)
    raise AssertionError(where)  # pragma: no cover


def validate_config(raw: dict) -> dict:
    """Defaults filled in, every value checked; returns a new nested dict.

    Raises:
        ConfigError: unknown section/key, wrong type, or value out of range.
    """
    if not isinstance(raw, dict):
        raise ConfigError("config: expected a table of sections")
    unknown = sorted(set(raw) - set(DEFAULTS))
    if unknown:
        raise ConfigError(f"config: unknown sections {unknown}; expected {sorted(DEFAULTS)}")
    cfg = copy.deepcopy(DEFAULTS)
    for sec, table in raw.items():
        if not isinstance(table, dict):
            raise ConfigError(f"{sec}: expected a table ([{sec}]), got {_type_name(table)}")
        bad = sorted(set(table) - set(DEFAULTS[sec]))
        if bad:
            known = sorted(DEFAULTS[sec])
            raise ConfigError(f"{sec}: unknown keys {bad}; expected some of {known}")
        for key, v in table.items():
            cfg[sec][key] = _check_value(sec, key, v, DEFAULTS[sec][key])
    p = cfg["problem"]
    if p["horizon"] / p["dt"] < 1:
        raise ConfigError(f"problem.horizon: must be >= problem.dt, got {p['horizon']}")
    if p["variant"] == "vcm" and p["tune"] == ["P_int"]:
        raise ConfigError("problem.tune: the 'vcm' variant has no integral gains to tune")
    return cfg


def load_config(path) -> dict:
    """Read and validate a TOML file; ``problem.initial_gains`` is resolved against its folder."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except OSError as err:
        raise ConfigError(f"cannot read {path}: {err}") from None
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: invalid TOML: {err}") from None
    cfg = validate_config(raw)
    g = cfg["problem"]["initial_gains"]
    if g:
        gp = Path(g)
        cfg["problem"]["initial_gains"] = str(gp if gp.is_absolute() else path.parent / gp)
    return cfg
