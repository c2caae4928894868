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

from vcjax._checks import check_value, key, unknown_key
from vcjax.config.frozen import FrozenSection
from vcjax.config.values import (
    ConfigError,
)
from vcjax.environment.flow import ConstantCurrent
from vcjax.environment.sea import MIN_SPREADING as _MIN_SPREADING
from vcjax.environment.sea import Waves as WavesComponent

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


def _held(v, meta):
    """A component's checked value as its config section holds it (a sampled number ``x`` as
    the range ``(x, x)``)."""
    if meta["type"] == "range" and v is not None and not isinstance(v, tuple):
        return (float(v), float(v))
    return v


def component_section(comp, name: str, doc: str) -> type:
    """The frozen section dataclass of an environment component's section, built from the
    component's own declaration (``comp.schema``: default, bounds, unit, meaning, older
    spellings), so that the section is declared once. A sampled key is held as ``(lo, hi)`` (a
    number ``x`` as ``(x, x)``). [`parse_section`][vcjax.config.schema.parse_section] checks such
    a section with the component's ``check`` (the one validator, and the component's own
    refusals of keys that do not apply)."""
    fields = []
    for k, spec in comp.schema.items():
        meta = spec.meta()
        if meta["type"] == "sampled":
            meta["type"] = "range"
        default = _held(spec.default, meta)
        typ = {"str": str, "int": int, "float": float}.get(meta["type"], tuple)
        fields.append((k, typ, dataclasses.field(default=default, metadata=meta)))
    cls = dataclasses.make_dataclass(name, fields, frozen=True, namespace={"__doc__": doc})
    cls.__module__ = __name__
    cls.component = comp
    return cls


#: ``[current]``: the ocean current of every scenario, declared by the
#: [`ConstantCurrent`][vcjax.environment.flow.ConstantCurrent] component
#: (`CURRENT_SCHEMA`)
Current = component_section(
    ConstantCurrent(),
    "Current",
    """``[current]``: the ocean current of every scenario (NED; the direction is the one the
    water flows towards, clockwise from north).

    ``model = "gauss_markov"`` lets the speed wander around the sampled one (``sigma``, ``tau``,
    clipped to ``[0, max_speed]``); these three keys are refused with the constant model (they
    would be ignored). In tune configs ``[scenarios] current_max = m`` is the older spelling of
    ``speed = [0, m]``, ``direction_deg = [0, 360]`` (the tune's current without ``speed`` and
    ``direction_deg``); giving either key uses ``[current]``, the other key at its default.
    The keys are declared once, by the component
    (`CURRENT_SCHEMA`).""",
)


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


#: ``[waves]``: a random sea in every scenario, declared by the
#: [`Waves`][vcjax.environment.sea.Waves] component
Waves = component_section(
    WavesComponent(),
    "Waves",
    """``[waves]``: a random sea in every scenario (linear Airy waves in deep water,
    [`vcjax.environment.waves`][vcjax.environment.waves]; NED, depth positive down). Each scenario
    draws its ``hs``, ``tp``, ``direction_deg`` and ``origin_depth`` from the ranges and its sea
    (frequencies, phases, directions) from its own key, so a scenario's sea is the same whatever
    the chunk size or device count. ``hs`` and ``tp`` are required; ``hs = 0`` is a calm sea
    (the run is then exactly the run without waves). The integration step must resolve the
    shortest component (``tp / 4``) with 10 steps: ``tp >= 40 dt``. Loops whose plant cannot
    feel a sea refuse the section. The keys are declared once, by the component
    ([`vcjax.environment.sea.Waves`][vcjax.environment.sea.Waves]).""",
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


#: the smallest positive ``[waves] spreading`` (declared with the waves component)
MIN_SPREADING = _MIN_SPREADING


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
CROSS_CHECKS = {ModelError: _model_error_applies}


def registered() -> dict[str, type]:
    """The sections added by [`register_section`][vcjax.config.schema.register_section], beyond the
    built-in ones: the section dataclasses of the one table of added sections
    (`vcjax.environment.REGISTRY`, which also holds the
    environment components)."""
    from vcjax.environment.component import REGISTRY

    return {n: d for n, d in REGISTRY.items() if isinstance(d, type)}


def register_section(name: str, cls: type, check=None, replace: bool = False) -> type:
    """Add a shared section ``[name]``: ``cls`` is a frozen dataclass whose fields are declared
    with `key` (type, default, unit, doc, bounds);
    ``check(obj, table, name_of)`` optionally refuses keys that do not apply to the others'
    values (``name_of(key)`` gives ``"[name] key"``). It joins the one table of added sections
    (`vcjax.environment.REGISTRY`, where
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
    comp = getattr(cls, "component", None)
    if comp is not None:  # an environment component's section: its own check
        try:
            checked = comp.check(table)
        except ConfigError as err:
            raise ConfigError(f"{pre}{err}") from None
        return cls(**{k: _held(checked[k], fields[k].metadata) for k in fields})
    kw = {}
    for k, v in table.items():
        if k not in fields:
            raise ConfigError(f"{pre}{unknown_key(section, k, fields)}")
        kw[k] = check_value(f"{pre}[{section}] {k}", v, fields[k].metadata)
    obj = cls(**kw)
    if cls in CROSS_CHECKS:
        CROSS_CHECKS[cls](obj, table, lambda k: f"{pre}[{section}] {k}")
    return obj
