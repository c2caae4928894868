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

Every error names the config file, the section and the key; a log's errors name the log file and
the column. Unknown sections and keys are rejected.
"""

from __future__ import annotations

import json
import math
import tomllib
from pathlib import Path

from vcjax.identify.data import load_log
from vcjax.identify.models import get_fit_model, scalar_fields
from vcjax.identify.shooting import FitResult, fit_logs

__all__ = ["FitConfig", "load_fit_config", "run_fit_config", "FIT_SCHEMA"]

#: section -> key -> (expected type(s), default; ``...`` = required)
FIT_SCHEMA: dict[str, dict[str, tuple]] = {
    "data": {"files": (list, ...)},
    "model": {
        "vehicle": (str, ...),
        "step": (str, "rk4"),
        "current_speed": ((int, float), 0.0),
        "current_direction_deg": ((int, float), 0.0),
    },
    "fit": {
        "params": (list, ...),
        "fit_current": (bool, False),
        "initial_scale": ((int, float), 1.0),
        "segment_steps": (int, 50),
        "max_iters": (int, 50),
    },
}

_TYPE_NAMES = {list: "a list", str: "a string", bool: "true or false", int: "an integer"}


class FitConfig(dict):
    """The parsed config: ``cfg[section][key]`` with defaults filled in, plus ``cfg.path``."""

    path: Path


def _type_name(t) -> str:
    return "a number" if t == (int, float) else _TYPE_NAMES.get(t, str(t))


def load_fit_config(path) -> FitConfig:
    """Parse and check a ``vcjax fit`` config (nothing is loaded or compiled).

    Raises:
        ValueError: ``"CONFIG: [section] key: ..."`` for the first problem found.
        OSError: when the file cannot be read.
    """
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ValueError(f"{path}: not valid TOML: {err}") from None
    for section in raw:
        if section not in FIT_SCHEMA:
            raise ValueError(
                f"{path}: unknown section [{section}] (allowed: "
                f"{', '.join(f'[{s}]' for s in FIT_SCHEMA)})"
            )
    cfg = FitConfig()
    cfg.path = path
    for section, keys in FIT_SCHEMA.items():
        given = raw.get(section, {})
        if not isinstance(given, dict):
            raise ValueError(f"{path}: [{section}] must be a table")
        for key in given:
            if key not in keys:
                raise ValueError(
                    f"{path}: [{section}] unknown key {key!r} (allowed: {', '.join(keys)})"
                )
        out = {}
        for key, (typ, default) in keys.items():
            where = f"{path}: [{section}] {key}"
            if key not in given:
                if default is ...:
                    raise ValueError(f"{where}: required key is missing")
                out[key] = default
                continue
            v = given[key]
            if isinstance(v, bool) and typ is not bool or not isinstance(v, typ):
                raise ValueError(f"{where}: expected {_type_name(typ)}, got {v!r}")
            out[key] = v
        cfg[section] = out
    _check_values(path, cfg)
    return cfg


def _check_values(path: Path, cfg: FitConfig) -> None:
    d, m, f = cfg["data"], cfg["model"], cfg["fit"]
    if not d["files"] or not all(isinstance(x, str) and x for x in d["files"]):
        raise ValueError(f"{path}: [data] files: expected a non-empty list of file names")
    try:
        model = get_fit_model(m["vehicle"])
    except ValueError as err:
        raise ValueError(f"{path}: [model] {err}") from None
    if m["step"] not in model.steps:
        raise ValueError(
            f"{path}: [model] step: {m['step']!r} is not available for {m['vehicle']!r}; "
            f"choose one of {list(model.steps)}"
        )
    for key in ("current_speed", "current_direction_deg"):
        if not math.isfinite(m[key]):
            raise ValueError(f"{path}: [model] {key}: expected a finite number, got {m[key]}")
    if m["current_speed"] < 0:
        raise ValueError(f"{path}: [model] current_speed: expected >= 0, got {m['current_speed']}")
    if f["fit_current"] and not m["current_speed"] > 0:
        raise ValueError(
            f"{path}: [model] current_speed: fit_current = true needs a positive initial guess"
        )
    if not all(isinstance(p, str) for p in f["params"]):
        raise ValueError(f"{path}: [fit] params: expected a list of parameter names")
    if not f["params"] and not f["fit_current"]:
        raise ValueError(f"{path}: [fit] params: nothing to fit")
    nominal = model.nominal(None)
    scalars = scalar_fields(nominal)
    for p in f["params"]:
        if p not in scalars:
            raise ValueError(
                f"{path}: [fit] params: {p!r} is not a scalar parameter of {m['vehicle']!r} "
                f"(choose from {', '.join(scalars)})"
            )
    if len(set(f["params"])) != len(f["params"]):
        raise ValueError(f"{path}: [fit] params: names must be unique, got {f['params']}")
    if not (math.isfinite(f["initial_scale"]) and f["initial_scale"] > 0):
        raise ValueError(f"{path}: [fit] initial_scale: expected > 0, got {f['initial_scale']}")
    if f["segment_steps"] < 2:
        raise ValueError(f"{path}: [fit] segment_steps: expected >= 2, got {f['segment_steps']}")
    if f["max_iters"] < 1:
        raise ValueError(f"{path}: [fit] max_iters: expected >= 1, got {f['max_iters']}")


def run_fit_config(config_path, out, progress: bool = False) -> dict:
    """Run ``vcjax fit``: load the logs, fit, write ``fit.json`` and the figures into ``out``.

    Returns:
        ``{"result": FitResult, "fit": fit.json's dict, "files": [written paths]}``.

    Raises:
        ValueError: for a bad config or log (naming file, section, key or column); OSError.
    """
    cfg = load_fit_config(config_path)
    m, f = cfg["model"], cfg["fit"]
    model = get_fit_model(m["vehicle"])
    base = Path(config_path).parent
    logs = [
        load_log(base / name, model.state_columns, model.command_columns)
        for name in cfg["data"]["files"]
    ]
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out: {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)

    def callback(stage, it, cost, lam):
        if progress:
            print(f"  stage {stage} iteration {it:3d}: cost {cost:.6g} (damping {lam:.2g})")

    result: FitResult = fit_logs(
        model,
        logs,
        f["params"],
        step=m["step"],
        fit_current=f["fit_current"],
        current_speed=float(m["current_speed"]),
        current_direction=math.radians(m["current_direction_deg"]),
        initial_scale=float(f["initial_scale"]),
        segment_steps=f["segment_steps"],
        max_iters=f["max_iters"],
        callback=callback,
    )
    fit = result.to_json()
    fit["files"] = [str(x) for x in cfg["data"]["files"]]
    fit["config"] = {k: dict(v) for k, v in cfg.items()}
    files = [out / "fit.json"]
    (out / "fit.json").write_text(json.dumps(fit, indent=2, allow_nan=False) + "\n")
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
