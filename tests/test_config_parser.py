"""The one parser (vcjax.config): every command's sections declared once with their types and
bounds and checked by one validator; one error format ``[section] key: message`` with the
closest valid key suggested; older spellings through one alias table, each with a one-line
note naming the new spelling."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import pytest

from vcjax.config import ConfigError, ConfigNote, closest
from vcjax.config.aliases import ALIASES, note_old_spellings

ROOT = Path(__file__).resolve().parents[1]


def test_alias_table_names_each_old_spelling_once_with_its_new_one():
    assert ALIASES["[problem] horizon"] == "[simulation] horizon"
    assert ALIASES["[problem] variant"] == "[scenario] controller"
    assert ALIASES["[simulation] edd"] == ALIASES["[problem] edd"] == "[scenario] edd"
    # shorthands, not renames: no note
    assert "[sweep] variants" not in ALIASES and "[scenarios] current_max" not in ALIASES
    for old, new in ALIASES.items():
        assert old != new and old.startswith("[") and new.startswith("[")


def test_old_spelling_gives_one_note_line_naming_the_new(tmp_path):
    from tuning.config import load_config

    f = tmp_path / "t.toml"
    f.write_text("[problem]\nhorizon = 2.0\ndt = 0.5\nvariant = 'vcm'\n")
    with pytest.warns(ConfigNote) as rec:
        cfg = load_config(f)
    msgs = [str(w.message) for w in rec]
    assert any(
        f"{f}: [problem] horizon is an older spelling of [simulation] horizon" in m for m in msgs
    )
    assert any("[problem] variant is an older spelling of [scenario] controller" in m for m in msgs)
    assert len(msgs) == 3 and cfg.problem.horizon == 2.0
    line = warnings.formatwarning(rec[0].message, ConfigNote, "x.py", 1)
    assert line == f"vcjax: note: {msgs[0]}\n"  # one line, no source location
    new = tmp_path / "n.toml"
    new.write_text("[simulation]\nhorizon = 2.0\ndt = 0.5\n[scenario]\ncontroller = 'vcm'\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConfigNote)
        assert load_config(new).to_dict() == cfg.to_dict()  # same config, no note


def test_note_old_spellings_lists_what_it_found():
    with pytest.warns(ConfigNote):
        found = note_old_spellings({"simulation": {"edd": "paper"}, "sweep": {}}, "f")
    assert found == ["[simulation] edd"]


@pytest.mark.parametrize("kind", ["sweeps", "tuning"])
def test_every_example_config_uses_the_current_spellings(kind):
    from tuning.config import load_config as load_tune
    from vcjax.sweep import load_config as load_sweep

    load = load_sweep if kind == "sweeps" else load_tune
    files = sorted((ROOT / "examples" / kind).glob("*.toml"))
    assert files
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConfigNote)
        for f in files:
            load(f)


@pytest.mark.parametrize(
    "raw, message",
    [
        ({"optimzer": {}}, r"unknown section \[optimzer\] \(did you mean 'optimizer'\?\)"),
        ({"train": {"sise": 3}}, r"\[train\] sise: unknown key \(did you mean 'size'\?\)"),
        ({"problem": {"horizon": 0}}, r"\[problem\] horizon: expected a value > 0"),
        ({"problem": {"risk": "max"}}, r"\[problem\] risk: expected one of \['mean', 'cvar'\]"),
        ({"problem": {"checkpoint_every": 0}}, r"\[problem\] checkpoint_every: .*>= 1"),
        ({"problem": {"tune": "P_G"}}, r"\[problem\] tune: expected a list of strings"),
        ({"problem": {"tune": ["P_G", "P_G"]}}, r"\[problem\] tune: duplicate names"),
        ({"weights": {"sat_width": 0.0}}, r"\[weights\] sat_width: expected a value > 0"),
        ({"scenarios": {"current_max": -1}}, r"\[scenarios\] current_max: expected a value >= 0"),
        ({"optimizer": {"grad_tol": -1e-3}}, r"\[optimizer\] grad_tol: expected a value >= 0"),
        ({"optimizer": {"learning_rate": 0}}, r"\[optimizer\] learning_rate: .*> 0"),
        ({"report": {"plot_scenarios": -1}}, r"\[report\] plot_scenarios: .*>= 0"),
        ({"heldout": {"seed": 1.5}}, r"\[heldout\] seed: expected an integer seed"),
        ({"model_error": {"fields": ["m", "m"]}}, r"\[model_error\] fields: duplicate names"),
        ({"model_error": {"relative": 1.0}}, r"\[model_error\] relative: expected a value < 1"),
        ({"disturbance": {"force": [[1.0, 0.0]]}}, r"\[disturbance\] force: expected finite lo"),
        ({"initial": {"xx": 1.0}}, r"\[initial\] xx: unknown key .*\(did you mean 'x'\?\)"),
        ({"simulation": {"dt": 2.0, "horizon": 1.0}}, r"\[simulation\] horizon: must be >= dt"),
        ({"simulation": {"edd": "both"}}, r"\[simulation\] edd: expected one of"),
        ({"waves": {"hs": 1.0, "tp": 1.0}}, r"\[waves\] tp: the shortest wave period"),
    ],
)
def test_tune_errors_have_one_format(raw, message):
    from tuning.config import validate_config

    with pytest.raises(ConfigError, match=message):
        validate_config(raw)


def test_tune_sections_reuse_the_shared_declarations():
    """tuning/spec declares no shared section again: [disturbance] and [model_error] are the
    classes of vcjax.config.schema, and every tune key's unit and description come from its
    declaration."""
    from tuning import spec
    from vcjax.config import Disturbance, ModelError

    assert spec.TuneConfig.__dataclass_fields__["disturbance"].type in ("Disturbance",)
    assert spec.ForceRanges is Disturbance and spec.PlantError is ModelError
    assert isinstance(spec.TuneConfig().model_error, ModelError)
    for (sec, key), (_unit, doc) in spec.KEY_DOCS.items():
        assert doc, (sec, key)
        assert key in spec.DEFAULTS[sec]
    assert spec.DEFAULTS["train"] == {"size": 16, "seed": 0}


def test_fit_config_goes_through_the_one_validator(tmp_path):
    from vcjax.identify.config import FIT_SCHEMA, FitOptions, load_fit_config

    assert FIT_SCHEMA["fit"]["params"] is ... and FIT_SCHEMA["fit"]["max_iters"] == 50
    meta = {f.name: f.metadata for f in dataclasses.fields(FitOptions)}
    assert meta["segment_steps"]["lo"] == 2
    log = tmp_path / "a.csv"
    log.write_text("t\n0\n")
    base = f'[data]\nfiles = ["{log}"]\n[model]\nvehicle = "remus100"\nstep = "pvs"\n'
    f = tmp_path / "f.toml"
    for fit, message in (
        (
            "params = ['CD_0']\nsegment_step = 3",
            r"\[fit\] segment_step: unknown key \(did you mean",
        ),
        ("params = ['CD_0', 'CD_0']", r"\[fit\] params: duplicate names"),
        ("params = ['CD_0']\nsegment_steps = 1", r"\[fit\] segment_steps: .*>= 2"),
        ("params = ['CD_0']\ninitial_scale = 0", r"\[fit\] initial_scale: expected a value > 0"),
        ("params = ['CD_0']\nfit_current = 1", r"\[fit\] fit_current: expected true or false"),
        ("max_iters = 3", r"\[fit\] params: required key is missing"),
    ):
        f.write_text(f"{base}[fit]\n{fit}\n")
        with pytest.raises(ConfigError, match=rf"{f}: .*{message}"):
            load_fit_config(f)


def test_closest_suggests_only_near_names():
    assert closest("horizn", ["horizon", "dt"]) == " (did you mean 'horizon'?)"
    assert closest("zzz", ["horizon", "dt"]) == ""


# ------------------------------------------------------------------ registered sections


@dataclasses.dataclass(frozen=True)
class Tidal:
    """``[tideline]``: a current that turns with the tide (a test's own section)."""

    from vcjax.config.schema import key as _key

    amplitude: float = _key(0.0, "float", "m/s", "tidal speed amplitude", lo=0.0)
    period: float = _key(44700.0, "float", "s", "tidal period", lo=0.0, lo_open=True)
    phase_deg: tuple = _key((0.0, 0.0), "range", "deg", "phase at t = 0")
    del _key


def _tidal_check(obj, table, name):
    if obj.amplitude == 0.0 and "phase_deg" in table:
        raise ConfigError(f"{name('phase_deg')}: no tide (amplitude 0) has no phase")


@pytest.fixture
def tidal():
    from vcjax.config.schema import CROSS_CHECKS, register_section
    from vcjax.environment import unregister

    register_section("tideline", Tidal, _tidal_check)
    try:
        yield
    finally:
        unregister("tideline")
        CROSS_CHECKS.pop(Tidal)


def test_registered_section_is_parsed_by_sweep_and_tune_and_listed(tidal, tmp_path):
    from tuning.config import validate_config
    from vcjax import config
    from vcjax.sweep import load_config

    f = tmp_path / "s.toml"
    f.write_text("[sweep]\nnum_scenarios = 2\n[tideline]\namplitude = 0.3\nphase_deg = [0, 90]\n")
    tide = load_config(f)[1]["sections"]["tideline"]
    assert tide == Tidal(amplitude=0.3, phase_deg=(0.0, 90.0))
    for text, message in (
        ("[tideline]\namplitud = 0.3\n", r"\[tideline\] amplitud: unknown key \(did you mean"),
        ("[tideline]\nperiod = 0\n", r"\[tideline\] period: expected a value > 0"),
        ("[tideline]\nphase_deg = 10\n", r"\[tideline\] phase_deg: no tide"),
    ):
        f.write_text("[sweep]\nnum_scenarios = 2\n" + text)
        with pytest.raises(ConfigError, match=message):
            load_config(f)
    validate_config({"tideline": {"amplitude": 0.1}})
    with pytest.raises(ConfigError, match=r"\[tideline\] amplitude: expected a value >= 0"):
        validate_config({"tideline": {"amplitude": -0.1}})
    assert config.schema()["tideline"]["keys"]["period"]["unit"] == "s"
    assert "### [tideline]" in config.reference_markdown()


def test_register_section_refusals(tidal):
    from vcjax.config import register_section

    with pytest.raises(ValueError, match=r"\[tideline\] is taken"):
        register_section("tideline", Tidal)
    with pytest.raises(ValueError, match=r"\[current\] is taken"):
        register_section("current", Tidal)
    with pytest.raises(ValueError, match="expected a section name"):
        register_section("a b", Tidal)

    @dataclasses.dataclass(frozen=True)
    class Bare:
        x: float = 1.0

    with pytest.raises(TypeError, match=r"\[bare\] x: declare it with key\(\)"):
        register_section("bare", Bare)
    with pytest.raises(TypeError, match="expected a dataclass"):
        register_section("bare", dict)
