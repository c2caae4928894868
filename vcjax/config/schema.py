"""The shared sections of ``vcjax sweep`` and ``vcjax tune`` configs, declared once.

Every section is a frozen dataclass; each of its fields carries, in its ``metadata``, the key's
``type`` (``"float"``, ``"int"``, ``"bool"``, ``"str"``, ``"range"`` = a number or ``[lo, hi]``
sampled uniformly, ``"str_list"``, ``"range_list"``), ``unit``, ``doc`` (one line), ``choices``,
bounds and the older spellings still accepted (``aliases``, as ``"[section] key"``). The field's
default is the key's default. [`schema`][vcjax.config.schema] lists them for a reference table;
[`parse_section`][vcjax.config.schema.parse_section] turns one TOML table into a section object
(eager checks, errors name the
file, section and key).

The ``[scenario]`` section (what is simulated) is
[`ScenarioChoice`][vcjax.config.scenario.ScenarioChoice]:
its loop options are read from the loop class's dataclass fields, so it lives beside the loop
registry. The scenario of a config without ``[scenario]`` is ``DEFAULT_SCENARIO``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from vcjax.config.frozen import FrozenSection
from vcjax.config.values import (
    ConfigError,
    as_bool,
    as_choice,
    as_int,
    as_number,
    as_range,
    as_seed,
    as_str,
    as_str_list,
    closest,
)

__all__ = [
    "DEFAULT_SCENARIO",
    "registered",
    "register_section",
    "Simulation",
    "Current",
    "Waves",
    "Initial",
    "ModelError",
    "SensorNoise",
    "Disturbance",
    "SECTIONS",
    "parse_section",
]

#: the scenario of a config without ``[scenario]``: Simulation 1 of the paper (the
#: INFANTE-class craft on the line ``[10, w]``, its default controller)
DEFAULT_SCENARIO: dict[str, Any] = {"vehicle": "infante", "controller": None, "path": None}


def key(default, type_: str, unit: str = "", doc: str = "", **meta):
    """A section field with its metadata (``choices``, ``lo``/``lo_open``/``hi``/``hi_open``,
    ``aliases``)."""
    return dataclasses.field(
        default=default, metadata={"type": type_, "unit": unit, "doc": doc, **meta}
    )


@dataclasses.dataclass(frozen=True)
class Simulation:
    """``[simulation]``: how one rollout is integrated.

    ``horizon`` and ``dt`` default per command (``None`` here): ``vcjax sweep`` 60 s / 0.05 s,
    ``vcjax tune`` 80 s / 0.1 s. ``smooth`` (tanh actuator saturation, gradients pass) is what
    ``vcjax tune`` trains with; a sweep always simulates the hard-clipped plant. Tune configs
    may still write these keys under ``[problem]``.
    """

    horizon: float | None = key(
        None, "float", "s", "simulated time", lo=0.0, lo_open=True, aliases=("[problem] horizon",)
    )
    dt: float | None = key(
        None, "float", "s", "integration step", lo=0.0, lo_open=True, aliases=("[problem] dt",)
    )
    integrator: str = key(
        "rk4",
        "str",
        "",
        "fixed-step integrator",
        choices=("euler", "heun", "rk4"),
        aliases=("[problem] integrator",),
    )
    timing: str = key(
        "continuous",
        "str",
        "",
        "controller evaluated inside every stage, or sampled once per step (zero-order hold)",
        choices=("continuous", "sampled"),
        aliases=("[problem] timing",),
    )
    u_d: tuple[float, float] | None = key(
        None, "range", "m/s", "desired speed (default: the loop's)", positive=True
    )
    smooth: bool = key(
        True, "bool", "", "smooth (tanh) saturation while training", aliases=("[problem] smooth",)
    )


@dataclasses.dataclass(frozen=True)
class Current:
    """``[current]``: the ocean current of every scenario (NED; the direction is the one the
    water flows towards, clockwise from north).

    ``model = "gauss_markov"`` lets the speed wander around the sampled one (``sigma``, ``tau``,
    clipped to ``[0, max_speed]``); these three keys are refused with the constant model (they
    would be ignored). In tune configs ``[scenarios] current_max = m`` is the older spelling of
    ``speed = [0, m]``, ``direction_deg = [0, 360]`` (the tune's current without ``speed`` and
    ``direction_deg``); giving either key uses ``[current]``, the other key at its default.
    """

    model: str = key("constant", "str", "", "current model", choices=("constant", "gauss_markov"))
    speed: tuple[float, float] = key(
        (0.5, 0.5),
        "range",
        "m/s",
        "mean current speed",
        lo=0.0,
        aliases=("[scenarios] current_max",),
    )
    direction_deg: tuple[float, float] = key(
        (90.0, 90.0), "range", "deg", "direction the water flows towards"
    )
    sigma: float = key(0.05, "float", "m/s", "Gauss-Markov speed standard deviation", lo=0.0)
    tau: float = key(300.0, "float", "s", "Gauss-Markov time constant", lo=0.0, lo_open=True)
    max_speed: float = key(2.0, "float", "m/s", "Gauss-Markov speed bound", lo=0.0, lo_open=True)


@dataclasses.dataclass(frozen=True)
class Initial:
    """``[initial]``: ranges of the vehicle's initial keys (``loop.initial_keys``, e.g. ``x``,
    ``y``, ``heading_deg``; missing keys: the loop's defaults). The keys depend on the vehicle.
    In tune configs ``[scenarios] position_offset`` (m, on ``x`` and ``y``) and
    ``heading_offset_deg`` (deg, on ``heading_deg``) are the older spellings of ranges about the
    default start; keys given here override them."""

    values: tuple[tuple[str, tuple[float, float]], ...] = key(
        (),
        "range",
        "m, deg",
        "one range per initial key of the vehicle",
        open_keys="the vehicle's initial keys",
        aliases=("[scenarios] position_offset", "[scenarios] heading_offset_deg"),
    )


@dataclasses.dataclass(frozen=True)
class ModelError(FrozenSection):
    """``[model_error]``: plant-only multiplicative parameter errors, each field scaled by
    ``1 + relative * U(-1, 1)`` (the controller keeps the nominal model)."""

    relative: float = key(0.0, "float", "", "relative error bound", lo=0.0, hi=1.0, hi_open=True)
    fields: tuple[str, ...] | None = key(
        None,
        "str_list",
        "",
        "the vehicle's parameter names (default: its default set)",
        unique=True,
    )


@dataclasses.dataclass(frozen=True)
class SensorNoise:
    """``[sensor_noise]``: standard deviation of the Gaussian noise added to what the
    controller measures, per channel of the vehicle (``loop.noise_channels``; ``*_deg``
    channels in degrees or deg/s). Sweeps only."""

    values: tuple[tuple[str, float], ...] = key(
        (),
        "float",
        "SI, deg",
        "one standard deviation per noise channel",
        lo=0.0,
        open_keys="the vehicle's noise channels",
    )


@dataclasses.dataclass(frozen=True)
class Disturbance(FrozenSection):
    """``[disturbance]``: a constant generalised force on the plant, one range per component
    (N, N m; empty: none)."""

    force: tuple[tuple[float, float], ...] = key(
        (), "range_list", "N, N m", "one range per generalised force component"
    )


@dataclasses.dataclass(frozen=True)
class Waves:
    """``[waves]``: a random sea in every scenario (linear Airy waves in deep water,
    [`vcjax.environment.waves`][vcjax.environment.waves]; NED, depth positive down). Each scenario
    draws its ``hs``,
    ``tp``, ``direction_deg`` and ``origin_depth`` from the ranges and its sea (frequencies, phases,
    directions) from its own key, so a scenario's sea is the same whatever the chunk size or
    device count. ``hs`` and ``tp`` are required; ``hs = 0`` is a calm sea (the run is then
    exactly the run without waves). The integration step must resolve the shortest component
    (``tp / 4``) with 10 steps: ``tp >= 40 dt``. Loops whose plant cannot feel a sea refuse the
    section."""

    spectrum: str = key(
        "jonswap", "str", "", "wave spectrum (pm: Pierson-Moskowitz)", choices=("jonswap", "pm")
    )
    hs: tuple[float, float] | None = key(
        None, "range", "m", "significant wave height (required)", lo=0.0
    )
    tp: tuple[float, float] | None = key(
        None, "range", "s", "peak period (required)", positive=True
    )
    direction_deg: tuple[float, float] = key(
        (0.0, 0.0), "range", "deg", "direction the waves travel towards, clockwise from north"
    )
    gamma: float = key(3.3, "float", "", "JONSWAP peak enhancement (1: Pierson-Moskowitz)", lo=1.0)
    spreading: float = key(
        0.0,
        "float",
        "",
        "s of the cos^2s directional spreading: 0 = long-crested (every component towards "
        "direction_deg), else s >= 1 (1: cos^2, the widest; larger s: narrower)",
        lo=0.0,
    )
    components: int = key(64, "int", "", "regular components of each sea", lo=1)
    origin_depth: tuple[float, float] = key(
        (0.0, 0.0),
        "range",
        "m",
        "depth of the NED origin below the mean free surface: the vehicle feels the sea at "
        "depth origin_depth + z (the same mission at another depth)",
    )


#: TOML section name -> section class (``[scenario]``:
#: [`vcjax.config.scenario`][vcjax.config.scenario])
SECTIONS: dict[str, type] = {
    "simulation": Simulation,
    "current": Current,
    "waves": Waves,
    "initial": Initial,
    "model_error": ModelError,
    "sensor_noise": SensorNoise,
    "disturbance": Disturbance,
}


def check_value(name: str, v, meta) -> Any:
    """``v`` checked against a field's metadata (``ConfigError`` naming ``name``)."""
    t = meta["type"]
    bounds = {k: meta[k] for k in ("lo", "lo_open", "hi", "hi_open") if k in meta}
    if t == "float":
        return as_number(name, v, **bounds)
    if t == "int":
        return as_int(name, v, meta.get("lo", 0))
    if t == "bool":
        return as_bool(name, v)
    if t == "str":
        v = as_str(name, v)
        return as_choice(name, v, meta["choices"]) if meta.get("choices") else v
    if t == "range":
        return as_range(name, v, lo_min=meta.get("lo"), positive=meta.get("positive", False))
    if t == "seed":
        return as_seed(name, v)
    if t == "str_list":
        v = as_str_list(name, v)
        if meta.get("unique") and len(set(v)) != len(v):
            raise ConfigError(f"{name}: duplicate names in {list(v)}")
        return v
    if t == "range_list":
        if not isinstance(v, list | tuple):
            raise ConfigError(f"{name}: expected a list, got {v!r}")
        return tuple(as_range(name, r) for r in v)
    raise AssertionError(t)  # pragma: no cover


