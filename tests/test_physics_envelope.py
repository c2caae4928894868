"""Physics outside its validity, and work that cannot fit, said before any work (issue 31,
items 2, 4 and 7): a survey above the sea is refused naming the key; a sea beyond linear wave
theory is warned about; the sea's components are in the size estimate (refused when they cannot
fit, a wall-time warning when they are slow); a sea's keys without a spectrum are refused; a
metric that cannot be computed says why. CLI cases go through ``vcjax.cli.main`` (the user's
path) with ``tmp_path`` as ``--out``; none of them compiles a rollout: the run itself is replaced
by a sentinel where the warning comes before the work.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from scipy import integrate

from vcjax import cli, metrics
from vcjax.config import ConfigError
from vcjax.environment import waves
from vcjax.runtime import sizing
from vcjax.sweep import ScenarioSpec

ROOT = Path(__file__).resolve().parents[1]
SWEEP_WAVES = (ROOT / "examples" / "sweeps" / "remus100_waves.toml").read_text()
TUNE_WAVES = (ROOT / "examples" / "tuning" / "remus100_waves.toml").read_text()


def _edit(text: str, **keys) -> str:
    """``text`` with each ``key = ...`` line replaced by ``key = value`` (the first one)."""
    for k, v in keys.items():
        text, n = re.subn(rf"(?m)^{k} = .*$", f"{k} = {v}", text, count=1)
        assert n == 1, k
    return text


def _config(tmp_path, text, name="c.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def _run(argv, capsys):
    rc = cli.main([str(a) for a in argv])
    return rc, capsys.readouterr().err


class _Stop(Exception):
    """Raised in place of the run: what the command said before it is what is tested."""


def _no_run(*_args, **_kwargs):
    raise _Stop


# ------------------------------------------------------------------ item 4: validity envelope


def test_a_survey_above_the_sea_is_refused_naming_the_key(tmp_path, capsys):
    cfg = _config(tmp_path, _edit(SWEEP_WAVES, origin_depth="[-5.0, -5.0]"))
    out = tmp_path / "out"
    rc, err = _run(["sweep", cfg, "--out", out], capsys)
    assert rc == 2, err
    assert "[waves] origin_depth" in err and "above the mean free surface" in err, err
    assert "Traceback" not in err and err.count("\n") == 1
    assert not (out / "summary.json").exists()


def test_an_origin_above_the_sea_is_refused_by_the_api():
    with pytest.raises(
        ConfigError, match=r"\[waves\] origin_depth: -5 m puts the NED origin above"
    ):
        ScenarioSpec(wave_spectrum="jonswap", wave_hs=(1.0, 1.0), wave_origin_depth=(-5.0, 2.0))
    with pytest.raises(ValueError, match="origin_depth: -0.5 m"):
        waves.check_origin_depth((-0.5, 3.0))
    waves.check_origin_depth((0.0, 3.0))  # at the surface: allowed


def test_steepness_against_an_independent_evaluation():
    """Hs / lambda_p with lambda_p = g Tp^2 / (2 pi): Hs 15 m, Tp 5 s is 15 / 39.03 = 0.384,
    2.7 x Stokes' 1/7; Hs 5 m, Tp 6 s is 5 / 56.2 = 0.089 (past 1/14, not breaking); Hs 2 m, Tp 8 s is
    0.020 (linear)."""
    assert waves.peak_wavelength(5.0) == pytest.approx(9.81 * 25.0 / (2.0 * math.pi), rel=1e-12)
    (w,) = waves.envelope_warnings(15.0, 5.0)
    assert "steepness Hs/lambda_p = 0.384" in w and "2.7x steeper than breaking" in w, w
    (w,) = waves.envelope_warnings(5.0, 6.0)
    assert "= 0.089," in w and "past the 1/14 limit" in w, w
    assert waves.envelope_warnings(2.0, 8.0) == []
    # ranges: the steepest case (largest hs, shortest tp) is what counts
    assert waves.envelope_warnings((0.5, 15.0), (5.0, 12.0)) != []
    # the sweep example's corner (hs 3 m, tp 5 s: 0.0769) is past 1/14; the share of its
    # independently uniform (hs, tp) draws that are, integrated here in closed form:
    # hs > c tp^2 with c = g / (2 pi 14), i.e. tp < sqrt(hs / c), over [0.5, 3] x [5, 12]
    c = 9.81 / (2.0 * math.pi * 14.0)
    share = integrate.quad(lambda h: max(math.sqrt(h / c) - 5.0, 0.0), 25 * c, 3.0)[0] / 17.5
    (w,) = waves.envelope_warnings((0.5, 3.0), (5.0, 12.0), (2.0, 10.0))
    assert f"({100 * share:.2g} % of its sea states are past 1/14)" in w, (w, share)
    assert "0.0769" in w and "past the 1/14 limit" in w
    # just inside / outside 1/14
    lam = waves.peak_wavelength(8.0)
    assert waves.envelope_warnings(0.99 * lam / 14.0, 8.0) == []
    assert len(waves.envelope_warnings(1.01 * lam / 14.0, 8.0)) == 1


def test_a_vehicle_among_the_crests_is_warned_about():
    (w,) = waves.envelope_warnings(3.0, 10.0, origin_depth=(1.0, 6.0))
    assert "origin_depth 1 m is less than hs / 2 = 1.5 m" in w, w
    assert waves.envelope_warnings(3.0, 10.0, origin_depth=(1.5, 6.0)) == []


def test_a_sea_steeper_than_breaking_is_warned_before_the_sweep(tmp_path, capsys, monkeypatch):
    import vcjax.sweep

    monkeypatch.setattr(vcjax.sweep, "run_sweep_config", _no_run)
    cfg = _config(tmp_path, _edit(SWEEP_WAVES, hs="[15.0, 15.0]", tp="[5.0, 5.0]"))
    with pytest.raises(_Stop):
        cli.main(["sweep", str(cfg), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert "vcjax: warning:" in err and "2.7x steeper than breaking" in err, err


def test_simulate_warns_a_sea_beyond_linear_theory(tmp_path, capsys, monkeypatch):
    from vcjax.experiments import REMUS100

    monkeypatch.setattr(type(REMUS100), "run", lambda self, *a, **k: _no_run())
    with pytest.raises(_Stop):
        cli.main(["simulate", "remus100", "--waves", "15", "5", "90", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert "vcjax: warning: simulate remus100: --waves:" in err, err
    assert "2.7x steeper than breaking" in err


def test_wave_keys_without_a_spectrum_are_refused_not_run_calm():
    with pytest.raises(ConfigError, match=r"wave_hs: given without wave_spectrum.*calm"):
        ScenarioSpec(wave_hs=(1.0, 2.0))
    with pytest.raises(ConfigError, match="wave_components: given without wave_spectrum"):
        ScenarioSpec(wave_components=128)
    assert ScenarioSpec(wave_spectrum="pm", wave_hs=(1.0, 2.0)).waves
    assert not ScenarioSpec().waves  # no sea asked for: none


# ------------------------------------------------------------------ item 2: the sea's size


def test_ten_million_components_are_refused_with_the_estimate(tmp_path, capsys, monkeypatch):
    import vcjax.sweep

    # never the run itself, even if the estimate let it through (it grew to 23.6 GB before
    # the kernel killed it): a missed refusal fails here as _Stop
    monkeypatch.setattr(vcjax.sweep, "run_sweep_config", _no_run)
    cfg = _config(tmp_path, _edit(SWEEP_WAVES, components="10000000"))  # x 256 scenarios
    out = tmp_path / "out"
    rc, err = _run(["sweep", cfg, "--out", out], capsys)
    assert rc == 2, err
    # 256 scenarios x 1e7 components x 20 float64 = 410 GB, the sea named in the estimate
    assert "needs about 410 GB of memory" in err and "sea 410 GB" in err, err
    assert "--max-memory-gb" in err and "Traceback" not in err
    assert not (out / "summary.json").exists()


def test_the_sea_estimate_is_the_measured_bytes_per_component(tmp_path):
    """20 float64 per component and scenario of a chunk (sizing.WAVE_* : the sea's 5 arrays
    and 15 work arrays, measured), none without a sea; the chunk, not the whole study."""
    import dataclasses

    from vcjax.sweep import load_config

    text = _edit(SWEEP_WAVES, components="1000", num_scenarios="1000", chunk_size="100")
    spec, _ = load_config(_config(tmp_path, text))
    est = sizing.sweep_estimate(spec)
    assert est["parts"]["sea"] == 100 * 1000 * 20 * 8
    calm = dataclasses.replace(spec, scenario=spec.scenario.without_waves())
    assert "sea" not in sizing.sweep_estimate(calm)["parts"]
    assert est["memory_bytes"] == sizing.sweep_estimate(calm)["memory_bytes"] + 100 * 1000 * 160


def test_tune_counts_the_sea_on_its_gradient_tape(tmp_path):
    """Reverse mode keeps WAVE_TAPE_ARRAYS (N,) arrays per scenario, RK4 stage and stored step:
    one step's with the default per-step checkpointing (the backward pass recomputes each step),
    every step's with ``checkpoint = false``."""
    from tuning.config import load_config

    n, N = 400, 64  # 40 s / 0.1 s, 64 components
    for text, steps in (
        (TUNE_WAVES, 1),
        (TUNE_WAVES.replace("[problem]\n", "[problem]\ncheckpoint = false\n"), n),
    ):
        cfg = load_config(_config(tmp_path, text))
        est = sizing.tune_estimate(cfg)
        B, H = cfg["train"]["size"], cfg["heldout"]["size"]
        tape = B * steps * 4 * N * sizing.WAVE_TAPE_ARRAYS * 8
        seas = (B + H) * N * 5 * 8
        work = max(B, H) * N * sizing.WAVE_WORK_ARRAYS * 8
        assert est["parts"]["sea"] == tape + seas + work


