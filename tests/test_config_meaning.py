"""One bound per value and no silent change of meaning (issue: reliability round 3): seeds are
checked against the range the sampler uses, through the CLI and the Python API; a default means
the same written or omitted; old and new spellings that disagree are refused naming both; a key
that does not apply is refused; a gains file is refused for another vehicle or controller."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vcjax import cli
from vcjax.config import SEED_MAX, ConfigError, as_seed


def _run(argv, capsys) -> tuple[int, str]:
    rc = cli.main(argv)
    return rc, capsys.readouterr().err


# ------------------------------------------------------------------ seeds


@pytest.mark.parametrize("seed", [-1, 2**32, 2**63 - 1, 2**63])
def test_seed_outside_the_sampler_range_is_refused_by_the_python_api(seed):
    from tuning.scenarios import sample_scenarios as tune_samples
    from vcjax.sweep import ScenarioSpec, SweepSpec, sample_scenarios

    msg = f"seed: {seed} is outside the seed range 0 .. {SEED_MAX}"
    with pytest.raises(ConfigError, match=msg):
        SweepSpec(num_scenarios=1, seed=seed)
    with pytest.raises(ConfigError, match=msg):
        sample_scenarios(ScenarioSpec(), seed, np.arange(1))
    with pytest.raises(ValueError, match=msg):
        tune_samples(seed, 1)


@pytest.mark.parametrize("v", [True, 1.0, "3", None])
def test_seed_must_be_an_integer(v):
    with pytest.raises(ConfigError, match="x: expected an integer seed"):
        as_seed("x", v)


def test_seed_bound_is_the_sampler_key_type():
    """SEED_MAX is the largest uint32 (what the sampler's key is built from), accepted; one more
    does not fit the key type at all."""
    import jax.numpy as jnp

    assert as_seed("s", SEED_MAX) == SEED_MAX == int(jnp.iinfo(jnp.uint32).max)
    assert as_seed("s", np.int64(7)) == 7
    assert SEED_MAX + 1 > int(np.iinfo(np.uint32).max)


# ------------------------------------------------------------------ written == omitted


def _tune_base():
    return {"problem": {"horizon": 1.0, "dt": 0.5}, "train": {"size": 4}, "heldout": {"size": 3}}


def test_tune_current_model_written_as_its_default_changes_nothing():
    """[current] model = "constant" (the default) used to switch the current from U(0, 1) m/s in
    any direction to 0.5 m/s towards 90 deg, run.json still recording current_max."""
    from tuning.config import validate_config
    from tuning.run import build

    omitted = validate_config(_tune_base())
    written = validate_config({**_tune_base(), "current": {"model": "constant"}})
    assert omitted == written
    assert (written.current.speed, written.current.direction_deg) == ((0.0, 1.0), (0.0, 360.0))
    a, b = build(omitted), build(written)
    for x, y in zip(a[3:], b[3:], strict=True):  # training and held-out batches
        np.testing.assert_array_equal(x.current, y.current)
    speeds = np.hypot(np.asarray(b[3].current)[:, 0], np.asarray(b[3].current)[:, 1])
    assert np.all(speeds <= 1.0) and np.ptp(speeds) > 0  # U(0, 1), not the fixed 0.5 m/s


def test_tune_records_the_current_that_runs():
    from tuning.config import validate_config

    cfg = validate_config({**_tune_base(), "scenarios": {"current_max": 0.7}})
    d = json.loads(json.dumps(cfg.to_dict()))  # what run.json records
    assert d["current"]["speed"] == [0.0, 0.7] and d["current"]["direction_deg"] == [0.0, 360.0]
    cfg = validate_config({**_tune_base(), "current": {"speed": 0.2}})
    cur = cfg.to_dict()["current"]
    assert cur["speed"] == [0.2, 0.2] and cur["direction_deg"] == [90.0, 90.0]


# ------------------------------------------------------------------ keys that do not apply


@pytest.mark.parametrize("key, value", [("sigma", 0.1), ("tau", 50.0), ("max_speed", 1.0)])
def test_gauss_markov_key_with_a_constant_current_is_refused(key, value, tmp_path, capsys):
    from tuning.config import validate_config

    msg = rf"\[current\] {key}: applies to model = 'gauss_markov' only"
    with pytest.raises(ConfigError, match=msg):
        validate_config({"current": {key: value}})
    f = tmp_path / "s.toml"
    f.write_text(f"[sweep]\nnum_scenarios = 2\n[current]\n{key} = {value}\n")
    rc, err = _run(["sweep", str(f), "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and f"[current] {key}: applies to model = 'gauss_markov' only" in err
    f.write_text(
        f"[sweep]\nnum_scenarios = 2\n[current]\nmodel = 'gauss_markov'\n{key} = {value}\n"
    )
    from vcjax.sweep import load_config

    assert load_config(f)[0].scenario.current_model == "gauss_markov"  # applies: accepted


WAVES = "[scenario]\nvehicle = 'remus100'\n[sweep]\nnum_scenarios = 2\n[current]\nspeed = 0.0\n"


@pytest.mark.parametrize(
    "waves, message",
    [
        ("spectrum = 'pm'\ngamma = 2.0", "[waves] gamma: the peak enhancement of the JONSWAP"),
        ("spreading = 1e-12", "[waves] spreading: 0 is long-crested (one direction)"),
        ("spreading = 0.5", "[waves] spreading: 0 is long-crested (one direction)"),
    ],
)
def test_waves_key_that_does_not_apply_is_refused(waves, message, tmp_path, capsys):
    f = tmp_path / "s.toml"
    f.write_text(f"{WAVES}[waves]\nhs = 1.0\ntp = 8.0\n{waves}\n")
    rc, err = _run(["sweep", str(f), "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and message in err and "Traceback" not in err


def test_waves_keys_that_apply_are_accepted(tmp_path):
    from vcjax.sweep import load_config

    f = tmp_path / "s.toml"
    for extra, check in (
        ("spreading = 1.0", lambda sc: sc.wave_spreading == 1.0),
        ("spreading = 0.0", lambda sc: sc.wave_spreading == 0.0),
        ("spectrum = 'pm'", lambda sc: sc.wave_spectrum == "pm"),
        ("gamma = 2.0", lambda sc: sc.wave_gamma == 2.0),
    ):
        f.write_text(f"{WAVES}[waves]\nhs = 1.0\ntp = 8.0\n{extra}\n")
        assert check(load_config(f)[0].scenario)


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"wave_hs": (1.0, 2.0)}, "wave_hs: given without wave_spectrum"),
        (
            {"wave_spectrum": "pm", "wave_gamma": 2.0},
            r"\[waves\] gamma: the peak enhancement of the JONSWAP",
        ),
        ({"wave_spectrum": "jonswap", "wave_spreading": 1e-12}, r"\[waves\] spreading: 0 is long"),
        ({"current_sigma": 0.2}, r"\[current\] sigma: applies to model = 'gauss_markov'"),
    ],
)
def test_scenario_spec_refuses_a_field_that_does_not_apply(kw, message):
    from vcjax.sweep import ScenarioSpec

    with pytest.raises(ConfigError, match=message):
        ScenarioSpec(**kw)


def test_without_waves_is_calm():
    from vcjax.sweep import ScenarioSpec

    sea = ScenarioSpec(wave_spectrum="jonswap", wave_hs=(1.0, 2.0), wave_components=8)
    assert sea.without_waves() == ScenarioSpec()


# ------------------------------------------------------------------ conflicting spellings


SWEEP = "[sweep]\nnum_scenarios = 2\n"


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "[scenario]\ncontroller = 'vcm'\n[sweep]\nnum_scenarios = 2\nvariants = ['ilos']\n",
            "[sweep] variants: ['ilos'] contradicts [scenario] controller 'vcm'",
        ),
        (
            "[scenario]\nedd = 'implied'\n[simulation]\nedd = 'paper'\n" + SWEEP,
            "[simulation] edd: 'paper' contradicts [scenario] edd 'implied'",
        ),
    ],
)
def test_sweep_conflicting_spellings_are_refused_naming_both(text, message, tmp_path, capsys):
    f = tmp_path / "s.toml"
    f.write_text(text)
    import warnings

    from vcjax.config import ConfigNote

    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        rc, err = _run(["sweep", str(f), "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and message in err
    assert not [w for w in rec if w.category is ConfigNote]  # the refusal alone, no note


def test_sweep_records_the_edd_that_runs(tmp_path):
    from vcjax.sweep import load_config
    from vcjax.sweep.spec import spec_to_dict

    f = tmp_path / "s.toml"
    f.write_text("[scenario]\nedd = 'implied'\n" + SWEEP)
    spec = load_config(f)[0]
    assert dict(spec.choice.options)["edd"] == "implied" == spec_to_dict(spec)["edd"]
    assert spec.loop("vcm").edd == "implied"
    f.write_text("[scenario]\nedd = 'implied'\n[simulation]\nedd = 'implied'\n" + SWEEP)
    assert load_config(f)[0].loop("vcm").edd == "implied"  # both spellings, same value
    f.write_text("[simulation]\nedd = 'implied'\n" + SWEEP)  # the older spelling alone
    assert load_config(f)[0].loop("vcm").edd == "implied"
    f.write_text("[scenario]\ncontroller = 'vcm'\n[sweep]\nnum_scenarios = 2\nvariants = ['vcm']\n")
    assert load_config(f)[0].variants == ("vcm",)


@pytest.mark.parametrize("old", ["problem", "simulation"])
def test_tune_edd_spellings_conflict_or_record_what_runs(old):
    from tuning.config import validate_config

    with pytest.raises(ConfigError, match=rf"\[{old}\] edd: 'paper' contradicts \[scenario\] edd"):
        validate_config({"scenario": {"edd": "implied"}, old: {"edd": "paper"}})
    cfg = validate_config({"scenario": {"edd": "implied"}})
    assert dict(cfg.scenario.options)["edd"] == "implied"
    cfg = validate_config({old: {"edd": "implied"}})  # the older spelling alone
    assert dict(cfg.scenario.options)["edd"] == "implied"
    assert dict(validate_config({}).scenario.options)["edd"] == "paper"  # run.json: what ran


# ------------------------------------------------------------------ gains files


def _same(a, b) -> bool:
    import jax

    return all(
        np.array_equal(x, y)
        for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True)
    )


def test_gains_file_records_its_vehicle_and_is_refused_for_another(tmp_path, capsys):
    """INFANTE gains on sim2 (ODIN) used to drive it; now refused naming both."""
    from vcjax import loops

    infante = loops.make_loop("infante", "vcm_integral")
    d = infante.gains_to_json(infante.default_gains())
    assert d["vehicle"] == "infante" and d["controller"] == "vcm_integral"
    back = infante.gains_from_json(json.loads(json.dumps(d)))  # round trip
    assert _same(back, infante.default_gains())
    odin = loops.make_loop("odin", loops.loop_class("odin").controllers[0])
    with pytest.raises(ValueError, match="gains of vehicle 'infante'.*not of 'odin'"):
        odin.gains_from_json(d)
    with pytest.raises(ValueError, match="controller 'alos3d'"):
        infante.gains_from_json({**d, "controller": "alos3d"})
    # an older file without the two keys still loads
    old = {k: v for k, v in d.items() if k not in ("vehicle", "controller")}
    assert _same(infante.gains_from_json(old), back)
    f = tmp_path / "gains.json"
    f.write_text(json.dumps(d))
    rc, err = _run(["simulate", "sim2", "--gains", str(f), "--out", str(tmp_path / "o")], capsys)
    assert rc == 2 and "gains of vehicle 'infante'" in err and "Traceback" not in err


# ------------------------------------------------------------------ changed meaning


def test_engine_loop_sweep_without_current_says_its_meaning_changed(tmp_path):
    """8ff09b6's puck sweep ran in still water (the engine felt no current); the engine now
    feels the default 0.5 m/s current: the sweep says so, and [current] silences it."""
    from pathlib import Path

    from vcjax.config import ConfigNote
    from vcjax.sweep import load_config

    module = Path(__file__).resolve().parents[1] / "examples" / "loops" / "puck.py"
    f = tmp_path / "puck.toml"
    text = f"[scenario]\nmodule = '{module}'\nvehicle = 'puck'\n[sweep]\nnum_scenarios = 2\n"
    f.write_text(text)
    with pytest.warns(ConfigNote, match=r"\[current\] speed not given: the puck scenarios run in"):
        spec = load_config(f)[0]
    assert spec.scenario.current_speed == (0.5, 0.5)  # numbers unchanged (committed figure)
    import warnings

    for current in ("speed = 0.0", "speed = 0.5\ndirection_deg = 90.0"):
        f.write_text(f"{text}[current]\n{current}\n")
        with warnings.catch_warnings():
            warnings.simplefilter("error", ConfigNote)
            assert load_config(f)[0].scenario.current_speed[0] == float(current.split()[2])


def test_unknown_key_suggests_the_closest():
    from vcjax import config

    with pytest.raises(ConfigError, match=r"\[current\] sped: unknown key \(did you mean 'speed'"):
        config.parse_section(config.Current, {"sped": 1.0}, "current")


def test_empty_model_error_fields_is_refused_in_sweep_and_tune(tmp_path):
    """`fields = []` meant the default set in tune and no field at all in sweep; omitting the
    key (the default set) is the one way to say the default."""
    from tuning.config import validate_config
    from vcjax.sweep import load_config

    with pytest.raises(ConfigError, match=r"\[model_error\] fields: an empty list"):
        validate_config({"model_error": {"relative": 0.1, "fields": []}})
    f = tmp_path / "s.toml"
    f.write_text("[sweep]\nnum_scenarios = 2\n[model_error]\nrelative = 0.1\nfields = []\n")
    with pytest.raises(ConfigError, match=r"\[model_error\] fields: an empty list"):
        load_config(f)
    f.write_text("[sweep]\nnum_scenarios = 2\n[model_error]\nrelative = 0.1\n")
    spec = load_config(f)[0]
    loop = spec.loop("vcm")
    assert spec.scenario.fields_for(loop) == loop.default_model_fields()


def test_current_model_written_as_its_default_on_a_loop_without_currents(tmp_path):
    """The arm feels no current: omitted [current] ran in still water, while writing the
    default model = "constant" switched on the 0.5 m/s default and was refused."""
    from vcjax.sweep import load_config

    f = tmp_path / "s.toml"
    base = "[scenario]\nvehicle = 'arm'\n[sweep]\nnum_scenarios = 2\n"
    f.write_text(base)
    omitted = load_config(f)[0]
    f.write_text(base + "[current]\nmodel = 'constant'\n")
    assert load_config(f)[0] == omitted
    assert omitted.scenario.current_speed == (0.0, 0.0)
