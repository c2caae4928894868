"""The configuration reference: every shared section (``[scenario]`` and those of
:mod:`vcjax.config.schema`) with its keys' types, defaults, units, descriptions and older
spellings, as data (:func:`schema`) and as Markdown tables (:func:`reference_markdown`, rendered
into the documentation)."""

from __future__ import annotations

import dataclasses

from vcjax.config.scenario import ScenarioChoice
from vcjax.config.schema import SECTIONS

__all__ = ["schema", "reference_markdown"]


def schema() -> dict[str, dict]:
    """Every shared section: ``{name: {"doc": str, "keys": {key: {"type", "default", "unit",
    "doc", ...}}}}`` (``[scenario]`` included), for a reference table."""
    out = {}
    for name, cls in {"scenario": ScenarioChoice, **SECTIONS}.items():
        keys = {}
        for f in dataclasses.fields(cls):
            if "type" not in f.metadata:
                continue
            keys[f.name] = {"default": f.default, **dict(f.metadata)}
        out[name] = {"doc": (cls.__doc__ or "").strip(), "keys": keys}
    return out


def reference_markdown() -> str:
    """The shared sections as Markdown: per section its docstring and a table of its keys
    (type, default, unit, description, older spellings), rendered from :func:`schema`."""
    out = []
    for name, sec in schema().items():
        out += [f"### [{name}]", "", " ".join(sec["doc"].split()), ""]
        out += ["| key | type | default | unit | description | older spellings |"]
        out += ["|---|---|---|---|---|---|"]
        for key, m in sec["keys"].items():
            key = f"*{m['open_keys']}*" if "open_keys" in m else key
            choices = f" (one of {', '.join(m['choices'])})" if m.get("choices") else ""
            out.append(
                f"| {key} | {m['type']} | {m['default']!r} | {m['unit']} | {m['doc']}{choices} "
                f"| {', '.join(m.get('aliases', ()))} |"
            )
        out.append("")
    return "\n".join(out)
