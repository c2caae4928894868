"""Robust tuning (``[robust]`` of ``vcjax tune``, tuning/robust.py): the section's refusals, the
tuning loss as a search metric (equal to the tune's own scenario loss), the adversarial slot
filled and refreshed every K steps, ``vcjax falsify --metric loss`` and the replay of a
``worst.json`` through ``vcjax sweep --scenario``."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tuning.config import validate_config
from vcjax.config import ConfigError

jax.config.update("jax_enable_x64", True)

#: a tiny Simulation 1 problem (the falsify tests' horizon and ranges: shared compiled programs)
TINY = """
[scenario]
controller = "vcm_integral"
[simulation]
horizon = 2.0
dt = 0.05
[current]
speed = [0.0, 0.5]
direction_deg = [0.0, 360.0]
[initial]
y = [-5.0, 5.0]
heading_deg = [60.0, 120.0]
[train]
size = 2
[heldout]
size = 2
[optimizer]
name = "adam"
steps = 3
[report]
plot_scenarios = 0
"""
ROBUST = """
[robust]
adversarial_every = 2
adversarial_count = 1
starts = 2
budget = 2
check_starts = 2
check_budget = 2
"""


def _raw(text):
    import tomllib

    return tomllib.loads(text)


@pytest.mark.parametrize(
    ("table", "match"),
    [
        (
            {"adversarial_evry": 2},
            r"\[robust\].*adversarial_evry.*did you mean 'adversarial_every'",
        ),
        ({"adversarial_every": 0}, r"\[robust\] adversarial_every"),
        ({"budget": 1.5}, r"\[robust\] budget"),
        ({"compare": "yes"}, r"\[robust\] compare"),
        ({"step_size": -0.1}, r"\[robust\] step_size"),
        ({"starts": 2, "adversarial_count": 3}, r"\[robust\] starts: must be >= adversarial_count"),
        ({"metric": "tuning_los"}, r"\[robust\] metric: .*did you mean 'tuning_loss'"),
    ],
)
def test_robust_section_refusals(table, match):
    raw = _raw(TINY)
    raw["robust"] = table
    with pytest.raises(ConfigError, match=match):
        validate_config(raw)


def test_robust_section_recorded_only_where_given():
    from tuning.spec import TuneConfig

    plain = validate_config(_raw(TINY))
    assert plain.robust is None and "robust" not in plain.to_dict()
    rob = validate_config(_raw(TINY + ROBUST))
    assert rob.robust.adversarial_every == 2 and rob.robust.metric == "tuning_loss"
    assert TuneConfig.from_dict(rob.to_dict()) == rob
    assert TuneConfig.from_dict(plain.to_dict()) == plain


def _tune(text):
    from tuning.run import _prepare

    return _prepare(validate_config(_raw(text)), lambda m: None)


def test_refresh_hook_swaps_the_arguments_and_restarts_lbfgs():
    """``TunerHooks.refresh``: new arguments from step K on (the loss follows them), L-BFGS's
    memory restarted there, the best parameters those of the latest arguments."""
    from tuning.optim import TunerHooks, run_gradient_tuner

    loss = lambda th, c: jnp.sum((th - c) ** 2)  # noqa: E731
    seen = []

    def refresh(k, theta, args):
        seen.append(k)
        return (jnp.asarray([3.0, -1.0]),) if k == 2 else None

    res = run_gradient_tuner(
        loss,
        jnp.zeros(2),
        (jnp.asarray([1.0, 1.0]),),
        optimizer="lbfgs",
        steps=6,
        hooks=TunerHooks(refresh=refresh),
    )
    assert seen[:3] == [0, 1, 2]
    np.testing.assert_allclose(np.asarray(res.theta), [3.0, -1.0], atol=1e-6)
    assert res.history[2]["loss"] > res.history[1]["loss"]  # the new objective from step 2


@pytest.mark.slow  # compiles the search's reverse-mode program with the tuning loss (~30 s loaded)
def test_tuning_loss_metric_is_the_tunes_scenario_loss_and_the_slot_refreshes():
    """The search's tuning loss of the adversarial scenarios (streamed, segment by segment) is
    the tune's own scenario loss of the slot it fills (whole rollouts); the batch keeps its
    shape; a refresh at step K puts new scenarios in the slot, not before."""
    from tuning.loss import scenario_losses
    from tuning.robust import concat_batches, hook
    from tuning.run import distribute
    from tuning.scenarios import batch_size, scenario_at

    t = _tune(TINY + ROBUST)
    rs = t.robust
    assert batch_size(t.train_d) == 3 and len(rs.rounds) == 1
    slot = scenario_at(t.train_d, 2)
    losses, _ = scenario_losses(t.start, t.data, t.train_d, t.problem)
    assert float(losses[2]) == pytest.approx(rs.rounds[0]["worst"], rel=1e-9)
    refresh = hook(t, lambda m: None, distribute)
    args = (t.data_d, t.train_d)
    assert refresh(1, t.start, args) is None
    new = refresh(2, t.start + 0.3, args)
    assert new is not None and batch_size(new[1]) == 3 and len(rs.rounds) == 2
    assert not np.allclose(np.asarray(scenario_at(new[1], 2).eta0), np.asarray(slot.eta0))
    np.testing.assert_array_equal(np.asarray(new[1].eta0[:2]), np.asarray(t.train_d.eta0[:2]))
    assert batch_size(concat_batches(t.train, t.train)) == 4


@pytest.mark.slow  # a whole robust tune with compare = true (two tunes, four searches): ~2 min
def test_robust_tune_reports_nominal_and_robust(tmp_path):
    from tuning.run import run_tune_config

    cfg = tmp_path / "t.toml"
    cfg.write_text(TINY + ROBUST + "compare = true\n")
    res = run_tune_config(cfg, tmp_path / "out", progress=None)
    r = res["summary"]["robust"]
    for k in ("robust", "nominal"):
        assert set(r[k]) >= {"heldout_mean", "worst", "params"}
    assert [x["step"] for x in r["search"]["training"]["rounds"]] == [0, 2]
    assert (tmp_path / "out" / "nominal" / "summary.json").is_file()
    assert "change" in r


@pytest.mark.slow  # compiles the search's reverse-mode program with the tuning loss (~45 s loaded)
def test_falsify_metric_loss_and_sweep_scenario_replay(tmp_path, capsys):
    """``vcjax falsify --metric loss`` searches the tuning loss ([weights] of the file); ``vcjax
    sweep CONFIG --scenario worst.json`` runs those scenarios again: the same loss (1e-9),
    every metric; bad input refused before --out."""
    from test_falsify import CLI_CONFIG

    from vcjax import cli

    cfg = tmp_path / "f.toml"
    cfg.write_text(CLI_CONFIG + "[weights]\neps = 2.0\n")
    out = tmp_path / "out"
    assert cli.main(["falsify", str(cfg), "--out", str(out), "--metric", "loss"]) == 0
    worst = json.loads((out / "worst.json").read_text())
    assert worst["metric"] == "tuning_loss"
    vals = [s["tuning_loss"] for s in worst["scenarios"]]
    assert vals == sorted(vals, reverse=True) and vals[0] > 0
    rep = tmp_path / "sweep"
    assert (
        cli.main(["sweep", str(cfg), "--scenario", str(out / "worst.json"), "--out", str(rep)]) == 0
    )
    got = json.loads((rep / "scenarios.json").read_text())["scenarios"]
    np.testing.assert_allclose([s["tuning_loss"] for s in got], vals, rtol=1e-9)
    assert {"max_abs_e", "rms_cross_track_e"} <= set(got[0]["metrics"])
    capsys.readouterr()
    bad = tmp_path / "bad.toml"
    bad.write_text(CLI_CONFIG + "[weights]\nepss = 2.0\n")
    assert cli.main(["falsify", str(bad), "--out", str(tmp_path / "o2"), "--metric", "loss"]) == 2
    assert "[weights]" in capsys.readouterr().err and not (tmp_path / "o2").exists()
    assert cli.main(["falsify", str(bad), "--out", str(tmp_path / "o3")]) == 2
    assert "only with metric" in capsys.readouterr().err
    assert cli.main(["sweep", str(cfg), "--scenario", str(cfg), "--out", str(tmp_path / "o4")]) == 2
    assert "--scenario" in capsys.readouterr().err and not (tmp_path / "o4").exists()


def test_tuning_loss_metric_checks_its_weights():
    from tuning.robust import TuningLossMetric

    with pytest.raises(ValueError, match="weights.eps"):
        TuningLossMetric.of({"eps": -1.0})
    m = TuningLossMetric.of_table({"eps": 2.0})
    assert dict(m.weights)["eps"] == 2.0 and hash(m) == hash(
        TuningLossMetric.of_table({"eps": 2.0})
    )
    acc = m.init(jnp.float64)
    assert float(m.value(acc, 10)) == 0.0
