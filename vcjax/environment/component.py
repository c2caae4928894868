"""The seam: [`Component`][vcjax.environment.component.Component] (one thing the world does to a
vehicle), its registry, and
[`Environment`][vcjax.environment.component.Environment] (the components of a run with their
sampled, traced parameters).

A component is *static* (a frozen, hashable dataclass: what it is and its static options) and
declares

* ``section``: the name of its TOML section, and ``schema``: the section's keys
  ([`Key`][vcjax.environment.component.Key]: default, bounds, unit, meaning), checked eagerly by
  [`Component.check`][vcjax.environment.component.Component.check];
* ``kind``: what a loop must be able to feel to take it (one of ``KINDS``; a loop declares
  what it feels in ``vcjax.loops.Loop.feels``);
* ``sample(key, section) -> params``: the traced parameters of one run, drawn from the checked
  section (a key's value is a number, or a ``[lo, hi]`` range sampled uniformly); pure
  ``jax`` so that it runs under ``vmap`` and differentiates through continuous values;
* optionally a process: ``init(params) -> state`` and ``advance(params, state, k, t, dt) ->
  (state, held)``, once per integration step ``k`` (``held`` is what the step's contribution
  reads, e.g. a noise sample, or a current's value and slope on ``[t_k, t_k + dt]``);
* its contribution: ``water(params, held, t, p_ned, current) -> (v (3,), a (3,))`` the water's
  velocity [m/s] and material acceleration [m/s^2] in NED at the point ``p_ned`` (3,) [m] and
  time ``t`` [s] (``current``: the uniform current the component's water is advected by),
  ``force(params) -> (n_nu,)`` a constant generalised body force [N, N m], or
  ``noise(params, held) -> (n,)`` what is added to the controller's measurement.

What a kind means to the simulation ([`vcjax.loops.simulate`][vcjax.loops.disturbances.simulate]):

========================  ===================================================================
``current``               uniform, constant water velocity (``water`` at ``t = 0``)
``varying_current``       uniform water velocity that varies in time (``water`` every stage)
``waves``                 water that varies in space (evaluated at the vehicle, every stage)
``force``                 a constant generalised force added to the plant's disturbance
``noise``                 sensor noise added to what the controller measures
========================  ===================================================================

A new disturbance is one class and one line, ``register(MyComponent())``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, ClassVar, NamedTuple

import jax
import jax.numpy as jnp

from vcjax._checks import ConfigError, as_float_array, check_value, float_dtype, unknown_key

__all__ = [
    "KINDS",
    "Component",
    "Environment",
    "Key",
    "WaterMotion",
    "check_section",
    "components",
    "lookup",
    "draw",
    "draw_unit",
    "freeze",
    "check_for_loop",
    "written",
    "register",
    "unregister",
    "REGISTRY",
    "add_section",
    "sample",
    "water_motion",
]

#: what a component asks of a loop (see the module docstring)
KINDS = ("current", "varying_current", "waves", "force", "noise")

#: how a refusal names each kind ("the X loop cannot take ...")
KIND_WORDS = {
    "current": "a current",
    "varying_current": "a time-varying current",
    "waves": "waves",
    "force": "a disturbance force",
    "noise": "sensor noise",
}


class WaterMotion(NamedTuple):
    """The water at a vehicle: the one door through which every plant takes it.

    A plant's arguments hold one ``water: WaterMotion``; what the plant does with it is the
    plant's model (a horizontal-plane craft uses the first two components and cannot feel the
    vertical one; a 6-DOF body takes all three), written in its module. The loops build it from
    the environment ([`Loop.plant_args`][vcjax.loops.loop.Loop.plant_args],
    [`Loop.with_current`][vcjax.loops.loop.Loop.with_current],
    [`Water.at`][vcjax.loops.types.Water.at] in a sea).

    Attributes:
        velocity: (3,) the water's velocity in NED at the vehicle [m/s] (uniform current plus
            what varies in space, e.g. a wave's orbital motion).
        acceleration: (3,) its material acceleration ``Dv/Dt`` in NED [m/s^2] (zeros for a
            constant uniform current), or ``None``: zero, and the plant leaves its terms out
            (the same numbers as zeros).
    """

    velocity: Any
    acceleration: Any


def water_motion(velocity=None, acceleration=None, dtype=None) -> WaterMotion:
    """Validated [`WaterMotion`][vcjax.environment.component.WaterMotion]: ``velocity`` and
    ``acceleration`` (3,) NED (default zeros: still water), as float arrays of ``dtype``
    (default: the velocity's own float dtype, or JAX's default float). ``ValueError`` naming
    the field for a wrong shape or a NaN/inf entry."""
    if velocity is None:
        v = jnp.zeros(3, float_dtype(dtype))
    else:
        v = as_float_array("velocity", velocity, (3,), dtype)
    dtype = v.dtype
    a = (
        jnp.zeros(3, dtype)
        if acceleration is None
        else as_float_array("acceleration", acceleration, (3,), dtype)
    )
    return WaterMotion(v, a)


class Key(NamedTuple):
    """One key of a component's section (its declaration: the one place its default, bounds,
    unit and meaning are written; [`vcjax.config`][vcjax.config] reads the built-in sections'
    keys from here).

    Attributes:
        default: the value when the key is absent (a number, a string, or a ``(lo, hi)``
            range); ``None``: required.
        doc: meaning, one line.
        lo, hi: bounds every value (and both ends of a range) must respect.
        choices: the allowed strings of a string key (static options), else empty.
        strict_lo: ``lo`` itself is excluded (``> lo`` instead of ``>= lo``).
        unit: the unit, for the configuration reference (e.g. ``"m/s"``).
        kind: ``"sampled"`` (a number, or a ``[lo, hi]`` range drawn per run: the default),
            ``"float"`` (one number, a static option), ``"int"`` or ``"str"`` (with
            ``choices``).
        aliases: older spellings still accepted, as ``"[section] key"``
            ([`vcjax.config.aliases`][vcjax.config.aliases]).
    """

    default: Any
    doc: str
    lo: float = -math.inf
    hi: float = math.inf
    choices: tuple = ()
    strict_lo: bool = False
    unit: str = ""
    kind: str = "sampled"
    aliases: tuple = ()

    def meta(self) -> dict:
        """The key as the metadata `check_value` reads."""
        kind = "str" if self.choices else self.kind
        m = {"type": kind, "unit": self.unit, "doc": self.doc, "aliases": self.aliases}
        if self.choices:
            m["choices"] = tuple(self.choices)
        if math.isfinite(self.lo):
            m["lo"], m["lo_open"] = self.lo, self.strict_lo
        if math.isfinite(self.hi):
            m["hi"] = self.hi
        return m


def check_section(section: str, schema: Mapping[str, Key], raw: Mapping | None) -> dict:
    """``raw`` (a TOML table) checked against ``schema`` by the one validator,
    `check_value`: unknown keys (with the closest valid one), types
    and bounds; absent keys take their defaults. Sampled keys come back as floats (a number) or
    ``(lo, hi)`` tuples (a range). ``ValueError`` (a ``ConfigError``) ``[section] key: message``."""
    raw = dict(raw or {})
    unknown = sorted(set(raw) - set(schema))
    if unknown:
        raise ConfigError(unknown_key(section, unknown[0], schema))
    out = {}
    for name, spec in schema.items():
        x = raw.get(name, spec.default)
        if x is None:
            form = " (a number or [lo, hi])" if spec.kind == "sampled" else ""
            raise ConfigError(f"[{section}] {name}: required{form}")
        if name not in raw and not isinstance(x, str):  # a default is the declaration's own
            out[name] = tuple(x) if isinstance(x, list) else x
            continue
        out[name] = check_value(f"[{section}] {name}", x, spec.meta())
    return out


def written(raw, schema: Mapping[str, Key]) -> dict:
    """The keys a table wrote: a mapping as it is; a frozen table (a tuple of ``(key, value)``
    pairs, checked, its defaults filled in: [`freeze`][vcjax.environment.component.freeze]) only
    the keys whose value is not the default. What a component's refusals of keys that do not
    apply look at: a key the user wrote is refused, a default filled in is not."""
    if isinstance(raw, tuple):
        return {k: v for k, v in raw if k not in schema or v != schema[k].default}
    return dict(raw or {})


def draw_unit(u, value, dtype=None):
    """() a traced value of one section key from a uniform number ``u`` in [0, 1): the number
    itself, or ``lo + (hi - lo) u`` for a ``(lo, hi)`` range (reparameterised: differentiable
    in both ends; ``lo == hi`` gives ``lo`` exactly)."""
    dtype = jnp.asarray(u).dtype if dtype is None else dtype
    if isinstance(value, tuple):
        lo, hi = (jnp.asarray(v, dtype) for v in value)
        return lo + (hi - lo) * u
    return jnp.asarray(value, dtype)


def draw(key, value, dtype=None):
    """() a traced value of one section key: the number itself, or a uniform draw from a
    ``(lo, hi)`` range ([`draw_unit`][vcjax.environment.component.draw_unit] of
    ``uniform(key)``)."""
    dtype = jnp.asarray(0.0).dtype if dtype is None else dtype
    if isinstance(value, tuple):
        return draw_unit(jax.random.uniform(key, (), dtype), value, dtype)
    return jnp.asarray(value, dtype)


@dataclasses.dataclass(frozen=True)
class Component:
    """One thing the world does to a vehicle (static, hashable; see the module docstring).

    Subclasses set ``section``, ``kind``, ``schema`` and define
    [`sample`][vcjax.environment.component.sample]
    and the contribution of their kind (``water``, [`force`][vcjax.environment.force] or
    [`noise`][vcjax.environment.noise]); a
    component with memory sets ``process`` and defines ``init`` and ``advance``.
    """

    #: name of the TOML section (and of the component in the registry)
    section: ClassVar[str] = ""
    #: what a loop must feel to take it (one of ``KINDS``)
    kind: ClassVar[str] = ""
    #: the section's keys
    schema: ClassVar[Mapping[str, Key]] = {}
    #: True when the component has a per-step process (``init``, ``advance``)
    process: ClassVar[bool] = False

    def bind(self, loop) -> Component:
        """This component for ``loop`` (e.g. sensor noise over its channels); default: self."""
        return self

    def check(self, raw: Mapping | None) -> dict:
        """The section checked against ``schema`` (eager; defaults filled in)."""
        return check_section(self.section, self.schema, raw)

    def resolve(self, section: Mapping) -> Component:
        """The component that simulates the checked ``section``: default ``self``; a section
        whose static options choose another model returns that model's component (e.g.
        ``[current] model = "gauss_markov"``)."""
        return self

    def sample(self, key, section: Mapping):
        """Traced parameters of one run from the checked ``section`` and a PRNG ``key``."""
        raise NotImplementedError(f"{type(self).__name__}.sample")

    def init(self, params):
        """Process state at ``t = 0`` (components with ``process``)."""
        return None

    def advance(self, params, state, k, t, dt):
        """``(state_next, held)`` over step ``k`` on ``[t, t + dt]``."""
        return state, None

    def water(self, params, held, t, p_ned, current):
        """``(v (3,), a (3,))`` the water's velocity [m/s] and material acceleration [m/s^2]
        in NED at ``p_ned`` (3,) [m], time ``t`` [s]; ``current`` (3,) [m/s] advects it."""
        raise NotImplementedError(f"{type(self).__name__}.water")

    def force(self, params):
        """(n_nu,) constant generalised body force [N, N m]."""
        raise NotImplementedError(f"{type(self).__name__}.force")

    def noise(self, params, held):
        """(n,) what is added to the controller's measurement (SI units)."""
        raise NotImplementedError(f"{type(self).__name__}.noise")


