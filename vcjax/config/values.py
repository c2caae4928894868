"""One way to read and validate the TOML files of every command (``vcjax sweep``, ``vcjax tune``).

[`ConfigError`][vcjax.config.values.ConfigError] is the one error class: its message names the file,
the section and the key
(``examples/x.toml: [current] speed: expected finite lo <= hi, got [1.0, 0.5]``), and a file a
config refers to (gains, parameters) by its path. The helpers below check one value each and
raise with the name they are given; [`read_toml`][vcjax.config.values.read_toml] and
[`check_schema`][vcjax.config.values.check_schema] handle the file
and its sections. Validation is eager (plain Python), before anything is compiled.
"""

from __future__ import annotations

import math
import tomllib
import warnings
from pathlib import Path
from typing import Any

__all__ = [
    "ConfigError",
    "ConfigNote",
    "note",
    "read_toml",
    "check_schema",
    "as_range",
    "as_number",
    "as_int",
    "as_choice",
    "as_bool",
    "as_str",
    "as_str_list",
    "resolve_file",
    "SEED_MAX",
    "as_seed",
    "closest",
]

#: the largest seed of a study: the scenario sampler
#: ([`vcjax.sweep.sample_scenarios`][vcjax.sweep.spec.sample_scenarios])
#: builds its JAX PRNG key from ``jnp.uint32(seed)``, in float64 and float32 mode alike, so
#: every seed of a config or of the Python API lies in ``0 .. SEED_MAX`` (checked by
#: [`as_seed`][vcjax.config.values.as_seed], here and in the sampler: one bound)
SEED_MAX = 2**32 - 1


class ConfigError(ValueError):
    """An invalid configuration (the message names the file, section and key)."""


class ConfigNote(UserWarning):
    """A one-line note about a valid config: an older spelling (naming the new one), or a
    config whose meaning changed since such configs were written
    ([`note`][vcjax.config.values.note])."""


def note(message: str) -> None:
    """Issue ``message`` as a [`ConfigNote`][vcjax.config.values.ConfigNote] warning (shown once per
    message, on stderr
    as one line ``vcjax: note: MESSAGE``)."""
    warnings.warn(message, ConfigNote, stacklevel=3)


_FORMAT = warnings.formatwarning


def _format_note(message, category, filename, lineno, line=None):
    """A [`ConfigNote`][vcjax.config.values.ConfigNote] as one line (other warnings keep Python's
    format)."""
    if isinstance(category, type) and issubclass(category, ConfigNote):
        return f"vcjax: note: {message}\n"
    return _FORMAT(message, category, filename, lineno, line)


warnings.formatwarning = _format_note