#: the smallest positive ``[waves] spreading``: ``s -> 0+`` tends to a uniform spread over the
#: whole +-90 deg half-plane (the widest), while ``s = 0`` is long-crested (one direction), so a
#: tiny positive ``s`` would silently mean the opposite of what 0 means
MIN_SPREADING = 1.0


def _current_applies(cur: Current, table: dict, name) -> None:
    """The Gauss-Markov keys are refused with a constant current (they would be ignored)."""
    if cur.model == "constant":
        for k in ("sigma", "tau", "max_speed"):
            if k in table:
                raise ConfigError(
                    f"{name(k)}: applies to model = 'gauss_markov' only; with the constant "
                    "current (model = 'constant', the default) it would be ignored"
                )


def _waves_apply(wav: Waves, table: dict, name) -> None:
    """``gamma`` is JONSWAP's; a positive ``spreading`` is at least
    [`MIN_SPREADING`][vcjax.config.schema.MIN_SPREADING]."""
    if wav.spectrum == "pm" and "gamma" in table:
        raise ConfigError(
            f"{name('gamma')}: the peak enhancement of the JONSWAP spectrum; spectrum = 'pm' "
            "(Pierson-Moskowitz) has none and would ignore it"
        )
    if 0.0 < wav.spreading < MIN_SPREADING:
        raise ConfigError(
            f"{name('spreading')}: 0 is long-crested (one direction) and s >= {MIN_SPREADING:g} "
            f"spreads as cos^2s (1 the widest); got {wav.spreading:g}, which would spread the "
            "components over the whole +-90 deg half-plane"
        )