def test_a_tune_with_ten_million_components_is_refused(tmp_path, capsys, monkeypatch):
    import tuning.run

    # never the run (see above); patched where ``tuning``'s lazy name finds it: patching
    # ``tuning.run_tune_config`` itself would bind the real function into ``tuning`` when the
    # patch is undone, and later tests' stubs of ``tuning.run`` would no longer be seen
    monkeypatch.setattr(tuning.run, "run_tune_config", _no_run)
    text = TUNE_WAVES.replace("[waves]\n", "[waves]\ncomponents = 10000000\n")
    cfg = _config(tmp_path, text)
    rc, err = _run(["tune", cfg, "--out", tmp_path / "out"], capsys)
    assert rc == 2, err
    assert "of memory" in err and "sea" in err and "Traceback" not in err, err


def test_a_million_components_warn_with_a_wall_time(tmp_path, capsys, monkeypatch):
    """1e6 components x 16 scenarios x 2400 steps x 2 variants x 4 stages x 20 ns = 102 min:
    said before the run starts (the run itself replaced here)."""
    import vcjax.sweep

    monkeypatch.setattr(vcjax.sweep, "run_sweep_config", _no_run)
    text = _edit(SWEEP_WAVES, components="1000000", num_scenarios="16", chunk_size="16")
    cfg = _config(tmp_path, text)
    with pytest.raises(_Stop):
        cli.main(["sweep", str(cfg), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    line = next(ln for ln in err.splitlines() if "components = 1000000" in ln)
    assert line.startswith("vcjax: warning:") and "about 102 min" in line, err
    assert "76800 scenario-steps" in line  # 16 x 2400 x 2


def test_the_wall_time_warning_threshold():
    est = sizing.Estimate(trajectory_steps=1000, wave_components=64)
    assert sizing.time_warnings(est, "x") == []  # 1000 x 4 x 64 x 20 ns = 5 ms
    n = int(sizing.WALL_WARN_S / (4 * 1000 * sizing.WAVE_SECONDS_PER_COMPONENT))
    assert (
        sizing.time_warnings(sizing.Estimate(trajectory_steps=1000, wave_components=n), "x") == []
    )
    warn = sizing.time_warnings(sizing.Estimate(trajectory_steps=1000, wave_components=3 * n), "x")
    assert len(warn) == 1 and "about 3 min" in warn[0]


# ------------------------------------------------------------------ item 4: nan metrics say why


class _Coeffs(NamedTuple):
    leg: float
    radius: float
    n_legs: int


def test_a_metric_that_cannot_be_computed_says_why():
    """The survey's steady-state metrics are taken on the straight legs after the first, 150 m
    past each turn (the mission's legs of 250 m, turns of radius 30 m: 250 + 94.2 + 150 = 494 m
    of path); a run that got 454 m in 300 s (the waves guide's command) has none, and says so
    with the horizon that would reach them (494 m at 454.3 m / 300 s: 326 s, rounded up to
    330 s)."""
    from vcjax.experiments.remus100 import undefined_reasons

    m = {
        "rms_dist_3d": 0.99,
        "max_dist_3d": 2.1,
        "ss_cross_track": math.nan,
        "ss_depth_err": math.nan,
        "ss_dist_3d": math.nan,
        "sat_fraction": 0.03,
        "healthy": True,
        "end_w": 454.3,
    }
    why = undefined_reasons(m, _Coeffs(250.0, 30.0, 4), 300.0)
    assert sorted(why) == ["ss_cross_track", "ss_depth_err", "ss_dist_3d"]
    r = why["ss_cross_track"]
    assert "horizon is too short to settle" in r and "454 m" in r and "494 m" in r, r
    assert "--horizon of about 330 s" in r
    # a run that did not finish the first leg: its distance metrics are nan too, said so
    short = dict(m, rms_dist_3d=math.nan, max_dist_3d=math.nan, end_w=120.0)
    r = undefined_reasons(short, _Coeffs(250.0, 30.0, 4), 80.0)["rms_dist_3d"]
    assert "the first leg (250 m) was not finished" in r and "about 170 s" in r, r
    m_ok = dict(m, ss_cross_track=0.1, ss_depth_err=0.1, ss_dist_3d=0.1)
    assert undefined_reasons(m_ok, _Coeffs(250.0, 30.0, 4), 900.0) == {}


def test_undefined_metrics_names_every_non_finite_value():
    got = metrics.undefined_metrics(
        {"a": 1.0, "b": math.nan, "c": None, "d": math.inf, "ok": True}, {"b": "why b"}, "other"
    )
    assert got == {"b": "why b", "c": "other", "d": "other"}


@pytest.mark.slow  # ~80 s: five REMUS 100 controllers compiled and run for 300 s
def test_the_waves_guide_command_says_why_its_metrics_are_nan(tmp_path, capsys):
    out = tmp_path / "out"
    rc = cli.main(["simulate", "remus100", "--waves", "2", "8", "90", "--horizon", "300",
                   "--out", str(out)])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 0, err
    notes = [ln for ln in err.splitlines() if ln.startswith("vcjax: note: remus100 ")]
    assert len(notes) == 5 and all("too short to settle" in n for n in notes), err
    doc = json.loads((out / "metrics.json").read_text())
    for v, u in doc["undefined"].items():
        assert doc["variants"][v]["ss_cross_track"] is None
        assert "too short to settle" in u["ss_cross_track"]


# ------------------------------------------------------------------ item 7: API shape checks


def _sea():
    import jax

    return waves.sea_state(jax.random.key(0), 1.0, 8.0, 0.0, components=4)


@pytest.mark.parametrize("shape", [(2,), (4,), (3, 1), ()])
def test_kinematics_refuse_a_point_that_is_not_3(shape):
    sea = _sea()
    p = np.ones(shape)
    for fn in (waves.orbital_velocity, waves.orbital_acceleration, waves.orbital_velocity_gradient):
        with pytest.raises(ValueError, match=r"p: expected a \(3,\) NED point"):
            fn(sea, 0.0, p)
    for fn in (waves.orbital_kinematics, waves.water_kinematics):
        with pytest.raises(ValueError, match=r"p_ned: expected a \(3,\) NED point"):
            fn(sea, 0.0, p)


def test_kinematics_refuse_a_bad_point_inside_jit_too():
    import jax

    sea = _sea()
    with pytest.raises(ValueError, match=r"got shape \(2,\)"):
        jax.jit(lambda p: waves.orbital_velocity(sea, 0.0, p))(np.ones(2))
    with pytest.raises(ValueError, match="current: expected a \\(3,\\) NED velocity"):
        waves.water_kinematics(sea, 0.0, np.ones(3), current=np.ones(2))
    with pytest.raises(ValueError, match="current_dot: expected a \\(3,\\) NED acceleration"):
        waves.water_kinematics(sea, 0.0, np.ones(3), np.zeros(3), current_dot=np.ones(2))
    u = waves.orbital_velocity(sea, 0.0, np.array([0.0, 0.0, 2.0]))
    assert u.shape == (3,)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(hs=np.ones(2)), "hs: expected a scalar"),
        (dict(tp=0.0), "tp: every entry must be > 0"),
        (dict(hs=-1.0), "hs: every entry must be >= 0"),
        (dict(gamma=0.5), "gamma: expected a peak enhancement >= 1"),
        (dict(gamma=np.ones(3)), "gamma: expected a scalar"),
    ],
)
def test_spectra_check_their_parameters(kwargs, match):
    args = dict(hs=2.0, tp=8.0) | kwargs
    gamma = args.pop("gamma", 3.3)
    with pytest.raises(ValueError, match=match):
        waves.jonswap(np.linspace(0.3, 2.0, 5), gamma=gamma, **args)
    if "gamma" not in kwargs:
        with pytest.raises(ValueError, match=match):
            waves.pierson_moskowitz(np.linspace(0.3, 2.0, 5), **args)


@pytest.mark.parametrize("dt", [0.0, -0.5, math.nan])
def test_run_metrics_refuses_a_step_that_is_not_positive(dt):
    from test_metrics import signals

    sig = signals()
    with pytest.raises(ValueError, match="dt: expected a finite step > 0"):
        metrics.run_metrics(sig, np.ones(5, bool), dt, start=0.6)


def test_run_metrics_checks_its_shapes_and_window():
    from test_metrics import signals

    sig = signals()
    with pytest.raises(ValueError, match=r"finite: expected shape \(5,\)"):
        metrics.run_metrics(sig, np.ones(4, bool), 0.5, start=0.6)
    with pytest.raises(ValueError, match="dt: expected a scalar"):
        metrics.run_metrics(sig, np.ones(5, bool), np.ones(2), start=0.6)
    with pytest.raises(ValueError, match=r"start: expected a fraction in \[0, 1\)"):
        metrics.run_metrics(sig, np.ones(5, bool), 0.5, start=1.0)
    m = metrics.run_metrics(sig, np.ones(5, bool), 0.5, start=0.6)
    assert float(m["iae_e"]) == pytest.approx(3.375)
