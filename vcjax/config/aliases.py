"""The older spellings of config keys, in one table, each with its one-line deprecation note.

``ALIASES`` maps an older ``"[section] key"`` to the newer one. It is read from the
declarations (the ``aliases`` metadata of the shared sections' keys,
[`vcjax.config.schema`][vcjax.config.schema]
and [`ScenarioChoice`][vcjax.config.scenario.ScenarioChoice]) plus ``MOVED`` (keys whose new home is
not a declared field of a shared section).
[`note_old_spellings`][vcjax.config.aliases.note_old_spellings] issues one
[`ConfigNote`][vcjax.config.values.ConfigNote] per older spelling a config uses; the parsers accept
both and
refuse the two given together with different values (naming both).

Not deprecated: ``[sweep] variants`` (several controllers in one sweep: ``[scenario]
controller`` names one) and the ``[scenarios]`` shorthands of ``vcjax tune``
(``current_max``, ``position_offset``, ``heading_offset_deg``: distributions about the
vehicle's default start, which ``[current]`` and ``[initial]`` can also write out in full).
"""

from __future__ import annotations

import dataclasses

from vcjax import loops
from vcjax.config.scenario import ScenarioChoice, loop_options
from vcjax.config.schema import SECTIONS
from vcjax.config.values import ConfigError, note

__all__ = ["ALIASES", "MOVED", "note_old_spellings", "take_moved", "moved_values"]

#: older spelling -> newer, for keys that moved to a section other than a declared alias's (the
#: ``[scenario]`` ones are loop options: parsed with the others, by
#: [`parse_scenario`][vcjax.config.scenario.parse_scenario])
MOVED = {
    "[problem] edd": "[scenario] edd",
    "[simulation] edd": "[scenario] edd",
}
#: the older spellings that are shorthands, not renames (no deprecation note)
_KEPT = ("[sweep] variants", "[scenarios] ")


def _declared() -> dict[str, str]:
    out = {}
    for name, cls in {"scenario": ScenarioChoice, **SECTIONS}.items():
        for f in dataclasses.fields(cls):
            for old in f.metadata.get("aliases", ()):
                if not old.startswith(_KEPT):
                    out[old] = f"[{name}] {f.name}"
    return out


#: older ``"[section] key"`` -> newer ``"[section] key"`` (one table)
ALIASES: dict[str, str] = {**_declared(), **MOVED}


def note_old_spellings(raw: dict, where: str) -> list[str]:
    """One [`ConfigNote`][vcjax.config.values.ConfigNote] per older spelling used in ``raw`` (a
    parsed TOML
    file); returns the older spellings found."""
    found = []
    for old, new in ALIASES.items():
        sec, key = old[1:].split("] ")
        table = raw.get(sec)
        if isinstance(table, dict) and key in table:
            note(f"{where}: {old} is an older spelling of {new}; write {new}")
            found.append(old)
    return found


def take_moved(raw: dict) -> tuple[dict, dict]:
    """``(rest, older)``: ``raw`` without the older spellings of ``[scenario]`` loop options
    (``MOVED``), and those as ``{key: (older spelling, value)}`` for
    [`parse_scenario`][vcjax.config.scenario.parse_scenario] (two older spellings that disagree
    are refused naming both)."""
    rest, older = dict(raw), {}
    for old, new in MOVED.items():
        sec, key = old[1:].split("] ")
        table = rest.get(sec)
        if not (new.startswith("[scenario] ") and isinstance(table, dict) and key in table):
            continue
        opt = new.removeprefix("[scenario] ")
        if opt in older and older[opt][1] != table[key]:
            raise ConfigError(
                f"{old}: {table[key]!r} contradicts {older[opt][0]} {older[opt][1]!r}; give one"
            )
        older[opt] = (old, table[key])
        rest[sec] = {k: v for k, v in table.items() if k != key}
    return rest, older


def moved_values(choice: ScenarioChoice) -> dict:
    """``{key: value}`` of every ``[scenario]`` option with an older spelling (``MOVED``): the
    value that ran, or for a loop without the option the default of the loops that have it (what
    ``run.json`` and ``summary.json`` recorded of them before they moved)."""
    cls = loops.loop_class(choice.vehicle)
    out = {}
    for new in dict.fromkeys(MOVED.values()):
        opt = new.removeprefix("[scenario] ")
        if opt in loop_options(cls):
            out[opt] = dict(choice.options).get(opt, loop_options(cls)[opt]["default"])
            continue
        for v in loops.vehicles():
            if opt in loop_options(loops.loop_class(v)):
                out[opt] = loop_options(loops.loop_class(v))[opt]["default"]
                break
    return out