def _model_error_applies(err: ModelError, table: dict, name) -> None:
    """An empty ``fields`` list is refused: it meant the default set in tune configs and no
    field at all in sweep configs; omitting the key means the vehicle's default set in both."""
    if err.fields == ():
        raise ConfigError(
            f"{name('fields')}: an empty list perturbs no parameter; omit the key for the "
            "vehicle's default set (or set relative = 0 for no model error)"
        )


#: section class -> check of the keys that depend on each other (a key that does not apply
#: to the values of the others is refused, never silently ignored)
CROSS_CHECKS = {Current: _current_applies, Waves: _waves_apply, ModelError: _model_error_applies}


def registered() -> dict[str, type]:
    """The sections added by [`register_section`][vcjax.config.schema.register_section], beyond the
    built-in ones: the section dataclasses of the one table of added sections
    ([`vcjax.environment.REGISTRY`][vcjax.environment.component.REGISTRY], which also holds the
    environment components)."""
    from vcjax.environment.component import REGISTRY

    return {n: d for n, d in REGISTRY.items() if isinstance(d, type)}


def register_section(name: str, cls: type, check=None, replace: bool = False) -> type:
    """Add a shared section ``[name]``: ``cls`` is a frozen dataclass whose fields are declared
    with [`key`][vcjax.config.schema.key] (type, default, unit, doc, bounds);
    ``check(obj, table, name_of)`` optionally refuses keys that do not apply to the others'
    values (``name_of(key)`` gives ``"[name] key"``). It joins the one table of added sections
    ([`vcjax.environment.REGISTRY`][vcjax.environment.component.REGISTRY], where
    [`vcjax.environment.register`][vcjax.environment.component.register] puts a component's); from
    then on ``vcjax sweep`` and ``vcjax tune`` configs accept the section, parse it with
    [`parse_section`][vcjax.config.schema.parse_section] (the one validator)
    and the configuration reference lists it. A taken name is refused unless ``replace``.
    Returns ``cls``."""
    from vcjax.environment.component import REGISTRY, add_section

    if not (isinstance(name, str) and name.isidentifier()):
        raise ValueError(f"register_section: expected a section name, got {name!r}")
    if not (dataclasses.is_dataclass(cls) and isinstance(cls, type)):
        raise TypeError(f"register_section: {name}: expected a dataclass, got {cls!r}")
    for f in dataclasses.fields(cls):
        if "type" not in f.metadata:
            raise TypeError(f"register_section: [{name}] {f.name}: declare it with key()")
        if f.default is dataclasses.MISSING:
            raise TypeError(f"register_section: [{name}] {f.name}: needs a default")
    if (name in SECTIONS or name in REGISTRY) and not replace:
        raise ValueError(f"register_section: [{name}] is taken (replace=True to replace it)")
    add_section(name, cls, replace=True)
    if check is not None:
        CROSS_CHECKS[cls] = check
    return cls


