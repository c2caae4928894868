"""The paper's Simulation 1 end to end: ``vcjax simulate sim1`` writes figures and metrics, and
the metrics meet the issue's expectations; gains files round-trip; bad input is rejected."""

import json

import numpy as np
import pytest

from vcjax import cli, experiments, loops

SIM1 = experiments.get("sim1")

KEYS = {
    "ss_abs_e",
    "ss_abs_s",
    "ss_abs_u_err",
    "iae_e",
    "max_abs_tau_u",
    "max_abs_rudder_deg",
    "sat_fraction",
}


@pytest.fixture(scope="module")
def sim1_out(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim1")
    assert cli.main(["simulate", "sim1", "--out", str(out)]) == 0
    return out


def test_cli_writes_figures_and_metrics(sim1_out):
    for name in ("sim1_paths", "sim1_speed_heading", "sim1_controls", "sim1_errors"):
        f = sim1_out / f"{name}.png"
        assert f.stat().st_size > 10_000
        assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    metrics = json.loads((sim1_out / "metrics.json").read_text())
    assert set(metrics) == set(SIM1.variants())
    run = json.loads((sim1_out / "run.json").read_text())
    assert run["command"] == "simulate sim1"
    assert run["config"]["horizon"] == 150.0 and run["config"]["dt"] == 0.05
    assert run["config"]["scenario"]["current"][:2] == [0.0, 0.5]
    for m in metrics.values():
        assert KEYS <= set(m)
        assert m["healthy"]
        assert all(np.isfinite(m[k]) for k in KEYS)


def test_metrics_meet_the_papers_claims(sim1_out):
    m = json.loads((sim1_out / "metrics.json").read_text())
    # with integral action (41): u~ -> 0 and eps -> 0
    assert m["vcm_integral"]["ss_abs_e"] < 0.05
    assert m["vcm_integral"]["ss_abs_s"] < 0.05
    assert m["vcm_integral"]["ss_abs_u_err"] < 0.02
    # without it a visible steady-state error remains (the along-track current biases speed)
    assert m["vcm"]["ss_abs_s"] > 0.02 and m["vcm"]["ss_abs_u_err"] > 0.01
    assert m["vcm"]["ss_abs_s"] > 100 * m["vcm_integral"]["ss_abs_s"]
    # actuator limits are honoured (the plant saturates; the metrics report actual states)
    for v in m.values():
        assert v["max_abs_tau_u"] <= 920.0 + 1e-6
        assert v["max_abs_rudder_deg"] <= 30.0 + 1e-6
        assert 0.0 <= v["sat_fraction"] <= 1.0


def test_gains_file_round_trip(tmp_path):
    g = SIM1.default_gains("vcm")
    d = loops.gains_to_json(g)
    g2 = SIM1.load_gains(json.loads(json.dumps(d)))
    for a, b in zip(g.vcm, g2.vcm, strict=True):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(g.baseline, g2.baseline, strict=True):
        np.testing.assert_array_equal(a, b)
    d["vcm"]["Delta"] = 3.0
    g3 = SIM1.load_gains(d)
    assert float(g3.vcm.Delta) == 3.0
    with pytest.raises(ValueError, match="Delta"):
        SIM1.load_gains({"vcm": {"Delta": -1.0}})
    with pytest.raises(ValueError, match="unknown"):
        SIM1.load_gains({"vcm": {"Delta": 1.0}, "extra": {}})
    with pytest.raises(ValueError, match="gains file"):
        SIM1.load_gains({"vcm": {"P_K": [1.0]}})


def test_cli_rejects_a_bad_gains_file(tmp_path, capsys):
    bad = tmp_path / "gains.json"
    bad.write_text(json.dumps({"vcm": {"sigma": 0.0}}))
    assert cli.main(["simulate", "sim1", "--out", str(tmp_path), "--gains", str(bad)]) == 2
    assert "sigma" in capsys.readouterr().err


def test_scenario_and_setup_validation():
    loop = SIM1.loop("vcm")
    with pytest.raises(ValueError, match="eta0"):
        loops.make_scenario(loop, eta0=(0.0, 0.0))
    with pytest.raises(ValueError, match="current"):
        SIM1.scenario("vcm", SIM1.setup(current=(np.nan, 0.0)))
    with pytest.raises(ValueError, match="current"):
        SIM1.scenario("vcm", SIM1.setup(current=(0.0, 0.5, 0.0, 1.0)))
    with pytest.raises(ValueError, match="u_d"):
        loops.make_scenario(loop, u_d=0.0)
    with pytest.raises(ValueError, match="variant"):
        SIM1.loop("pid")
    with pytest.raises(ValueError, match="edd"):
        SIM1.setup(edd="neither")
    with pytest.raises(ValueError, match="horizon"):
        SIM1.simulate("vcm", SIM1.setup(horizon=-1.0))


@pytest.mark.slow  # 7 s; test_sim2 runs the experiment, test_out_order its refusals
def test_cli_sim2_and_argument_errors(tmp_path, capsys):
    out = tmp_path / "sim2"
    assert cli.main(["simulate", "sim2", "--out", str(out), "--horizon", "4", "--dt", "0.1"]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert {"rms_dist_3d", "max_dist_3d", "rms_depth_err", "thruster_sat_fraction"} <= set(m)
    assert set(m["by_actuation"]) == {"underactuated", "full"}
    run = json.loads((out / "run.json").read_text())
    assert run["command"] == "simulate sim2" and run["config"]["horizon"] == 4.0
    assert (out / "sim2_path_3d.png").exists()
    bad = tmp_path / "bad"  # `out` holds a run now: a new command there needs --overwrite
    assert cli.main(["simulate", "sim2", "--out", str(bad), "--current", "0", "1"]) == 2
    assert "not supported" in capsys.readouterr().err
    assert cli.main(["simulate", "sim1", "--out", str(out), "--dt", "-1"]) == 2
    assert "dt" in capsys.readouterr().err
    assert cli.main(["simulate", "sim2", "--out", str(out), "--horizon", "4"]) == 2
    assert "holds another vcjax run's files" in capsys.readouterr().err
