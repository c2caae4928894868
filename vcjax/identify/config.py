"""The ``vcjax fit`` TOML config: schema, eager validation, and the runner.

```toml
[data]
files = ["run1.csv"]          # relative to the config file's folder; .csv or .npz logs
[model]
vehicle = "remus100"          # "remus100" | "infante"
step = "pvs"                  # "pvs" (PythonVehicleSimulator's Euler step, REMUS 100 only) or an
                              # integrator name ("euler", "heun", "rk4") for the continuous plant
current_speed = 0.5           # m/s, known current (or the initial guess with fit_current)
current_direction_deg = 170.0 # deg, towards which the water flows (from north towards east)
[fit]
params = ["CD_0", "CL_delta_r", "CL_delta_s", "cf_coeff"]  # scalar fields of the parameters
fit_current = false           # also estimate the current's speed and direction
initial_scale = 1.0           # start from nominal * scale (1.3 = 30 % off, for studies and tests)
segment_steps = 50
max_iters = 50
```

Every error is a [`vcjax.config.ConfigError`][vcjax.config.values.ConfigError] (the one error class
of every command) naming
the config file, the section and the key; a log's errors name the log file and the column.
Unknown sections and keys are rejected.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from vcjax.config import ConfigError, check_schema, parse_section, read_toml
from vcjax.config.frozen import FrozenSection
from vcjax.config.schema import key
from vcjax.identify.data import load_log
from vcjax.identify.fit import FitResult, FitSettings, fit_logs
from vcjax.identify.models import get_fit_model, scalar_fields
from vcjax.runtime.outputs import write_json_atomic

__all__ = [
    "FitConfig",
    "FitData",
    "FitModel",
    "FitOptions",
    "load_fit_config",
    "run_fit_config",
    "FIT_SCHEMA",
]


@dataclasses.dataclass(frozen=True)
class FitData(FrozenSection):
    """``[data]``: the logs, relative to the config file's folder."""

    files: tuple[str, ...] = key(
        (), "str_list", "file", "the logs (.csv or .npz), relative to the config", required=True
    )


@dataclasses.dataclass(frozen=True)
class FitModel(FrozenSection):
    """``[model]``: the vehicle, its step, and the known (or first-guess) current."""

    vehicle: str = key("", "str", "", "remus100 or infante", required=True)
    step: str = key("rk4", "str", "", "pvs (REMUS 100 only) or euler, heun, rk4")
    current_speed: float = key(
        0.0, "float", "m/s", "known current (initial guess with fit_current)", lo=0.0
    )
    current_direction_deg: float = key(
        0.0, "float", "deg", "direction the water flows towards (from north towards east)"
    )


@dataclasses.dataclass(frozen=True)
class FitOptions(FrozenSection):
    """``[fit]``: what is estimated and how."""

    params: tuple[str, ...] = key(
        (), "str_list", "", "scalar parameters to estimate", required=True, unique=True
    )
    fit_current: bool = key(False, "bool", "", "also estimate the current's speed and direction")
    initial_scale: float = key(1.0, "float", "", "start from nominal * scale", lo=0.0, lo_open=True)
    segment_steps: int = key(50, "int", "", "steps per multiple-shooting segment", lo=2)
    max_iters: int = key(50, "int", "", "Levenberg-Marquardt iterations", lo=1)


_SECTION_TYPES = {"data": FitData, "model": FitModel, "fit": FitOptions}

#: section -> key -> default (``...`` = required), read from the declarations above
FIT_SCHEMA: dict[str, dict[str, object]] = {
    sec: {f.name: ... if f.metadata.get("required") else f.default for f in dataclasses.fields(c)}
    for sec, c in _SECTION_TYPES.items()
}


@dataclasses.dataclass(frozen=True)
class FitConfig(FrozenSection):
    """A ``vcjax fit`` config, parsed once
    ([`load_fit_config`][vcjax.identify.config.load_fit_config]), frozen and hashable:
    ``cfg.model.vehicle`` (or ``cfg["model"]["vehicle"]``); ``path``: the file it was read
    from (not a section: ``to_dict`` holds the sections, ``run.json`` records the file)."""

    data: FitData = FitData()
    model: FitModel = FitModel()
    fit: FitOptions = FitOptions()
    path: Path = dataclasses.field(default=Path("config.toml"), metadata={"record": False})


def load_fit_config(path) -> FitConfig:
    """Parse and check a ``vcjax fit`` config (nothing is loaded or compiled): the sections
    declared above through the one validator
    ([`vcjax.config.parse_section`][vcjax.config.schema.parse_section]), then the
    names against the vehicle.

    Raises:
        vcjax.config.ConfigError (a ``ValueError``): ``"CONFIG: [section] key: ..."`` for the
            first problem found (unknown sections and keys included).
    """
    path = Path(path)
    raw = read_toml(path)
    check_schema(raw, {sec: tuple(keys) for sec, keys in FIT_SCHEMA.items()}, str(path))
    for section, keys in FIT_SCHEMA.items():
        for k, default in keys.items():
            if default is ... and k not in raw.get(section, {}):
                raise ConfigError(f"{path}: [{section}] {k}: required key is missing")
    sections = {
        sec: parse_section(cls, raw.get(sec), sec, str(path)) for sec, cls in _SECTION_TYPES.items()
    }
    cfg = FitConfig(**sections, path=path)
    _check_names(path, cfg)
    return cfg


