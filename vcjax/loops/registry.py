"""The registry of loops: ``vehicle name -> Loop subclass``, and each loop's laws.

[`register`][vcjax.loops.registry.register] adds a vehicle (refusing a class that lacks a required
method, naming them, and
a name already taken unless ``replace=True``); [`register_law`][vcjax.loops.registry.register_law]
adds a law to a registered
vehicle (one line beside a new law's file). [`make_loop`][vcjax.loops.registry.make_loop] builds a
loop by name.
"""

from __future__ import annotations

import inspect

from vcjax import paths
from vcjax.loops.law import Law, missing_methods
from vcjax.loops.loop import Loop

__all__ = [
    "check_step",
    "register",
    "register_law",
    "vehicles",
    "loop_class",
    "controllers",
    "default_path",
    "make_loop",
]

_REGISTRY: dict[str, type[Loop]] = {}


def _caller() -> str:
    """The module that called into the registry (for error messages)."""
    for frame in inspect.stack()[2:]:
        name = frame.frame.f_globals.get("__name__", "")
        if name != __name__ and not name.startswith("vcjax.loops"):
            return f"{name} ({frame.filename})"
    return "vcjax.loops"


def _origin(cls) -> str:
    mod = inspect.getmodule(cls)
    where = getattr(mod, "__file__", None)
    return f"{cls.__module__}.{cls.__qualname__}" + (f" ({where})" if where else "")


def _same(a: type, b: type) -> bool:
    """The same class, or the same class of a module imported again."""
    return a is b or (a.__module__, a.__qualname__) == (b.__module__, b.__qualname__)


def register(cls: type[Loop], *, replace: bool = False, check: bool = True) -> type[Loop]:
    """Register a [`Loop`][vcjax.loops.loop.Loop] subclass under ``cls.vehicle`` (usable as a
    decorator).

    Refused (``ValueError``): not a Loop subclass or no vehicle name; no controllers; required
    methods not defined (listed by name; ``default_gains``/``gain_specs`` may come from the
    laws); a vehicle name that another class already holds, unless ``replace=True`` (the
    message names the module that tried and the registered class); with ``check`` (the
    default), a controller whose one step does not trace
    ([`check_step`][vcjax.loops.registry.check_step]: signatures,
    gains, output shapes), named with what is wrong. vcjax's own loops register with
    ``check=False`` (at import, before JAX's devices are set up; the conformance suite traces
    them).
    """
    if not (isinstance(cls, type) and issubclass(cls, Loop)) or not cls.vehicle:
        raise ValueError(f"register: expected a Loop subclass with a vehicle name, got {cls!r}")
    if not cls.controllers:
        raise ValueError(f"register: {cls.__name__} lists no controllers")
    missing = missing_methods(cls)
    if not cls.laws:
        missing += [
            n for n in ("default_gains", "gain_specs") if getattr(cls, n) is getattr(Loop, n)
        ]
    if missing:
        raise ValueError(
            f"register: {cls.__name__} (vehicle {cls.vehicle!r}) does not define the required "
            f"methods {sorted(missing)}"
        )
    for name, law in cls.laws.items():
        _check_law(cls.vehicle, name, law)
    old = _REGISTRY.get(cls.vehicle)
    if old is not None and not replace and not _same(old, cls):
        raise ValueError(
            f"register: vehicle {cls.vehicle!r} is already registered by {_origin(old)}; "
            f"{_caller()} tried to register {cls.__qualname__} under the same name "
            "(choose another name, or pass replace=True)"
        )
    if check:
        taus = {name: check_step(cls, name, "register", compare=False) for name in cls.controllers}
        _same_force(cls, {k: v for k, v in taus.items() if v is not None})
    _REGISTRY[cls.vehicle] = cls
    return cls


def _check_law(vehicle: str, name: str, law) -> None:
    if not isinstance(law, Law):
        raise ValueError(f"register: {vehicle} law {name!r}: expected a Law, got {law!r}")
    missing = missing_methods(type(law))
    if missing:
        raise ValueError(
            f"register: {vehicle} law {name!r} ({type(law).__name__}) does not define the "
            f"required methods {missing}"
        )