def read_toml(path) -> dict:
    """The parsed TOML file; [`ConfigError`][vcjax.config.values.ConfigError] if it cannot be read
    or parsed."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as err:
        raise ConfigError(f"cannot read {path}: {err}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML (invalid TOML: {err})") from None


def check_schema(raw: dict, schema: dict[str, tuple[str, ...] | None], where: str) -> None:
    """Every section of ``raw`` is in ``schema`` and a table, every key known.

    Sub-tables listed in the schema as ``"section.sub"`` (e.g. ``"scenario.path"``) are
    allowed as keys of their parent and checked by their own parser; a section whose keys are
    ``None`` (they depend on the vehicle) is checked by the caller.
    """
    if not isinstance(raw, dict):
        raise ConfigError(f"{where}: expected a table of sections")
    for sec, body in raw.items():
        if sec not in schema:
            top = [s for s in schema if "." not in s]
            raise ConfigError(
                f"{where}: unknown section [{sec}]{closest(sec, top)}; expected {top}"
            )
        if not isinstance(body, dict):
            raise ConfigError(f"{where}: [{sec}] must be a table, got {body!r}")
        if schema[sec] is None:
            continue
        for key in body:
            if key not in schema[sec] and f"{sec}.{key}" not in schema:
                raise ConfigError(
                    f"{where}: unknown key [{sec}] {key!r}{closest(key, schema[sec])}; "
                    f"expected one of {list(schema[sec])}"
                )


def as_range(name, v, lo_min=None, positive=False) -> tuple[float, float]:
    """A number (fixed) or ``[lo, hi]`` (sampled uniformly) as ``(lo, hi)``."""
    if isinstance(v, bool) or not isinstance(v, int | float | tuple | list):
        raise ConfigError(f"{name}: expected a number or [lo, hi], got {v!r}")
    if isinstance(v, int | float):
        v = (v, v)
    if len(v) != 2 or any(isinstance(a, bool) or not isinstance(a, int | float) for a in v):
        raise ConfigError(f"{name}: expected a number or a list [lo, hi], got {list(v)!r}")
    lo, hi = float(v[0]), float(v[1])
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise ConfigError(f"{name}: expected finite lo <= hi, got [{lo}, {hi}]")
    if lo_min is not None and lo < lo_min:
        raise ConfigError(f"{name}: values must be >= {lo_min}, got [{lo}, {hi}]")
    if positive and lo <= 0:
        raise ConfigError(f"{name}: values must be > 0, got [{lo}, {hi}]")
    return lo, hi


def as_number(name, v, lo=None, lo_open=False, hi=None, hi_open=False) -> float:
    """A finite number within the given bounds."""
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise ConfigError(f"{name}: expected a finite number, got {v!r}")
    v = float(v)
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise ConfigError(f"{name}: expected a value {'>' if lo_open else '>='} {lo}, got {v}")
    if hi is not None and (v >= hi if hi_open else v > hi):
        raise ConfigError(f"{name}: expected a value {'<' if hi_open else '<='} {hi}, got {v}")
    return v


def as_int(name, v, lo) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ConfigError(f"{name}: expected an integer, got {v!r}")
    if v < lo:
        raise ConfigError(f"{name}: expected an integer >= {lo}, got {v}")
    return v


def as_seed(name, v) -> int:
    """An integer seed in ``0 .. SEED_MAX`` (what the sampler's ``jnp.uint32`` key takes)."""
    if isinstance(v, bool) or not hasattr(v, "__index__"):
        raise ConfigError(f"{name}: expected an integer seed, got {v!r}")
    v = int(v.__index__())
    if not 0 <= v <= SEED_MAX:
        raise ConfigError(
            f"{name}: {v} is outside the seed range 0 .. {SEED_MAX} (2**32 - 1: the scenario "
            "sampler's PRNG key is a 32-bit unsigned integer)"
        )
    return v


def closest(key: str, valid) -> str:
    """`` (did you mean 'x'?)`` for the valid key closest to a mistyped ``key`` (difflib), or
    ``""``."""
    import difflib

    near = difflib.get_close_matches(str(key), [str(v) for v in valid], n=1, cutoff=0.6)
    return f" (did you mean {near[0]!r}?)" if near else ""


def as_choice(name, v, choices) -> str:
    if v not in choices:
        raise ConfigError(f"{name}: expected one of {list(choices)}, got {v!r}")
    return v


def as_bool(name, v) -> bool:
    if not isinstance(v, bool):
        raise ConfigError(f"{name}: expected true or false, got {v!r}")
    return v


def as_str(name, v) -> str:
    if not isinstance(v, str):
        raise ConfigError(f"{name}: expected a string, got {type(v).__name__} {v!r}")
    return v


def as_str_list(name, v) -> tuple[str, ...]:
    if not isinstance(v, list | tuple) or not all(isinstance(a, str) for a in v):
        raise ConfigError(f"{name}: expected a list of strings, got {v!r}")
    return tuple(v)


def resolve_file(name: str, value: Any, config_path: Path) -> Path:
    """A file named in a config, relative to the config's folder; it must exist."""
    p = Path(as_str(name, value))
    p = p if p.is_absolute() else Path(config_path).parent / p
    if not p.is_file():
        raise ConfigError(f"{name}: no such file {p}")
    return p
