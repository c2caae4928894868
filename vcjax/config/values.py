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

import tomllib
import warnings
from pathlib import Path
from typing import Any

from vcjax._checks import (
    SEED_MAX,
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
    unknown_key,
)

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
    "unknown_key",
]


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
                raise ConfigError(f"{where}: {unknown_key(sec, key, schema[sec])}")


def resolve_file(name: str, value: Any, config_path: Path) -> Path:
    """A file named in a config, relative to the config's folder; it must exist."""
    p = Path(as_str(name, value))
    p = p if p.is_absolute() else Path(config_path).parent / p
    if not p.is_file():
        raise ConfigError(f"{name}: no such file {p}")
    return p
