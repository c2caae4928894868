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

from vcjax.config.scenario import ScenarioChoice
from vcjax.config.schema import SECTIONS
from vcjax.config.values import note

__all__ = ["ALIASES", "MOVED", "note_old_spellings"]

#: older spelling -> newer, for keys that moved to a section other than a declared alias's
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
