"""Frozen config objects: what ``vcjax tune`` and ``vcjax fit`` parse a file into (as
[`vcjax.sweep.SweepSpec`][vcjax.sweep.spec.SweepSpec] is for sweeps).

A [`FrozenSection`][vcjax.config.frozen.FrozenSection] is a frozen dataclass (immutable, hashable:
lists become tuples) that
also reads as a read-only mapping, ``cfg["problem"]["horizon"]`` as well as
``cfg.problem.horizon``, so code written against the older plain-dict results keeps working;
[`FrozenSection.to_dict`][vcjax.config.frozen.FrozenSection.to_dict] gives the plain-JSON form the
CLI records in ``run.json`` and
[`FrozenSection.from_dict`][vcjax.config.frozen.FrozenSection.from_dict] reads it back. This module
imports nothing of vcjax.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator, Mapping
from typing import Any

__all__ = ["FrozenSection", "freeze", "thaw"]


def freeze(v: Any) -> Any:
    """``v`` with every list (nested) turned into a tuple and every dict into a tuple of
    ``(key, value)`` pairs: a hashable value."""
    if isinstance(v, dict):
        return tuple((k, freeze(x)) for k, x in v.items())
    if isinstance(v, list | tuple):
        return tuple(freeze(x) for x in v)
    return v


def thaw(v: Any) -> Any:
    """Plain-JSON form: tuples become lists, sections dicts (inverse of
    [`freeze`][vcjax.config.frozen.freeze] for
    lists)."""
    if isinstance(v, FrozenSection):
        return v.to_dict()
    if isinstance(v, tuple):
        return [thaw(x) for x in v]
    return v


@dataclasses.dataclass(frozen=True)
class FrozenSection(Mapping):
    """Base of a frozen config section (module docstring). Subclasses are frozen dataclasses
    (their generated field-wise ``__eq__`` and ``__hash__`` replace the mapping's); list values
    are stored as tuples, dict values as tuples of pairs. A field with
    ``metadata={"record": False}`` (e.g. the file a config was read from) is neither a key of
    the mapping nor part of ``to_dict``."""

    def __post_init__(self):
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, list | dict):
                object.__setattr__(self, f.name, freeze(v))

    # ---------------------------------------------------------------- read-only mapping view
    def __getitem__(self, key: str) -> Any:
        if key not in self._keys():
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self) -> Iterator[str]:
        return iter(self._keys())

    def __len__(self) -> int:
        return len(self._keys())

    @classmethod
    def _keys(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls) if f.metadata.get("record", True))

    # ---------------------------------------------------------------- JSON
    def to_dict(self) -> dict:
        """Plain-JSON form (tuples as lists, sections as dicts)."""
        return {k: thaw(getattr(self, k)) for k in self._keys()}

    @classmethod
    def from_dict(cls, d: Mapping):
        """The section of a ``to_dict`` result (unknown keys: ``KeyError``)."""
        fields = {f.name: f for f in dataclasses.fields(cls)}
        unknown = sorted(set(d) - set(fields))
        if unknown:
            raise KeyError(f"{cls.__name__}: unknown keys {unknown}")
        vals = {}
        for k, v in d.items():
            sub = _section_type(fields[k].type, cls)
            vals[k] = sub.from_dict(v) if sub is not None and isinstance(v, Mapping) else v
        return cls(**vals)


def _section_type(annotation, owner) -> type | None:
    """The [`FrozenSection`][vcjax.config.frozen.FrozenSection] subclass a field is annotated with
    (string annotations are
    resolved in the owner's module), or None."""
    if isinstance(annotation, str):
        import sys

        annotation = getattr(sys.modules[owner.__module__], annotation, None)
    if isinstance(annotation, type) and issubclass(annotation, FrozenSection):
        return annotation
    return None
