"""mkdocs hooks: pages generated from the code and the benchmark results at build time.

* ``api/<concept>.md``: the API by concept (:data:`CONCEPTS`: loops and laws, vehicles, environment,
  rollouts, sweeps, tuning, ...), each page the public modules of its concept (mkdocstrings renders
  the docstrings), listed under *API* in the navigation; internals are not shown;
* ``<!-- vcjax:config-reference -->`` in a page becomes the configuration reference generated from
  the config schema objects (:func:`vcjax.config.schema`), one table per section;
* ``<!-- vcjax:benchmark-tables -->`` becomes one table per result file of
  ``benchmarks/results/*.json``, each with the machine it was measured on;
* ``benchmarks/results/*.png`` are served under ``benchmarks/``.
"""

from __future__ import annotations

import json
import pkgutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("vcjax", "tuning")


def public_modules() -> list[str]:
    """Dotted names of the public modules (no ``_private`` part) of :data:`PACKAGES`."""
    out = []
    for pkg in PACKAGES:
        out.append(pkg)
        for info in pkgutil.walk_packages([str(ROOT / pkg)], prefix=f"{pkg}."):
            if any(part.startswith("_") for part in info.name.split(".")):
                continue
            out.append(info.name)
    return sorted(out)


#: the API by concept: (page, title, introduction, module prefixes). A module belongs to the
#: first concept one of whose prefixes it equals or lies under; modules of no concept (the
#: command line's internals, interrupts, progress lines, size estimates) are not shown.
CONCEPTS = [
    (
        "engine",
        "The engine",
        "The generic virtually-constrained-motion engine: a mechanical system, its virtual "
        "constraints and their stabilised reaction force; the small linear solves; integrators; "
        "thruster allocation.",
        ["vcjax", "vcjax.mechanics", "vcjax.linalg", "vcjax.integrators", "vcjax.allocation"],
    ),
    (
        "loops",
        "Loops and laws",
        "Closed loops by name (vehicle x law x path), control laws as objects, their registry; "
        "paths and guidance.",
        ["vcjax.loops", "vcjax.control", "vcjax.paths", "vcjax.guidance"],
    ),
    (
        "vehicles",
        "Vehicles",
        "The plants: INFANTE-class, ODIN-class, REMUS 100, the 3-DOF "
        "design model and the two-link arm.",
        ["vcjax.vehicles"],
    ),
    (
        "environment",
        "Environment",
        "What the water and the world do to a vehicle: currents, random seas, sensor noise, "
        "forces.",
        ["vcjax.environment"],
    ),
    (
        "rollouts",
        "Rollouts and metrics",
        "The scan rollout, its health flags, and the one metrics function of every loop.",
        ["vcjax.rollout", "vcjax.metrics"],
    ),
    (
        "sweep",
        "Sweeps",
        "Monte-Carlo batches of any loop: sampling, running, results.",
        ["vcjax.sweep"],
    ),
    (
        "search",
        "Scenario search",
        "Worst-case search over an envelope of scenarios.",
        ["vcjax.falsify", "vcjax.search"],
    ),
    (
        "tuning",
        "Tuning",
        "Gain tuning through the closed loop: problems, losses, optimisers, "
        "black-box baselines, reports.",
        ["tuning"],
    ),
    (
        "identification",
        "Identification",
        "Plant parameters from logged runs by multiple shooting.",
        ["vcjax.identify"],
    ),
    (
        "config",
        "Configuration",
        "The configuration files: sections, values, older spellings.",
        ["vcjax.config"],
    ),
    (
        "experiments",
        "Experiments and figures",
        "The presets of `vcjax simulate` and the figures.",
        ["vcjax.experiments", "vcjax.plots"],
    ),
    (
        "runtime",
        "Outputs and runtime",
        "Output folders and what they record, the compilation cache and compiler flags, devices "
        "and processes.",
        [
            "vcjax.runtime.outputs",
            "vcjax.runtime.runinfo",
            "vcjax.runtime.cache",
            "vcjax.runtime.compiler",
            "vcjax.runtime.devices",
            "vcjax.runtime.distributed",
        ],
    ),
]


def _concept_of(module: str):
    for concept in CONCEPTS:
        for prefix in concept[3]:
            if module == prefix or (prefix != "vcjax" and module.startswith(prefix + ".")):
                return concept
    return None


def api_pages() -> dict[str, tuple[str, str, list[str]]]:
    """``{page: (title, introduction, [module, ...])}`` of the concepts that have modules."""
    pages: dict = {}
    for m in public_modules():
        concept = _concept_of(m)
        if concept is not None:
            pages.setdefault(concept[0], (concept[1], concept[2], []))[2].append(m)
    return {c[0]: pages[c[0]] for c in CONCEPTS if c[0] in pages}


def _api_page(title: str, intro: str, modules: list[str]) -> str:
    lines = [f"# {title}", "", intro, ""]
    for m in modules:
        lines += [
            f"## `{m}`",
            "",
            f"::: {m}",
            "    options:",
            "      heading_level: 3",
            "      show_submodules: false",
            "",
        ]
    return "\n".join(lines)


