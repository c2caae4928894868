"""One configuration system for ``vcjax sweep``, ``vcjax tune`` and ``vcjax fit``.

* [`vcjax.config.values`][vcjax.config.values] -- [`ConfigError`][vcjax.config.values.ConfigError]
(the one error class of every command; its
  message names the file, the section and the key: ``[section] key: message``, the closest valid
  key suggested for a typo), [`ConfigNote`][vcjax.config.values.ConfigNote] (one-line notes: older
  spellings, changed
  meanings), [`read_toml`][vcjax.config.values.read_toml] and one checker per value; ``SEED_MAX`` is
  the one seed bound
  (the sampler's ``uint32`` key: ``0 .. 2**32 - 1``), checked by
  [`as_seed`][vcjax.config.values.as_seed] in the parsers
  and in the sampler.
* [`vcjax.config.schema`][vcjax.config.schema] -- the shared sections as typed, frozen objects, each
key with its
  type, default, unit, description and older spellings: ``[simulation]`` (horizon, dt,
  integrator, timing, u_d, smooth), ``[current]``, ``[waves]``, ``[initial]``,
  ``[model_error]``, ``[sensor_noise]``, ``[disturbance]``; ``DEFAULT_SCENARIO`` is the
  scenario of a config without ``[scenario]`` (Simulation 1).
  Every section of every command (sweep, tune, fit) is declared with ``key`` (type, default, unit,
  doc, bounds, choices) and parsed by [`parse_section`][vcjax.config.schema.parse_section],
  the one validator; keys that do not apply to the others' values are refused there
  (``CROSS_CHECKS``). [`register_section`][vcjax.config.schema.register_section] adds a section (an
  environment component's) to the one table of added sections,
  `vcjax.environment.REGISTRY`, where
  [`vcjax.environment.register`][vcjax.environment.component.register] puts components: sweep and
  tune configs then accept and check it.
* [`vcjax.config.aliases`][vcjax.config.aliases] -- ``ALIASES``, the older spellings in
  one table (read from the declarations), each used one giving a note naming the new spelling.
* [`vcjax.config.reference`][vcjax.config.reference] -- [`schema`][vcjax.config.schema] returns
every section for a reference table,
  [`reference_markdown`][vcjax.config.reference.reference_markdown] renders the tables.
* [`vcjax.config.scenario`][vcjax.config.scenario] -- ``[scenario]`` (``ScenarioChoice``: vehicle,
  controller, path, parameter files, a module of your own loops, and any static option of the
  loop class read from its dataclass fields).

Older spellings stay accepted: in tune configs ``[problem] horizon/dt/integrator/timing/smooth``
(= ``[simulation]``), ``[problem] variant`` (= ``[scenario] controller``), ``[scenarios]
current_max`` (= ``[current] speed = [0, m]`` in every direction), ``[scenarios]
position_offset/heading_offset_deg`` (ranges of ``[initial]`` about the default start); in sweep
configs ``[sweep] variants`` (several controllers on the same scenarios); a loop option that
moved to ``[scenario]`` from ``[simulation]``/``[problem]`` (``aliases.MOVED``). A key given
under both spellings is refused.

Layering: this package sits just above [`vcjax.loops`][vcjax.loops] (``[scenario]`` reads the loop
registry and the loop classes' dataclass fields); ``values`` and ``schema`` import nothing of
vcjax at import time (``schema``'s added sections live in ``vcjax.environment.REGISTRY``), and
[`vcjax.loops`][vcjax.loops] never imports this package.
"""

from vcjax.config.reference import reference_markdown, schema
from vcjax.config.schema import (
    DEFAULT_SCENARIO,
    SECTIONS,
    Current,
    Disturbance,
    Initial,
    ModelError,
    SensorNoise,
    Simulation,
    Waves,
    parse_section,
    register_section,
)
from vcjax.config.values import (
    SEED_MAX,
    ConfigError,
    ConfigNote,
    as_bool,
    as_choice,
    as_int,
    as_number,
    as_range,
    as_seed,
    as_str,
    as_str_list,
    check_schema,
    closest,
    note,
    read_toml,
    resolve_file,
    unknown_key,
)

__all__ = [
    "ConfigError",
    "ConfigNote",
    "note",
    "SEED_MAX",
    "as_seed",
    "closest",
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
    "unknown_key",
    "DEFAULT_SCENARIO",
    "SECTIONS",
    "Simulation",
    "Current",
    "Waves",
    "Initial",
    "ModelError",
    "SensorNoise",
    "Disturbance",
    "parse_section",
    "register_section",
    "schema",
    "reference_markdown",
]