#: THE table of sections beyond the built-in ones of [`vcjax.config.schema`][vcjax.config.schema],
#: by TOML section name: a [`Component`][vcjax.environment.component.Component] (``register``) or a
#: section dataclass ([`vcjax.config.register_section`][vcjax.config.schema.register_section]);
#: sweep and tune configs accept, check and sample from what it holds
REGISTRY: dict[str, Any] = {}


def add_section(name: str, decl, replace: bool = False) -> None:
    """Put ``decl`` (a component, or a section dataclass) into ``REGISTRY`` as ``[name]``; a
    name taken by another declaration is refused unless ``replace``."""
    old = REGISTRY.get(name)
    if old is not None and not replace and old != decl:
        raise ValueError(f"section [{name}] is taken (replace=True to replace it)")
    REGISTRY[name] = decl


def unregister(name: str) -> None:
    """Forget the section ``[name]`` (a component or a registered section), if known."""
    REGISTRY.pop(name, None)


def register(comp: Component, *, replace: bool = False) -> Component:
    """Make ``comp`` known by its section name (one line per new disturbance): its section
    joins ``REGISTRY``, the one table of added sections."""
    if not isinstance(comp, Component):
        raise ValueError(f"register: expected a Component, got {type(comp).__name__}")
    if not comp.section or comp.kind not in KINDS:
        raise ValueError(
            f"register: {type(comp).__name__} needs a section and a kind in {list(KINDS)}"
        )
    if type(comp).sample is Component.sample:
        raise ValueError(f"register: {type(comp).__name__} defines no sample()")
    try:
        add_section(comp.section, comp, replace)
    except ValueError as err:
        raise ValueError(f"register: {err}") from None
    return comp


