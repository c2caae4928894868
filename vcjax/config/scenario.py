"""The ``[scenario]`` section shared by ``vcjax sweep`` and ``vcjax tune`` configs::

    [scenario]
    module = "my_loops.py"       # optional: a Python file that registers your own loops
                                 # (vcjax.loops.register), imported first
    vehicle = "infante"          # a registered vehicle (vcjax.loops.vehicles())
    controller = "vcm_integral"  # one of that vehicle's controllers (errors list them)
    params = "model.json"        # optional: parameter overrides of plant AND design model
    plant_params = "plant.json"  # optional: overrides of the plant only (after params)
    # integral = true            # optional static options of the loop class: any of its
                                 # dataclass fields but controller, path and smooth
                                 # (e.g. ODIN: integral, polish; the errors list them)
    [scenario.path]
    kind = "circle"              # "line" | "circle" | "helix" | "waypoints" | "lawnmower"
    center = [0.0, 0.0]          # kind-specific keys (vcjax.paths constructors):
    radius = 40.0                #   line: origin, direction; circle: center, radius, clockwise,
                                 #   phase; helix: center, a, b, T, climb, phase;
                                 #   waypoints: points, extend; lawnmower: start, leg,
                                 #   radius, n_legs, depth, descent

Without ``[scenario]`` a config means ``DEFAULT_SCENARIO`` (Simulation 1:
INFANTE-class on the line ``[10, w]``).
Parameter files (paths relative to the config file) are JSON: a flat ``{name: value}`` map, or a
``vcjax fit`` output whose ``"estimates"`` map is used; names are the vehicle's parameter names
(``loop.param_names()``), unknown ones are rejected with the valid ones listed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import importlib.util
import signal
import sys
import threading
from pathlib import Path
from typing import Any

from vcjax import loops, paths
from vcjax._checks import unknown_key
from vcjax.config.schema import DEFAULT_SCENARIO, key
from vcjax.config.values import (
    ConfigError,
    as_bool,
    as_choice,
    as_int,
    as_number,
    as_str,
    resolve_file,
)

__all__ = [
    "PATH_KINDS",
    "PathSpec",
    "ScenarioChoice",
    "parse_scenario",
    "SCENARIO_KEYS",
    "loop_options",
]

#: kind -> (constructor, its keyword arguments)
PATH_KINDS = {
    "line": (paths.line, ("origin", "direction")),
    "circle": (paths.circle, ("center", "radius", "clockwise", "phase")),
    "helix": (paths.helix, ("center", "a", "b", "T", "climb", "phase")),
    "waypoints": (paths.waypoints, ("points", "extend")),
    "lawnmower": (paths.lawnmower, ("start", "leg", "radius", "n_legs", "depth", "descent")),
}
#: fixed keys of [scenario] (besides the [scenario.path] table and the loop's options)
SCENARIO_KEYS = ("module", "vehicle", "controller", "params", "plant_params")
#: loop dataclass fields that are not [scenario] options
_NOT_OPTIONS = ("controller", "path", "smooth")


def loop_options(cls) -> dict[str, dict]:
    """The static options of a loop class that ``[scenario]`` accepts: its dataclass fields
    but controller, path and smooth, as ``{name: {"type", "default", "choices"}}``."""
    out = {}
    for f in dataclasses.fields(cls):
        if f.name in _NOT_OPTIONS:
            continue
        t = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
        choices = ()
        if t.startswith("Literal["):
            choices = tuple(a.strip().strip("'\"") for a in t[len("Literal[") : -1].split(","))
            t = "str"
        elif t not in ("bool", "int", "float", "str"):
            t = type(f.default).__name__
        out[f.name] = {"type": t, "default": f.default, "choices": choices}
    return out


def _option(name: str, v, opt: dict):
    t = opt["type"]
    if t == "bool":
        return as_bool(name, v)
    if t == "int":
        return as_int(name, v, 0)
    if t == "float":
        return as_number(name, v)
    if t == "str":
        v = as_str(name, v)
        return as_choice(name, v, opt["choices"]) if opt["choices"] else v
    raise ConfigError(f"{name}: the option's type {t} cannot be given in a config")


def import_module_file(path) -> None:
    """Import a Python file once (by its resolved path), e.g. one that registers loops.

    The module's own ``sys.exit()`` or ``raise KeyboardInterrupt`` at import is its failure
    (``ValueError`` naming the file), not the command's exit nor the user's Ctrl-C; a real
    Ctrl-C during the import still interrupts."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(
            f"{path} is a folder; expected a Python file (.py) that registers loops or laws"
        )
    path = path.resolve()
    if str(path) in _IMPORTED:
        return
    name = f"vcjax_user_{len(_IMPORTED)}_{path.stem}"
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ValueError(f"module: cannot import {path}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    ctrl_c: list[int] = []
    try:
        with _noting_ctrl_c(ctrl_c):
            spec.loader.exec_module(mod)
    except SystemExit as err:
        sys.modules.pop(name, None)
        raise ValueError(
            f"{path}: called sys.exit({err.code!r}) while being imported (a module that "
            "registers loops or laws must not exit)"
        ) from None
    except KeyboardInterrupt:
        sys.modules.pop(name, None)
        if ctrl_c:  # the user's Ctrl-C
            raise
        raise ValueError(f"{path}: raised KeyboardInterrupt while being imported") from None
    except BaseException:
        sys.modules.pop(name, None)
        raise
    _IMPORTED[str(path)] = mod


@contextlib.contextmanager
def _noting_ctrl_c(seen: list):
    """While importing a user's module: a real SIGINT is noted in ``seen`` (then raises
    ``KeyboardInterrupt`` as Python's default handler does), so that a ``KeyboardInterrupt``
    the module raises itself can be told from the user's Ctrl-C. Main thread, default
    handler only; elsewhere a no-op."""
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is not signal.default_int_handler
    ):
        yield
        return

    def handler(signum, frame):
        seen.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