def _api_index(pages) -> str:
    lines = [
        "# API reference",
        "",
        "Generated from the docstrings (shapes, units and frames are given there), by concept.",
        "Start with the loops (closed loops by name), the rollouts and the metrics.",
        "",
    ]
    lines += [f"- [{title}]({page}.md): {intro}" for page, (title, intro, _) in pages.items()]
    return "\n".join(lines) + "\n"


def on_config(config):
    pages = api_pages()
    for item in config["nav"]:
        if isinstance(item, dict) and "API" in item:
            item["API"] = ["api/index.md"] + [{t: f"api/{p}.md"} for p, (t, _, _) in pages.items()]
    return config


def on_files(files, config):
    from mkdocs.structure.files import File  # here, so the tests can import the generators

    pages = api_pages()
    files.append(File.generated(config, "api/index.md", content=_api_index(pages)))
    for page, (title, intro, modules) in pages.items():
        files.append(
            File.generated(config, f"api/{page}.md", content=_api_page(title, intro, modules))
        )
    for png in sorted((ROOT / "benchmarks" / "results").glob("*.png")):
        files.append(File.generated(config, f"benchmarks/{png.name}", abs_src_path=str(png)))
    return files


# ------------------------------------------------------------------------------ benchmark tables

#: result files shown as current tables (the rest go to the history appendix)
HISTORY_SUFFIX = "_round1"


def _fmt(v) -> str:
    if isinstance(v, bool):
        return str(v)
    if isinstance(v, float):
        if v == 0 or 1e-3 <= abs(v) < 1e6:
            return f"{v:.4g}"
        return f"{v:.3e}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_fmt(x) for x in v)
    if isinstance(v, dict):
        return "; ".join(f"{k}: {_fmt(x)}" for k, x in v.items())
    return str(v)


def _machine(meta: dict) -> str:
    keys = ("date", "device", "cpu", "cpu_model", "jax", "python", "load_average_1min_at_end")
    parts = [f"{k} {_fmt(meta[k])}" for k in keys if k in meta]
    return "Measured on: " + ", ".join(parts) + "."


def _rows_table(rows: list[dict]) -> list[str]:
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    out = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        out.append("| " + " | ".join(_fmt(r.get(c, "")) for c in cols) + " |")
    return out


def _result_section(path: Path) -> list[str]:
    data = json.loads(path.read_text())
    out = [f"### `{path.name}`", ""]
    if isinstance(data, dict) and "rows" in data and isinstance(data["rows"], list):
        meta = data.get("meta", {})
        out += [_machine(meta), ""] if meta else []
        if data["rows"] and isinstance(data["rows"][0], dict):
            out += _rows_table(data["rows"])
    elif isinstance(data, dict) and "machine" in data:
        out += [_machine(data["machine"]), ""]
        body = {k: v for k, v in data.items() if k != "machine"}
        rows = [
            {"case": k, **v} if isinstance(v, dict) else {"case": k, "value": v}
            for k, v in body.items()
        ]
        out += _rows_table(_flatten_rows(rows))
    elif isinstance(data, dict):
        out += ["| key | value |", "|---|---|"]
        out += [f"| {k} | {_fmt(v)[:200]} |" for k, v in data.items() if k != "spec"]
    return out + [""]


def _flatten_rows(rows):
    flat = []
    for r in rows:
        f = {}
        for k, v in r.items():
            if isinstance(v, dict):
                for k2, v2 in v.items():
                    f[f"{k}.{k2}"] = v2
            else:
                f[k] = v
        flat.append(f)
    return flat


def benchmark_tables() -> str:
    files = sorted((ROOT / "benchmarks" / "results").glob("*.json"))
    current = [p for p in files if HISTORY_SUFFIX not in p.stem]
    history = [p for p in files if HISTORY_SUFFIX in p.stem]
    out = ["## Every result file", ""]
    for p in current:
        out += _result_section(p)
    out += ["## Appendix: history", "", "Earlier measurements kept for comparison.", ""]
    for p in history:
        out += _result_section(p)
    return "\n".join(out)


# ------------------------------------------------------------------------------ config reference


def _shared_fields() -> dict[str, set[str]]:
    """Keys of the shared sections (``vcjax.config.schema()``: section -> {"doc", "keys"})."""
    from vcjax.config import schema

    return {sec: set(spec["keys"]) for sec, spec in schema().items()}


def _command_table(title: str, sections: dict, docs: dict, shared: dict) -> list[str]:
    """Tables of a command's own keys: ``sections`` maps section -> {key: default or ...}."""
    out = [f"### `{title}`", ""]
    for sec, keys in sections.items():
        own = {k: d for k, d in keys.items() if k not in shared.get(sec, set())}
        if not own:
            out += [f"`[{sec}]`: the shared section above.", ""]
            continue
        note = " (and the shared keys above)" if sec in shared else ""
        out += [
            f"`[{sec}]`{note}",
            "",
            "| key | default | unit | description |",
            "|---|---|---|---|",
        ]
        for key, default in own.items():
            unit, desc = docs[(sec, key)]
            from vcjax.config.reference import toml_literal

            shown = "required" if default is ... else f"`{toml_literal(default)}`"
            out.append(f"| {key} | {shown} | {unit} | {desc} |")
        out.append("")
    return out