def _components() -> dict[str, Component]:
    return {k: v for k, v in REGISTRY.items() if isinstance(v, Component)}


def lookup(section: str) -> Component:
    """The registered component of ``section`` (``ValueError`` listing the known ones)."""
    comps = _components()
    if section not in comps:
        raise ValueError(f"[{section}]: no such component; known: {sorted(comps)}")
    return comps[section]


def components() -> tuple[str, ...]:
    """The registered component section names."""
    return tuple(sorted(_components()))


@jax.tree_util.register_pytree_node_class
class Environment:
    """The components of a run (static: part of the tree's structure) with their traced
    parameters (the leaves), so a batch of environments is one ``vmap``-able pytree and
    gradients flow into every continuous parameter.

    Attributes:
        components: tuple of [`Component`][vcjax.environment.component.Component].
        params: tuple of their parameters (one pytree each, same order).
    """

    def __init__(self, components=(), params=()):
        self.components = tuple(components)
        self.params = tuple(params)
        if len(self.components) != len(self.params):
            raise ValueError("Environment: one params entry per component")

    def tree_flatten(self):
        return (self.params,), self.components

    @classmethod
    def tree_unflatten(cls, components, children):
        return cls(components, children[0])

    def __iter__(self):
        return iter(zip(self.components, self.params, strict=True))

    def __len__(self):
        return len(self.components)

    def __repr__(self):
        return f"Environment({[c.section for c in self.components]})"

    def kinds(self) -> tuple[str, ...]:
        return tuple(c.kind for c in self.components)

    def __add__(self, other: Environment) -> Environment:
        return Environment(self.components + other.components, self.params + other.params)


