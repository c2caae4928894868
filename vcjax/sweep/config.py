"""``vcjax sweep CONFIG.toml``: the TOML schema (see [`vcjax.sweep`][vcjax.sweep]),
[`load_config`][vcjax.sweep.config.load_config]
and [`run_sweep_config`][vcjax.sweep.config.run_sweep_config]."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax

from vcjax import environment, loops
from vcjax.config import (
    ConfigError,
    Current,
    Disturbance,
    ModelError,
    Simulation,
    Waves,
    as_bool,
    as_str_list,
    check_schema,
    note,
    parse_section,
    read_toml,
    resolve_file,
    unknown_key,
)
from vcjax.config.aliases import note_old_spellings, take_moved
from vcjax.config.scenario import parse_scenario
from vcjax.config.schema import registered
from vcjax.sweep.results import load_results, merge_results, save_results, summarize
from vcjax.sweep.run import run_sweep
from vcjax.sweep.spec import SECTIONS, ScenarioSpec, SweepSpec

#: the sections a ScenarioSpec holds as they are parsed
SCENARIO_SECTIONS = tuple(SECTIONS)

__all__ = ["SCHEMA", "load_config", "run_sweep_config", "refusal"]

#: section -> keys ([initial] and [sensor_noise] keys depend on the vehicle); a key of
#: [sweep], [simulation], [metrics] or [output] that is a field of SweepSpec is that field
SCHEMA: dict[str, tuple[str, ...] | None] = {
    "scenario": None,  # vcjax.config.scenario checks it (the options depend on the loop)
    "sweep": ("num_scenarios", "seed", "variants", "chunk_size"),
    "simulation": (*(f.name for f in dataclasses.fields(Simulation)), "gains"),
    "current": tuple(f.name for f in dataclasses.fields(Current)),
    "waves": tuple(f.name for f in dataclasses.fields(Waves)),
    "initial": None,
    "model_error": tuple(f.name for f in dataclasses.fields(ModelError)),
    "sensor_noise": None,
    "disturbance": tuple(f.name for f in dataclasses.fields(Disturbance)),
    "metrics": ("tail", "diverge_e"),
    "output": ("record_points", "figures"),
}
#: the sections whose keys are SweepSpec fields of the same name
_SPEC_SECTIONS = ("sweep", "simulation", "metrics", "output")


def _toml_name(msg: str) -> str:
    """Rewrite a SweepSpec field name at the start of ``msg`` into its ``[section] key``."""
    head, sep, rest = msg.partition(":")
    for sec in _SPEC_SECTIONS:
        if head in SCHEMA[sec]:
            return f"[{sec}] {head}{sep}{rest}"
    return msg


def refusal(err: ValueError) -> str:
    """[`vcjax.loops.check_disturbances`][vcjax.loops.scenario.check_disturbances]'s message with
    its TOML section first."""
    msg = str(err)
    for sec in ("waves", "current"):
        if msg.startswith(f"{sec}: "):
            return f"[{sec}] " + msg.removeprefix(f"{sec}: ")
    return msg


def _sections(raw: dict) -> dict:
    """The shared sections ([`vcjax.config.schema`][vcjax.config.schema]) of a sweep config,
    parsed (``"waves"``: ``None`` without ``[waves]``)."""
    out = {"waves": None}
    for sec, cls in SECTIONS.items():
        if sec != "waves" or "waves" in raw:
            out[sec] = parse_section(cls, raw.get(sec), sec)
    sim = {k: v for k, v in raw.get("simulation", {}).items() if k != "gains"}
    out["simulation"] = parse_section(Simulation, sim, "simulation")
    if "smooth" in sim and out["simulation"].smooth:
        raise ConfigError(
            "[simulation] smooth: a sweep simulates the hard-clipped plant (smooth = false)"
        )
    return out


def environment_sections(raw: dict, schema, where: str) -> tuple[dict, tuple]:
    """``(rest, environment)``: the sections of ``raw`` that are registered components of
    [`vcjax.environment`][vcjax.environment] and not sections of the command itself, checked and
    frozen
    ([`vcjax.environment.freeze`][vcjax.environment.component.freeze]), and the rest of ``raw``."""
    known = set(environment.components()) - set(schema)
    env = []
    for sec in [s for s in raw if s in known]:
        try:
            env.append(environment.freeze(sec, raw[sec]))
        except ValueError as err:
            raise ConfigError(f"{where}: {err}" if where else str(err)) from None
    return {k: v for k, v in raw.items() if k not in known}, tuple(env)


#: the note of a sweep of an engine loop (vcjax.loops.EngineLoop: the puck, the point mass, a
#: loop of your own) without [current]: such configs were written when the engine felt no
#: current and ran in still water; the engine now feels the default current
ENGINE_CURRENT_NOTE = (
    "{where}: [current] speed not given: the {vehicle} scenarios run in the default current, "
    "0.5 m/s towards 90 deg (Simulation 1's); engine loops feel it since the engine took the "
    "current (before, such a config ran in still water): write [current] speed = 0 for still "
    "water"
)


def _check_tables(raw: dict, cls, where: str) -> dict:
    """Every section and key known (the sections added to the one table of sections included,
    the vehicle's ``[initial]`` and ``[sensor_noise]`` keys), ``[sweep] num_scenarios`` given;
    returns the added sections, parsed."""
    added = registered()
    check_schema(
        raw,
        {**SCHEMA, **{n: tuple(f.name for f in dataclasses.fields(c)) for n, c in added.items()}},
        where,
    )
    for sec, valid in (("initial", tuple(cls.initial_keys)), ("sensor_noise", cls.noise_channels)):
        for key in raw.get(sec, {}):
            if key not in valid:
                note = f"for vehicle {cls.vehicle!r}"
                raise ConfigError(f"{where}: {unknown_key(sec, key, valid, note)}")
    if "num_scenarios" not in raw.get("sweep", {}):
        raise ConfigError(f"{where}: [sweep] num_scenarios is required")
    return {n: parse_section(c, raw.get(n), n, where) for n, c in added.items()}


def _spec_keys(raw: dict, choice, cls) -> dict:
    """The keys of ``[sweep]``, ``[simulation]``, ``[metrics]``, ``[output]`` that are
    [`SweepSpec`][vcjax.sweep.spec.SweepSpec] fields; ``variants``: ``[sweep] variants`` (which
    must agree with ``[scenario] controller``), else the controller, else the vehicle's."""
    fields = {f.name for f in dataclasses.fields(SweepSpec)}
    kw = {k: v for s in _SPEC_SECTIONS for k, v in raw.get(s, {}).items() if k in fields}
    ctrl = choice.controller
    if "variants" in kw:
        kw["variants"] = as_str_list("[sweep] variants", kw["variants"])
        if ctrl is not None and tuple(kw["variants"]) != (ctrl,):
            raise ConfigError(
                f"[sweep] variants: {list(kw['variants'])} contradicts [scenario] controller "
                f"{ctrl!r} (its newer spelling); give one of them"
            )
    elif ctrl:
        kw["variants"] = (ctrl,)
    elif choice.vehicle != "infante":
        kw["variants"] = cls.controllers
    return kw


def _scenario(raw: dict, sec: dict, env: tuple, cls, where: str) -> ScenarioSpec:
    """The [`ScenarioSpec`][vcjax.sweep.spec.ScenarioSpec]: the parsed sections as they are (a
    loop that feels no current gets still water unless ``[current] speed`` is given); a current,
    sea or component the loop cannot take is refused, never silently ignored."""
    current = sec["current"]
    if "speed" not in raw.get("current", {}):
        if not cls.can_feel("current"):
            current = dataclasses.replace(current, speed=(0.0, 0.0))
        elif issubclass(cls, loops.EngineLoop):
            note(ENGINE_CURRENT_NOTE.format(where=where, vehicle=cls.vehicle))
    try:
        gm = current.model == "gauss_markov"
        loops.check_disturbances(cls, max(current.speed) > 0, gm, waves=sec["waves"] is not None)
        loops.check_environment(cls, [environment.lookup(s) for s, _ in env])
    except ValueError as err:
        raise ConfigError(refusal(err)) from None
    keep = {k: sec[k] for k in SCENARIO_SECTIONS}
    return ScenarioSpec(**keep | {"current": current}, u_d=sec["simulation"].u_d, environment=env)


def load_config(config_path, raw: dict | None = None) -> tuple[SweepSpec, dict]:
    """Read and validate a sweep TOML file (schema: [`vcjax.sweep`][vcjax.sweep]); ``raw``: its
    tables already read (e.g. ``vcjax falsify``'s, without its own section).

    Returns:
        ``(spec, extras)``: the [`SweepSpec`][vcjax.sweep.spec.SweepSpec] and ``extras = {"gains":
        path or None, "figures": bool, "sections": {name: section}}`` (``sections``: the
        sections added by [`vcjax.config.register_section`][vcjax.config.schema.register_section],
        parsed).

    Raises:
        ConfigError: naming the file, section and key (unknown section or key, wrong type,
            out-of-range value, missing ``[sweep] num_scenarios``, a missing or invalid
            referenced file by its path).
    """
    config_path = Path(config_path)
    given = read_toml(config_path) if raw is None else raw
    where = str(config_path)
    raw, older = take_moved(given)  # loop options in their older spellings
    choice = parse_scenario(raw.get("scenario"), where, config_path, older)  # may register
    raw, env = environment_sections(raw, SCHEMA, where)
    cls = loops.loop_class(choice.vehicle)
    own = _check_tables(raw, cls, where)
    try:
        scenario = _scenario(raw, _sections(raw), env, cls, where)
        spec = SweepSpec(scenario=scenario, choice=choice, **_spec_keys(raw, choice, cls))
        figures = as_bool("[output] figures", raw.get("output", {}).get("figures", True))
    except ConfigError as err:
        raise ConfigError(f"{where}: {_toml_name(str(err))}") from None
    gains = raw.get("simulation", {}).get("gains")
    if gains is not None:
        gains = resolve_file(f"{where}: [simulation] gains", gains, config_path)
    note_old_spellings(given, where)  # once the config is known to be valid
    return spec, {"gains": gains, "figures": figures, "sections": own}


def run_sweep_config(
    config_path,
    out_dir,
    progress: bool | Callable[[str], Any] = True,
    netcdf: bool = False,
    loaded: tuple[SweepSpec, dict] | None = None,
    draw: Callable[[Any, Path], list[Path]] | None = None,
) -> dict:
    """Run the sweep described by a TOML file and write its results (the ``vcjax sweep`` CLI).

    Writes into ``out_dir``: ``summary.json`` ([`summarize`][vcjax.sweep.results.summarize]),
    ``results.npz`` ([`save_results`][vcjax.sweep.results.save_results]) and, with ``draw`` and
    unless
    ``[output] figures = false``, the figures ``draw`` writes. In a multi-process run
    (after ``jax.distributed.initialize``) every process runs its share of chunks and writes
    ``results.part<p>-of-<P>.npz`` into the (shared) ``out_dir``; process 0 waits for the others,
    merges the parts and writes the outputs. With ``netcdf``, also ``results.nc``
    ([`to_xarray`][vcjax.sweep.results.SweepResult.to_xarray]; needs the ``xarray`` extra).

    Args:
        config_path: the TOML file; out_dir: output folder (created).
        progress: True: a bar on stderr; a callable: one line per chunk; False: silent.
        netcdf: also write ``results.nc``.
        loaded: the file already parsed by [`load_config`][vcjax.sweep.config.load_config] (the CLI
            parses it once and
            records it); default: parse ``config_path``.
        draw: ``draw(result, out_dir) -> [Path, ...]`` writes the figures (the CLI passes
            [`sweep_figures`][vcjax.plots.sweep.sweep_figures]; the sweep itself draws nothing),
            called
            unless ``[output] figures = false``.

    Returns:
        ``{"summary": dict, "files": [Path, ...], "result": SweepResult, "figures": bool}``
        (on processes other than 0: the part file only, and ``summary`` None).
    """
    from vcjax.runtime.outputs import write_json_atomic

    spec, extras = load_config(config_path) if loaded is None else loaded
    if netcdf:
        from vcjax.sweep.labelled import _xr

        _xr()  # fail before the sweep, not after it, when xarray is missing
    gains = None
    if extras["gains"] is not None:
        loop = spec.loop(spec.variants[0])
        try:
            gains = loop.gains_from_json(json.loads(Path(extras["gains"]).read_text()))
        except (OSError, json.JSONDecodeError, ValueError) as err:
            raise ConfigError(
                f"{config_path}: [simulation] gains: {extras['gains']}: {err}"
            ) from None
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
    write_json_atomic(out / "summary.json", summary)
    files.append(out / "summary.json")
    if netcdf:
        from vcjax.sweep.labelled import write_netcdf

        files.append(write_netcdf(result, out / "results.nc"))
    if extras["figures"] and draw is not None:
        files += draw(result, out)
    return {"summary": summary, "files": files, "result": result, "figures": extras["figures"]}


#: (section, key) -> (unit, description) of the sweep-only keys (the shared sections are
#: described in [`vcjax.config.schema`][vcjax.config.schema]); the configuration reference is
#: generated from it
KEY_DOCS: dict[tuple[str, str], tuple[str, str]] = {
    ("sweep", "num_scenarios"): ("", "number of sampled scenarios (required; int >= 1)"),
    ("sweep", "seed"): ("", "seed of the scenario draws (scenario i uses fold_in(seed, i))"),
    ("sweep", "variants"): (
        "",
        "the controllers to compare (default: [scenario] controller if given, else the "
        "vehicle's controllers; INFANTE-class: the paper's vcm, vcm_integral, ilos, los_pid, "
        "vcm_ilos); must agree with [scenario] controller when both are given",
    ),
    ("sweep", "chunk_size"): ("", "scenarios per compiled batch (rounded to the device count)"),
    ("simulation", "gains"): ("file", "the vehicle's gains JSON (what vcjax tune writes)"),
    ("metrics", "tail"): ("", "fraction of the run that is the steady-state window"),
    ("metrics", "diverge_e"): ("m", "cross-track bound beyond which a run counts as diverged"),
    ("output", "record_points"): ("", "decimated trace samples kept per run for figures"),
    ("output", "figures"): ("", "draw the sweep figures"),
}