def _check_names(path: Path, cfg: FitConfig) -> None:
    """The names against the vehicle, and the keys that depend on each other
    (``ConfigError`` naming the key)."""
    d, m, f = cfg.data, cfg.model, cfg.fit
    w = lambda sec, key: f"{path}: [{sec}] {key}"
    if not d.files or not all(d.files):
        raise ConfigError(f"{w('data', 'files')}: expected a non-empty list of file names")
    try:
        model = get_fit_model(m.vehicle)
    except ValueError as err:
        raise ConfigError(f"{path}: [model] {err}") from None
    if m.step not in model.steps:
        raise ConfigError(
            f"{w('model', 'step')}: {m.step!r} is not available for {m.vehicle!r}; "
            f"choose one of {list(model.steps)}"
        )
    if f.fit_current and not m.current_speed > 0:
        raise ConfigError(
            f"{w('model', 'current_speed')}: fit_current = true needs a positive initial guess"
        )
    if not f.params and not f.fit_current:
        raise ConfigError(f"{w('fit', 'params')}: nothing to fit")
    scalars = scalar_fields(model.nominal(None))
    for p in f.params:
        if p not in scalars:
            raise ConfigError(
                f"{w('fit', 'params')}: {p!r} is not a scalar parameter of {m.vehicle!r} "
                f"(choose from {', '.join(scalars)})"
            )


def run_fit_config(
    config_path,
    out,
    progress: bool = False,
    cfg: FitConfig | None = None,
    max_memory_gb=None,
) -> dict:
    """Run ``vcjax fit``: load the logs, fit, write ``fit.json`` and the figures into ``out``.

    Returns:
        ``{"result": FitResult, "fit": fit.json's dict, "files": [written paths]}``.

    Raises:
        ValueError: for a bad config or log (naming file, section, key or column); OSError.
    """
    cfg = load_fit_config(config_path) if cfg is None else cfg  # parsed once by the CLI
    if not isinstance(cfg, FitConfig):  # the older dict form (e.g. a run.json record)
        cfg = FitConfig.from_dict(cfg)
    m, f = cfg.model, cfg.fit
    model = get_fit_model(m.vehicle)
    base = Path(config_path).parent
    logs = [
        load_log(base / name, model.state_columns, model.command_columns) for name in cfg.data.files
    ]
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)

    def callback(stage, it, cost, lam):
        if progress:
            print(f"  stage {stage} iteration {it:3d}: cost {cost:.6g} (damping {lam:.2g})")

    options = FitSettings(
        step=m.step,
        fit_current=f.fit_current,
        current_speed=float(m.current_speed),
        current_direction=math.radians(m.current_direction_deg),
        initial_scale=float(f.initial_scale),
        segment_steps=f.segment_steps,
        max_iters=f.max_iters,
        max_memory_gb=max_memory_gb,
    )
    result: FitResult = fit_logs(model, logs, list(f.params), options, callback=callback)
    fit = result.to_json()
    fit["files"] = [str(x) for x in cfg.data.files]
    fit["config"] = cfg.to_dict()
    files = [out / "fit.json"]
    write_json_atomic(out / "fit.json", fit, allow_nan=False)
    from vcjax.identify.figures import cost_history_figure, prediction_figure

    files.append(cost_history_figure(result, out / "cost_history.png"))
    for i, log in enumerate(logs):
        stem = Path(log.name).stem
        name = (
            "measured_vs_predicted.png" if len(logs) == 1 else f"measured_vs_predicted_{stem}.png"
        )
        pred0 = result.problem.free_run(result.z0, log)
        pred = result.problem.free_run(result.z, log)
        files.append(prediction_figure(result, log, pred0, pred, out / name, index=i))
    return {"result": result, "fit": fit, "files": files}


#: (section, key) -> (unit, description) of every fit key; the configuration reference is
#: generated from it and [`FIT_SCHEMA`][vcjax.identify.config.FIT_SCHEMA]
KEY_DOCS: dict[tuple[str, str], tuple[str, str]] = {
    ("data", "files"): ("file", "logs (.csv or .npz), relative to the config file (required)"),
    ("model", "vehicle"): ("", "the vehicle whose plant is fitted: remus100 or infante"),
    ("model", "step"): ("", "pvs (PythonVehicleSimulator's Euler step) or euler, heun, rk4"),
    ("model", "current_speed"): ("m/s", "known current (or the first guess with fit_current)"),
    ("model", "current_direction_deg"): ("deg", "towards which the water flows, from north"),
    ("fit", "params"): ("", "scalar parameters to estimate (required)"),
    ("fit", "fit_current"): ("", "also estimate the current's speed and direction"),
    ("fit", "initial_scale"): ("", "start from nominal x scale (studies and tests)"),
    ("fit", "segment_steps"): ("", "steps per multiple-shooting segment"),
    ("fit", "max_iters"): ("", "Levenberg-Marquardt iterations"),
}