def command_sections() -> dict[str, dict[str, dict]]:
    """Each command's sections and keys with defaults, read from the parsers' own schemas."""
    from tuning.config import DEFAULTS as TUNE
    from vcjax.identify.config import FIT_SCHEMA
    from vcjax.sweep import SweepSpec
    from vcjax.sweep.config import SCHEMA as SWEEP

    spec = SweepSpec.__dataclass_fields__
    sweep = {s: {k: _spec_default(spec, k) for k in keys} for s, keys in SWEEP.items() if keys}
    sweep["sweep"]["num_scenarios"] = ...
    from vcjax.search.config import FALSIFY_KEYS

    return {
        "vcjax sweep": sweep,
        "vcjax falsify": {"falsify": dict(FALSIFY_KEYS)},
        "vcjax tune": TUNE,
        "vcjax fit": FIT_SCHEMA,
    }


def _spec_default(fields, name):
    """Default of a SweepSpec field (``None``: not a field, or set per loop)."""
    import dataclasses

    f = fields.get(name)
    if f is None:
        return None
    if f.default is not dataclasses.MISSING:
        return f.default
    return None


def config_reference() -> str:
    from tuning.config import KEY_DOCS as TUNE_DOCS
    from vcjax.config import reference_markdown
    from vcjax.identify.config import KEY_DOCS as FIT_DOCS
    from vcjax.search.config import KEY_DOCS as FALSIFY_DOCS
    from vcjax.sweep.config import KEY_DOCS as SWEEP_DOCS

    shared = _shared_fields()
    docs = {
        "vcjax sweep": SWEEP_DOCS,
        "vcjax falsify": FALSIFY_DOCS,
        "vcjax tune": TUNE_DOCS,
        "vcjax fit": FIT_DOCS,
    }
    out = ["## Shared sections", "", reference_markdown(), "", "## Each command's own keys", ""]
    for cmd, sections in command_sections().items():
        out += _command_table(cmd, sections, docs[cmd], shared)
    return "\n".join(out)


# ------------------------------------------------------------------------------ CLI reference


def _md_cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _option_rows(parser) -> list[str]:
    import argparse

    rows = ["| option | meaning | default |", "|---|---|---|"]
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        if action.help == argparse.SUPPRESS:
            continue
        if action.option_strings:
            names = ", ".join(action.option_strings)
            takes = action.nargs != 0
            meta = action.metavar or (action.dest.upper() if takes else "")
            if isinstance(meta, tuple):
                meta = " ".join(meta)
            elif takes and isinstance(action.nargs, int) and action.nargs > 1:
                meta = " ".join([meta] * action.nargs)
            flag = f"`{names} {meta}`" if takes and meta else f"`{names}`"
        else:
            flag = f"`{action.metavar or action.dest.upper()}`"
        default = action.default
        if isinstance(default, (list, tuple)):
            default = " ".join(map(str, default))
        shown = (
            ""
            if default in (None, False, argparse.SUPPRESS) or action.nargs == 0
            else f"`{default}`"
        )
        help_text = (action.help or "") % {"default": default} if action.help else ""
        if action.choices and not isinstance(action.choices, dict):
            help_text += f" (one of: {', '.join(f'`{c}`' for c in action.choices)})"
        rows.append(f"| {flag} | {_md_cell(help_text)} | {shown} |")
    return rows


def _subcommands(parser, prefix: str):
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                yield f"{prefix} {name}", helps.get(name), sub
                yield from _subcommands(sub, f"{prefix} {name}")


def cli_reference() -> str:
    """Every command and option of ``vcjax``, generated from its argument parser
    (:func:`vcjax.cli.build_parser`): what ``vcjax COMMAND --help`` prints, as tables."""
    from vcjax.cli import build_parser

    out = []
    for name, help_text, sub in _subcommands(build_parser(), "vcjax"):
        depth = name.count(" ")
        out += [f"{'#' * min(depth + 2, 4)} `{name}`", ""]
        if help_text or sub.description:
            out += [_md_cell(sub.description or help_text), ""]
        out += [f"```text\n{sub.format_usage().strip()}\n```", ""]
        rows = _option_rows(sub)
        if len(rows) > 2:
            out += rows + [""]
    return "\n".join(out)


MARKERS = {
    "<!-- vcjax:cli-reference -->": cli_reference,
    "<!-- vcjax:benchmark-tables -->": benchmark_tables,
    "<!-- vcjax:config-reference -->": config_reference,
}


def on_page_markdown(markdown, page, config, files):
    for marker, make in MARKERS.items():
        if marker in markdown:
            markdown = markdown.replace(marker, make())
    return markdown