def register_law(
    vehicle: str, controller: str, law: Law, *, replace: bool = False, check: bool = True
) -> Law:
    """Add ``law`` to the registered ``vehicle``'s loop as controller ``controller``.

    Refused (``ValueError``): an unknown vehicle, a law missing required methods (named), a
    controller name the vehicle already has unless ``replace=True``; with ``check`` (the
    default), a law whose one step does not trace or gives outputs of the wrong shape
    ([`check_step`][vcjax.loops.registry.check_step]; the law is then not registered).
    """
    cls = loop_class(vehicle)
    if not isinstance(controller, str) or not controller:
        raise ValueError(f"register_law: controller: expected a name, got {controller!r}")
    _check_law(vehicle, controller, law)
    if controller in cls.controllers and not replace:
        raise ValueError(
            f"register_law: vehicle {vehicle!r} already has a controller {controller!r}; "
            f"{_caller()} tried to register {type(law).__name__} under it (pass replace=True)"
        )
    if not cls.laws and cls.controllers:
        raise ValueError(f"register_law: the {vehicle} loop implements its controllers itself")
    old = cls.laws, cls.controllers
    cls.laws = {**cls.laws, controller: law}
    cls.controllers = tuple(dict.fromkeys((*cls.controllers, controller)))
    if check:
        try:
            check_step(cls, controller, "register_law")
        except BaseException:
            cls.laws, cls.controllers = old  # refused: not registered
            raise
    return law


def _shapes(tree) -> str:
    import jax

    return str(jax.tree_util.tree_map(lambda a: tuple(a.shape), tree))


def _same_shapes(a, b) -> bool:
    import jax

    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    return ta == tb and all(x.shape == y.shape for x, y in zip(la, lb, strict=True))


class _Wrong(ValueError):
    """What [`check_step`][vcjax.loops.registry.check_step] found wrong before tracing (said as it
    is)."""


class _Spy:
    """A law that records what its ``step`` returned (for
    [`check_step`][vcjax.loops.registry.check_step])."""

    def __init__(self, law, seen: list):
        self._law, self._seen = law, seen

    def __getattr__(self, name):
        return getattr(self._law, name)

    def step(self, *args):
        out = self._law.step(*args)
        self._seen.append(out)
        return out


def _trace(cls: type[Loop], controller: str):
    """``(x0, z0, u, x_dot, step_out)``: shapes of one control step and one plant evaluation of
    ``cls``'s loop with ``controller`` at its default gains and scenario (``jax.eval_shape``:
    nothing is computed; ``step_out`` is the law's ``step`` output, None for a loop without
    laws)."""
    import jax
    import jax.numpy as jnp

    from vcjax.loops.scenario import make_scenario

    seen: list = []
    law = cls.laws.get(controller)
    laws = cls.laws
    if law is not None:
        cls.laws = {**laws, controller: _Spy(law, seen)}
    try:
        loop = cls(controller=controller, path=cls.default_path()[0])
        gains = loop.default_gains()
        if not (isinstance(gains, tuple) and hasattr(type(gains), "_fields")):
            raise _Wrong(
                f"default_gains returned a {type(gains).__name__}; expected a NamedTuple of "
                "arrays (gains are a pytree with named fields)"
            )
        sc = make_scenario(loop)

        def one(gains, sc):
            x0, z0 = loop.initial_state(sc)
            ctrl = loop.ctrl_params(gains, sc)
            t = jnp.zeros((), sc.u_d.dtype)
            u, z_dot, _ = loop.control(t, x0, z0, ctrl)
            args = loop.plant_args(sc, sc.current, jnp.zeros_like(sc.current))
            return x0, z0, u, z_dot, loop.plant(t, x0, u, args)

        x0, z0, u, z_dot, x_dot = jax.eval_shape(one, gains, sc)
    finally:
        cls.laws = laws
    return x0, z0, u, z_dot, x_dot, (jax.eval_shape(lambda: seen[0]) if seen else None)


def _same_force(cls: type[Loop], taus: dict) -> None:
    """Refuse laws of one vehicle whose forces differ in shape (the odd ones out, against the
    shape most of them give)."""
    shapes = {k: _shapes(v) for k, v in taus.items()}
    if len(set(shapes.values())) <= 1:
        return
    common = max(set(shapes.values()), key=list(shapes.values()).count)
    odd = sorted(k for k, v in shapes.items() if v != common)
    raise ValueError(
        f"register: {cls.vehicle}: the force tau of law(s) {odd} has shape "
        f"{shapes[odd[0]]}; the vehicle's other laws give {common}"
    )


def _check_signature(what: str, method, names: tuple[str, ...], hint: str = "") -> None:
    """Refuse a law method that cannot be called with the arguments ``names`` (the one
    signature the loops call it with)."""
    try:
        inspect.signature(method).bind(*names)
    except TypeError:
        raise ValueError(
            f"{what}: {method.__name__}{inspect.signature(method)} must take "
            f"({', '.join(names)}){hint}"
        ) from None
    except ValueError:  # no signature to inspect (a builtin): the trace will tell
        pass