_IMPORTED: dict[str, Any] = {}


def _freeze(v):
    return tuple(_freeze(a) for a in v) if isinstance(v, list | tuple) else v


def _thaw(v):
    return [_thaw(a) for a in v] if isinstance(v, tuple) else v


@dataclasses.dataclass(frozen=True)
class PathSpec:
    """A path named in a config: ``kind`` and the constructor's keyword arguments (hashable)."""

    kind: str
    args: tuple[tuple[str, Any], ...] = ()

    def build(self):
        """``(Path, coeffs)`` from [`vcjax.paths`][vcjax.paths] (raises ``ValueError`` naming the
        key)."""
        fn, _ = PATH_KINDS[self.kind]
        return fn(**{k: _thaw(v) for k, v in self.args})

    def to_dict(self) -> dict:
        return {"kind": self.kind, **{k: _thaw(v) for k, v in self.args}}


def path_spec(d: dict, where: str) -> PathSpec:
    """Validated [`PathSpec`][vcjax.config.scenario.PathSpec] of a ``[scenario.path]`` table (built
    once to check it)."""
    if not isinstance(d, dict):
        raise ConfigError(f"{where}: [scenario.path] must be a table, got {d!r}")
    if "kind" not in d:
        raise ConfigError(f"{where}: [scenario.path] kind is required; one of {list(PATH_KINDS)}")
    kind = as_choice(f"{where}: [scenario.path] kind", d["kind"], PATH_KINDS)
    allowed = PATH_KINDS[kind][1]
    for k in d:
        if k != "kind" and k not in allowed:
            raise ConfigError(
                f"{where}: {unknown_key('scenario.path', k, allowed, f'for kind {kind!r}')}"
            )
    spec = PathSpec(kind, tuple((k, _freeze(d[k])) for k in allowed if k in d))
    try:
        spec.build()
    except (ValueError, TypeError) as err:
        raise ConfigError(f"{where}: [scenario.path] {err}") from None
    return spec