def parse_section(cls: type, table: dict | None, section: str, where: str = ""):
    """The section object of one TOML table (missing keys: defaults).

    Sections with an open key set (``[initial]``, ``[sensor_noise]``) take any key; the
    vehicle checks those names. Errors read ``"WHERE: [section] key: ..."``.
    """
    table = {} if table is None else table
    pre = f"{where}: " if where else ""
    if not isinstance(table, dict):
        raise ConfigError(f"{pre}[{section}] must be a table, got {table!r}")
    fields = {f.name: f for f in dataclasses.fields(cls)}
    if len(fields) == 1 and "open_keys" in next(iter(fields.values())).metadata:
        (f,) = fields.values()
        vals = tuple(
            (k, check_value(f"{pre}[{section}] {k}", v, f.metadata)) for k, v in table.items()
        )
        return cls(**{f.name: vals})
    kw = {}
    for k, v in table.items():
        if k not in fields:
            raise ConfigError(
                f"{pre}unknown key [{section}] {k!r}{closest(k, fields)}; "
                f"expected one of {list(fields)}"
            )
        kw[k] = check_value(f"{pre}[{section}] {k}", v, fields[k].metadata)
    obj = cls(**kw)
    if cls in CROSS_CHECKS:
        CROSS_CHECKS[cls](obj, table, lambda k: f"{pre}[{section}] {k}")
    return obj
