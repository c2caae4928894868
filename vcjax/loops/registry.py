"""The registry of loops: ``vehicle name -> Loop subclass``, and each loop's laws.

:func:`register` adds a vehicle (refusing a class that lacks a required method, naming them, and
a name already taken unless ``replace=True``); :func:`register_law` adds a law to a registered
vehicle (one line beside a new law's file). :func:`make_loop` builds a loop by name.
"""

from __future__ import annotations

import inspect

from vcjax import paths
from vcjax.loops.law import Law, missing_methods
from vcjax.loops.loop import Loop

__all__ = [
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


def register(cls: type[Loop], *, replace: bool = False) -> type[Loop]:
    """Register a :class:`Loop` subclass under ``cls.vehicle`` (usable as a decorator).

    Refused (``ValueError``): not a Loop subclass or no vehicle name; no controllers; required
    methods not defined (listed by name; ``default_gains``/``gain_specs`` may come from the
    laws); a vehicle name that another class already holds, unless ``replace=True`` (the
    message names the module that tried and the registered class).
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


def register_law(vehicle: str, controller: str, law: Law, *, replace: bool = False) -> Law:
    """Add ``law`` to the registered ``vehicle``'s loop as controller ``controller``.

    Refused (``ValueError``): an unknown vehicle, a law missing required methods (named), a
    controller name the vehicle already has unless ``replace=True``.
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
    cls.laws = {**cls.laws, controller: law}
    cls.controllers = tuple(dict.fromkeys((*cls.controllers, controller)))
    return law


def vehicles() -> tuple[str, ...]:
    """Registered vehicle names (sorted)."""
    return tuple(sorted(_REGISTRY))


def loop_class(vehicle: str) -> type[Loop]:
    """The :class:`Loop` subclass of ``vehicle``; ``ValueError`` listing the vehicles if none."""
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
    kind); ``options``: the loop's static fields (e.g. ``edd``, ``smooth``)."""
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
