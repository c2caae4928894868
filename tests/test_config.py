"""The shared configuration system (vcjax.config): schema metadata, older spellings as aliases of
the shared keys (same parsed values, same sampled scenarios), loop options read from the loop
class, one error per bad key naming section and key."""

import dataclasses
import json

import numpy as np
import pytest

from tuning.config import validate_config
from vcjax import config, loops
from vcjax.config import ConfigError
from vcjax.config.scenario import ScenarioChoice, parse_scenario
from vcjax.sweep import load_config


def test_schema_lists_every_shared_section_with_metadata():
    s = config.schema()
    assert set(s) == {
        "scenario",
        "simulation",
        "current",
        "waves",
        "initial",
        "model_error",
        "sensor_noise",
        "disturbance",
    }
    for name, sec in s.items():
        assert sec["doc"], name
        for key, meta in sec["keys"].items():
            assert {"type", "unit", "doc", "default"} <= set(meta), (name, key)
            assert meta["doc"], (name, key)
    sim = s["simulation"]["keys"]
    assert sim["horizon"]["unit"] == "s" and "[problem] horizon" in sim["horizon"]["aliases"]
    assert s["current"]["keys"]["speed"]["aliases"] == ("[scenarios] current_max",)
    # the default scenario is declared once and is what a config without [scenario] means
    assert ScenarioChoice().vehicle == config.DEFAULT_SCENARIO["vehicle"] == "infante"
    assert parse_scenario(None, "x", "x.toml") == ScenarioChoice()


def test_parse_section_checks_types_and_names_the_key():
    cur = config.parse_section(config.Current, {"speed": [0.1, 0.3]}, "current", "f.toml")
    assert cur.speed == (0.1, 0.3) and cur.direction_deg == (90.0, 90.0)
    assert dataclasses.is_dataclass(cur)
    with pytest.raises(dataclasses.FrozenInstanceError):
        cur.speed = (0.0, 0.0)
    with pytest.raises(ConfigError, match=r"f.toml: \[current\] speed: values must be >= 0"):
        config.parse_section(config.Current, {"speed": [-1.0, 0.3]}, "current", "f.toml")
    with pytest.raises(ConfigError, match=r"\[current\] sped: unknown key"):
        config.parse_section(config.Current, {"sped": 1.0}, "current", "f.toml")
    with pytest.raises(ConfigError, match=r"\[simulation\] timing: expected one of"):
        config.parse_section(config.Simulation, {"timing": "often"}, "simulation")


def test_tune_simulation_section_equals_problem_spelling():
    old = validate_config({"problem": {"horizon": 4.0, "dt": 0.2, "timing": "sampled"}})
    new = validate_config({"simulation": {"horizon": 4.0, "dt": 0.2, "timing": "sampled"}})
    assert old["problem"] == new["problem"]
    with pytest.raises(ConfigError, match=r"\[simulation\] dt: also given as \[problem\] dt"):
        validate_config({"simulation": {"dt": 0.2}, "problem": {"dt": 0.1}})
    with pytest.raises(ConfigError, match="current_max, not both"):
        validate_config({"current": {"speed": 1.0}, "scenarios": {"current_max": 1.0}})
    with pytest.raises(ConfigError, match=r"\[current\] model"):
        validate_config({"current": {"model": "gauss_markov"}})


def test_tune_current_section_samples_the_current_max_scenarios():
    from tuning.run import build

    base = {"problem": {"horizon": 1.0, "dt": 0.5}, "train": {"size": 4}, "heldout": {"size": 3}}
    old = build(validate_config({**base, "scenarios": {"current_max": 0.7}}))
    new = build(
        validate_config({**base, "current": {"speed": [0.0, 0.7], "direction_deg": [0, 360]}})
    )
    for a, b in zip(old[3:], new[3:], strict=True):  # train and held-out batches
        np.testing.assert_array_equal(a.current, b.current)
        np.testing.assert_array_equal(a.eta0, b.eta0)
    other = build(validate_config({**base, "current": {"speed": 0.3}}))
    assert not np.array_equal(other[3].current, old[3].current)