def freeze(section: str, raw: Mapping | None) -> tuple:
    """``(section, ((key, value), ...))``: the registered component's checked table in a
    hashable form (for static configs); ``ValueError`` ``[section] key: message``."""
    if raw is not None and not isinstance(raw, Mapping | tuple):
        raise ValueError(f"[{section}]: expected a table, got {raw!r}")
    if not isinstance(raw, tuple):  # a tuple: already frozen, ((key, value), ...)
        raw = dict(raw or {})
    return section, tuple(sorted(lookup(section).check(raw).items()))


def check_for_loop(loop, sections) -> None:
    """Each ``(section, table)`` of ``sections`` checked by its registered component as it is for
    ``loop`` ([`Component.bind`][vcjax.environment.component.Component.bind]: e.g. the force's
    one key per generalised coordinate of the plant), before any work; ``ValueError``
    ``[section] key: message (vehicle 'name')``."""
    for name, table in sections:
        try:
            lookup(name).bind(loop).check(table)
        except ValueError as err:
            raise ValueError(f"{err} (vehicle {loop.vehicle!r})") from None


def sample(key, sections: Mapping[str, Mapping], loop=None, comps: Mapping | None = None):
    """[`Environment`][vcjax.environment.component.Environment] of the named ``sections``
    (``{section: raw table}``), each
    checked and sampled from its own key ``fold_in(key, i)`` (``i`` its place in ``sections``).

    ``loop``: the loop the environment is for
    ([`Component.bind`][vcjax.environment.component.Component.bind]); ``comps`` names
    components not in the registry (default: the registry's). Checking is eager
    (plain Python); the draws are traced, so ``vmap`` this over keys for a batch (the sections
    are static: build the checked dict once with
    [`Component.check`][vcjax.environment.component.Component.check] and close over it).
    """
    found, params = [], []
    for i, (name, raw) in enumerate(sections.items()):
        c = (comps or {}).get(name) or lookup(name)
        if loop is not None:  # checked against what it is for this loop (e.g. 6 forces of a 6-DOF)
            c = c.bind(loop)
        checked = c.check(raw)
        c = c.resolve(checked)
        c = c if loop is None else c.bind(loop)
        found.append(c)
        params.append(c.sample(jax.random.fold_in(key, i), checked))
    return Environment(found, params)
