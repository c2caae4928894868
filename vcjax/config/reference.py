"""The configuration reference: every shared section (``[scenario]`` and those of
[`vcjax.config.schema`][vcjax.config.schema]) with its keys' types, defaults, units, descriptions
and older
spellings, as data ([`schema`][vcjax.config.reference.schema]) and as Markdown tables
([`reference_markdown`][vcjax.config.reference.reference_markdown], rendered
into the documentation)."""

from __future__ import annotations

import dataclasses

from vcjax.config.scenario import ScenarioChoice
from vcjax.config.schema import SECTIONS, registered

__all__ = ["schema", "reference_markdown", "toml_literal"]


def toml_literal(value) -> str:
    """``value`` as a config file writes it: ``true``/``false``, ``"text"``, ``[0.5, 0.5]``,
    numbers as numbers; no default (``None``) as ``(none)``, a required key as
    ``(required)`` (``...``)."""
    if value is None:
        return "(none)"
    if value is ...:
        return "(required)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_literal(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_literal(v)}" for k, v in value.items()) + "}"
    if isinstance(value, float):
        return (
            repr(value)
            if value == value and abs(value) != float("inf")
            else ("nan" if value != value else ("inf" if value > 0 else "-inf"))
        )
    return repr(value)


def schema() -> dict[str, dict]:
    """Every shared section: ``{name: {"doc": str, "keys": {key: {"type", "default", "unit",
    "doc", ...}}}}`` (``[scenario]`` included), for a reference table."""
    out = {}
    for name, cls in {"scenario": ScenarioChoice, **SECTIONS, **registered()}.items():
        keys = {}
        for f in dataclasses.fields(cls):
            if "type" not in f.metadata:
                continue
            keys[f.name] = {"default": f.default, **dict(f.metadata)}
        out[name] = {"doc": (cls.__doc__ or "").strip(), "keys": keys}
    return out


def reference_markdown() -> str:
    """The shared sections as Markdown: per section its docstring and a table of its keys
    (type, default, unit, description, older spellings), rendered from
    [`schema`][vcjax.config.reference.schema]."""
    out = []
    for name, sec in schema().items():
        out += [f"### [{name}]", "", " ".join(sec["doc"].split()), ""]
        out += ["| key | type | default | unit | description | older spellings |"]
        out += ["|---|---|---|---|---|---|"]
        for key, m in sec["keys"].items():
            key = f"*{m['open_keys']}*" if "open_keys" in m else key
            choices = f" (one of {', '.join(m['choices'])})" if m.get("choices") else ""
            default = toml_literal(m["default"])
            out.append(
                f"| {key} | {m['type']} | `{default}` | {m['unit']} | {m['doc']}{choices} "
                f"| {', '.join(m.get('aliases', ()))} |"
            )
        out.append("")
    return "\n".join(out)