def test_scenario_options_come_from_the_loop_dataclass(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text(
        '[scenario]\nvehicle = "odin"\ncontroller = "vcm"\npolish = 7\nintegral = false\n'
        "[sweep]\nnum_scenarios = 2\n"
    )
    spec, _ = load_config(f)
    loop = spec.loop("vcm")
    assert loop.polish == 7 and loop.integral is False
    assert isinstance(loop, loops.loop_class("odin"))
    f.write_text('[scenario]\nvehicle = "odin"\npolish = "many"\n[sweep]\nnum_scenarios = 2\n')
    with pytest.raises(ConfigError, match=r"\[scenario\] polish: expected an integer"):
        load_config(f)
    f.write_text('[scenario]\nvehicle = "arm"\nedd = "paper"\n[sweep]\nnum_scenarios = 2\n')
    with pytest.raises(ConfigError, match=r"\[scenario\] edd: not an option of the arm loop"):
        load_config(f)
    f.write_text('[scenario]\nvehicle = "arm"\nfoo = 1\n[sweep]\nnum_scenarios = 2\n')
    with pytest.raises(ConfigError, match=r"\[scenario\] foo: unknown key"):
        load_config(f)


def test_sweep_refuses_smooth_plant(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text("[simulation]\nsmooth = true\n[sweep]\nnum_scenarios = 2\n")
    with pytest.raises(ConfigError, match=r"s.toml: \[simulation\] smooth: a sweep simulates"):
        load_config(f)
    f.write_text("[simulation]\nsmooth = false\nu_d = [1.0, 1.2]\n[sweep]\nnum_scenarios = 2\n")
    spec, _ = load_config(f)
    assert spec.scenario.u_d == (1.0, 1.2)


def test_reference_markdown_has_one_row_per_key():
    md = config.reference_markdown()
    for name, sec in config.schema().items():
        assert f"### [{name}]" in md
        rows = [ln for ln in md.split(f"### [{name}]")[1].split("###")[0].splitlines()]
        assert len([r for r in rows if r.startswith("| ") and not r.startswith("| key")]) == len(
            sec["keys"]
        )
    assert "| horizon | float | `(none)` | s |" in md and "[problem] horizon" in md


def test_tune_simulation_u_d_reaches_the_scenarios():
    from tuning.run import build

    base = {"problem": {"horizon": 1.0, "dt": 0.5}, "train": {"size": 3}, "heldout": {"size": 2}}
    train = build(validate_config({**base, "simulation": {"u_d": 1.25}}))[3]
    np.testing.assert_array_equal(np.asarray(train.u_d), 1.25)
    default = build(validate_config(base))[3]
    assert not np.any(np.asarray(default.u_d) == 1.25)


# ------------------------------------------------------------------ tune and fit: frozen objects


def test_tune_config_is_frozen_hashable_and_reads_as_before():
    from tuning.spec import TuneConfig

    cfg = validate_config(
        {
            "problem": {"tune": ["P_G", "sigma"], "horizon": 4.0, "dt": 0.2},
            "initial": {"x": [0.0, 1.0]},
            "disturbance": {"force": [[0.0, 1.0], [-2.0, 2.0], 0.0]},
            "current": {"speed": [0.0, 0.3]},
        }
    )
    assert isinstance(cfg, TuneConfig) and hash(cfg) == hash(TuneConfig.from_dict(cfg.to_dict()))
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.problem.horizon = 8.0
    # attribute and mapping reads agree; lists are stored as tuples
    assert cfg.problem.tune == ("P_G", "sigma") and cfg["problem"]["tune"] == ("P_G", "sigma")
    assert cfg.disturbance.force == ((0.0, 1.0), (-2.0, 2.0), (0.0, 0.0))
    assert {**cfg["weights"]} == dict(cfg.weights.to_dict())
    # the older dict form: [scenario], [initial], [current] as plain dicts, defaults filled in
    assert cfg["scenario"]["vehicle"] == "infante" and cfg.scenario.vehicle == "infante"
    assert cfg["initial"] == {"x": [0.0, 1.0]} and cfg["current"]["speed"] == [0.0, 0.3]
    assert cfg["current"]["direction_deg"] == [90.0, 90.0]  # run.json records what runs
    d = json.loads(json.dumps(cfg.to_dict()))  # what run.json records
    assert d["problem"]["tune"] == ["P_G", "sigma"] and d["simulation"] == {"u_d": None}
    assert TuneConfig.from_dict(d) == cfg
    # the older [problem] spelling and the shared [simulation] give the same object
    old = validate_config({"problem": {"horizon": 4.0, "dt": 0.2, "timing": "sampled"}})
    new = validate_config({"simulation": {"horizon": 4.0, "dt": 0.2, "timing": "sampled"}})
    assert old == new and hash(old) == hash(new)


def test_tune_config_files_resolve_initial_gains_next_to_the_config(tmp_path):
    from tuning.config import load_config as load_tune

    (tmp_path / "sub").mkdir()
    f = tmp_path / "sub" / "t.toml"
    f.write_text('[problem]\ninitial_gains = "g.json"\nhorizon = 1.0\ndt = 0.5\n')
    cfg = load_tune(f)
    assert cfg.problem.initial_gains == str(tmp_path / "sub" / "g.json")


def test_fit_config_is_frozen_hashable_and_round_trips(tmp_path):
    from vcjax.identify import load_fit_config
    from vcjax.identify.config import FitConfig

    f = tmp_path / "fit.toml"
    f.write_text(
        '[data]\nfiles = ["a.csv"]\n[model]\nvehicle = "infante"\n'
        '[fit]\nparams = ["X_uu", "N_ur"]\nsegment_steps = 25\n'
    )
    cfg = load_fit_config(f)
    assert isinstance(cfg, FitConfig) and cfg.path == f and hash(cfg)
    assert cfg.fit.params == ("X_uu", "N_ur") and cfg["fit"]["segment_steps"] == 25
    assert cfg.model.step == "rk4" and cfg["model"]["current_speed"] == 0.0  # defaults
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.fit.max_iters = 3
    d = json.loads(json.dumps(cfg.to_dict()))
    assert set(d) == {"data", "model", "fit"} and d["data"]["files"] == ["a.csv"]
    assert FitConfig.from_dict(d) == dataclasses.replace(cfg, path=FitConfig().path)


def test_the_reference_prints_defaults_as_toml():
    """Defaults in the configuration reference are what a config file would write (TOML
    literals), never Python's spelling."""
    import re

    from vcjax.config.reference import reference_markdown, toml_literal

    assert toml_literal(True) == "true" and toml_literal(False) == "false"
    assert toml_literal((0.5, 0.5)) == "[0.5, 0.5]" and toml_literal("pm") == '"pm"'
    assert toml_literal(None) == "(none)" and toml_literal(3) == "3"
    cells = re.findall(r"^\| [^|]+ \| [^|]+ \| `([^`]*)` \|", reference_markdown(), flags=re.M)
    assert cells
    for cell in cells:
        assert not re.search(r"\b(True|False|None)\b|\(\d|'", cell), cell