def check_step(cls: type[Loop], controller: str, who: str = "check_step", compare: bool = True):
    """Trace one step of ``cls``'s loop with ``controller`` (``jax.eval_shape``, default
    gains and scenario) before any work, and refuse (``ValueError`` naming the vehicle, the law
    and what is wrong) a law whose methods do not take the arguments the loop passes (a
    ``step`` without ``z``, a ``params`` not ``(loop, gains, sc, design)``), whose gains are
    not a NamedTuple (a dict), whose ``z_dot`` does
    not match its state ``z``, whose force ``tau`` differs in shape from the vehicle's other
    laws' (a (2,) force for a 3-DOF plant, which indexing would silently clamp), or whose
    plant derivative does not match the state. Returns the shapes of the law's force ``tau``
    (None for a loop without laws); ``compare=False`` leaves out the comparison with the other
    laws ([`register`][vcjax.loops.registry.register] compares them all at once)."""
    law = cls.laws.get(controller)
    what = f"{who}: {cls.vehicle} " + (
        f"law {controller!r} ({type(law).__name__})" if law is not None else repr(controller)
    )
    if law is not None:
        _check_signature(what, law.step, ("loop", "params", "t", "meas", "z"))
        _check_signature(
            what,
            law.params,
            ("loop", "gains", "sc", "design"),
            " (design: what the vehicle's loop derives from sc.design, loop.law_design(sc); "
            "an INFANTE law's former model and k_rudder are design.model and design.k_rudder)",
        )
    try:
        x0, z0, u, z_dot, x_dot, out = _trace(cls, controller)
    except _Wrong as err:
        raise ValueError(f"{what}: {err}") from None
    except Exception as err:  # the user's code: whatever it raised, in one line
        msg = str(err).strip().splitlines()[0] if str(err).strip() else ""
        raise ValueError(
            f"{what}: one step does not trace with the default gains and scenario: "
            f"{type(err).__name__}: {msg}"
        ) from None
    if not _same_shapes(z_dot, z0):
        raise ValueError(
            f"{what}: z_dot {_shapes(z_dot)} does not match the law's state z {_shapes(z0)}"
        )
    if not _same_shapes(x_dot, x0):
        raise ValueError(
            f"{what}: the plant's x_dot {_shapes(x_dot)} does not match the state "
            f"{_shapes(x0)} with this law's command {_shapes(u)}"
        )
    if out is None:
        return None
    if not (isinstance(out, tuple) and len(out) == 3):
        raise ValueError(f"{what}: step must return (tau, z_dot, aux), got {_shapes(out)}")
    others = [c for c in cls.laws if c != controller]
    if compare and others:
        ref = _trace(cls, others[0])[-1]
        if ref is not None and not _same_shapes(out[0], ref[0]):
            raise ValueError(
                f"{what}: step returns a force tau of shape {_shapes(out[0])}; the "
                f"{cls.vehicle} loop's law {others[0]!r} returns {_shapes(ref[0])}"
            )
    return out[0]


def vehicles() -> tuple[str, ...]:
    """Registered vehicle names (sorted)."""
    return tuple(sorted(_REGISTRY))


def loop_class(vehicle: str) -> type[Loop]:
    """The [`Loop`][vcjax.loops.loop.Loop] subclass of ``vehicle``; ``ValueError`` listing the
    vehicles if none."""
    if vehicle not in _REGISTRY:
        raise ValueError(f"vehicle: expected one of {list(vehicles())}, got {vehicle!r}")
    return _REGISTRY[vehicle]


def controllers(vehicle: str) -> tuple[str, ...]:
    """The controllers ``vehicle``'s loop supports."""
    return loop_class(vehicle).controllers


def default_path(vehicle: str):
    """``(Path, coeffs)``: the vehicle's default path (e.g. Simulation 1's line for INFANTE)."""
    return loop_class(vehicle).default_path()


def make_loop(vehicle: str, controller: str, path: paths.Path | None = None, **options) -> Loop:
    """The loop of ``vehicle`` x ``controller`` on ``path`` (default: the vehicle's default path
    kind); ``options``: the loop's static fields (e.g. ``smooth``, ``integral``)."""
    cls = loop_class(vehicle)
    if controller not in cls.controllers:
        raise ValueError(
            f"controller: vehicle {vehicle!r} supports {list(cls.controllers)}, got {controller!r}"
        )
    path = cls.default_path()[0] if path is None else path
    try:
        return cls(controller=controller, path=path, **options)
    except TypeError as err:
        raise ValueError(f"{vehicle} loop options: {err}") from None