@dataclasses.dataclass(frozen=True)
class ScenarioChoice:
    """``[scenario]``: what a config simulates (hashable): vehicle, controller (``None``: not
    given), path (``[scenario.path]``; ``None``: the vehicle's default), parameter overrides
    (name, value) of plant and design (``params``) and of the plant only (``plant_params``), and
    the static options of the loop class, written as keys of ``[scenario]`` named like its
    dataclass fields (e.g. ODIN's ``integral``, ``polish``). Without ``[scenario]``:
    Simulation 1 (``DEFAULT_SCENARIO``)."""

    vehicle: str = key(
        DEFAULT_SCENARIO["vehicle"], "str", "", "a registered vehicle (vcjax.loops.vehicles())"
    )
    controller: str | None = key(
        DEFAULT_SCENARIO["controller"],
        "str",
        "",
        "one of the vehicle's controllers (default: all of them in a sweep, its default "
        "controller in tune)",
        aliases=("[problem] variant", "[sweep] variants"),
    )
    module: str | None = key(
        None, "file", "", "a Python file that registers your own loops, imported first"
    )
    path: PathSpec | None = key(
        DEFAULT_SCENARIO["path"], "table", "", "[scenario.path]: kind and its constructor's keys"
    )
    params: tuple[tuple[str, Any], ...] = key(
        (), "file", "", "JSON parameter overrides of plant and design model"
    )
    plant_params: tuple[tuple[str, Any], ...] = key(
        (), "file", "", "JSON parameter overrides of the plant only (after params)"
    )
    options: tuple[tuple[str, Any], ...] = key(
        (),
        "options",
        "",
        "static options of the loop class (its dataclass fields but controller, path, smooth)",
        open_keys="the loop class's options",
    )

    def loop(self, controller: str | None = None, **options) -> loops.Loop:
        """The loop of ``controller`` (default ``controller``) with this path and options."""
        ctrl = controller or self.controller
        cls = loops.loop_class(self.vehicle)
        path = cls.default_path()[0] if self.path is None else self.path.build()[0]
        return loops.make_loop(self.vehicle, ctrl, path, **(dict(self.options) | options))

    def coeffs(self):
        """The path's coefficients."""
        cls = loops.loop_class(self.vehicle)
        return cls.default_path()[1] if self.path is None else self.path.build()[1]

    def nominal(self, loop: loops.Loop, dtype=None):
        """``(plant, design)`` parameters: defaults, ``params`` on both, ``plant_params`` on
        the plant."""
        design = loops.apply_params(loop.default_params(dtype), dict(self.params), "params")
        plant = loops.apply_params(design, dict(self.plant_params), "plant_params")
        return plant, design

    def to_dict(self) -> dict:
        return {
            "vehicle": self.vehicle,
            "controller": self.controller,
            "module": self.module,
            "path": None if self.path is None else self.path.to_dict(),
            "params": {k: _thaw(v) for k, v in self.params},
            "plant_params": {k: _thaw(v) for k, v in self.plant_params},
            "options": dict(self.options),
        }

    @classmethod
    def from_dict(cls, d: dict) -> ScenarioChoice:
        if d.get("module"):
            import_module_file(d["module"])
        p = d.get("path")
        path = None
        if p is not None:
            p = dict(p)
            kind = p.pop("kind")
            allowed = PATH_KINDS[kind][1]
            path = PathSpec(kind, tuple((k, _freeze(p[k])) for k in allowed if k in p))
        return cls(
            vehicle=d["vehicle"],
            controller=d.get("controller"),
            module=d.get("module"),
            path=path,
            params=tuple((k, _freeze(v)) for k, v in d.get("params", {}).items()),
            plant_params=tuple((k, _freeze(v)) for k, v in d.get("plant_params", {}).items()),
            options=tuple(d.get("options", {}).items()),
        )


def _with_older(options: tuple, older: dict, opts: dict, where: str) -> tuple:
    """``options`` with the loop options given in an older spelling (``older``: ``{key: (older
    spelling, value)}``, [`take_moved`][vcjax.config.aliases.take_moved]); a loop without the
    option runs without it, as before it moved. Both spellings must agree."""
    given = dict(options)
    for k, (old, v) in older.items():
        if k not in opts:
            continue
        v = _option(f"{where}: {old}", v, opts[k])
        if k in given and given[k] != v:
            raise ConfigError(
                f"{where}: {old}: {v!r} contradicts [scenario] {k} {given[k]!r} (its newer "
                "spelling); give one of them"
            )
        given[k] = v
    return tuple(given.items())


def parse_scenario(
    raw: dict | None, where: str, config_path, older: dict | None = None
) -> ScenarioChoice:
    """Validated [`ScenarioChoice`][vcjax.config.scenario.ScenarioChoice] of a ``[scenario]`` table
    (``None``: Simulation 1); ``older``: loop options given in an older spelling
    ([`take_moved`][vcjax.config.aliases.take_moved]).

    Raises:
        ConfigError: naming the file, ``[scenario]`` and the key; parameter files by path.
    """
    if raw is None and not older:
        return ScenarioChoice()
    raw = {} if raw is None else raw
    module = None
    if "module" in raw:
        given = raw["module"]
        if isinstance(given, str) and (Path(config_path).parent / given).is_dir():
            raise ConfigError(
                f"{where}: [scenario] module: {given!r} is a folder "
                f"({(Path(config_path).parent / given).resolve()}); expected a Python file "
                "(.py) that registers loops or laws"
            )
        module = str(resolve_file(f"{where}: [scenario] module", given, Path(config_path)))
        try:
            import_module_file(module)
        except Exception as err:  # the user's file: report whatever it raised, in one line
            if isinstance(err, ValueError) and str(err).startswith(str(module)):
                raise ConfigError(f"{where}: [scenario] module: {err}") from None  # names it
            raise ConfigError(f"{where}: [scenario] module: {module}: {err!r}") from None
    vehicle = raw.get("vehicle", DEFAULT_SCENARIO["vehicle"])
    try:
        cls = loops.loop_class(as_str("vehicle", vehicle))
    except ValueError as err:
        raise ConfigError(f"{where}: [scenario] {err}") from None
    opts = loop_options(cls)
    for k in raw:
        if k not in SCENARIO_KEYS and k != "path" and k not in opts:
            if any(k in loop_options(loops.loop_class(v)) for v in loops.vehicles()):
                raise ConfigError(f"{where}: [scenario] {k}: not an option of the {vehicle} loop")
            raise ConfigError(f"{where}: {unknown_key('scenario', k, [*SCENARIO_KEYS, *opts])}")
    controller = raw.get("controller")
    if controller is not None and controller not in cls.controllers:
        raise ConfigError(
            f"{where}: [scenario] controller: vehicle {vehicle!r} supports "
            f"{list(cls.controllers)}, got {controller!r}"
        )
    options = tuple(
        (k, _option(f"{where}: [scenario] {k}", raw[k], opts[k])) for k in opts if k in raw
    )
    options = _with_older(options, older or {}, opts, where)
    path = None if "path" not in raw else path_spec(raw["path"], where)
    choice = ScenarioChoice(
        vehicle=vehicle, controller=controller, module=module, path=path, options=options
    )
    probe = choice.loop(controller or cls.controllers[0])
    over = {}
    for name in ("params", "plant_params"):
        if name in raw:
            f = resolve_file(f"{where}: [scenario] {name}", raw[name], Path(config_path))
            try:
                vals = loops.read_param_file(f, probe, where=f"[scenario] {name}")
            except ValueError as err:
                raise ConfigError(f"{where}: {err}") from None
            over[name] = tuple((k, _freeze(v)) for k, v in vals.items())
    choice = dataclasses.replace(choice, **over)
    try:
        choice.nominal(probe)
    except ValueError as err:
        raise ConfigError(f"{where}: [scenario] {err}") from None
    return choice
