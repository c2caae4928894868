"""The experiment registry behind ``vcjax simulate NAME``: the same common options for every
experiment, its own options only where they apply (anything else: exit 2 naming the option,
nothing written), REMUS 100 gains from ``vcjax tune`` load."""

import json

import jax
import numpy as np
import pytest

from vcjax import cli, experiments, loops


def _cli(capsys, *argv):
    rc = cli.main(list(argv))
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.mark.parametrize(
    ("argv", "option"),
    [
        (["sim1", "--actuation", "full"], "--actuation"),
        (["sim2", "--edd", "implied"], "--edd"),
        (["sim2", "--timing", "sampled"], "--timing"),
        (["sim2", "--current", "0", "1"], "--current"),
        (["remus100", "--edd", "paper"], "--edd"),
        (["remus100", "--actuation", "underactuated"], "--actuation"),
    ],
)
def test_an_option_that_does_not_apply_is_refused(capsys, tmp_path, argv, option):
    out = tmp_path / "o"
    rc, _, err = _cli(capsys, "simulate", *argv, "--out", str(out))
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"vcjax: simulate {argv[0]}: {option} ")
    assert not out.exists()


def test_registry_declares_every_experiment_and_its_options():
    assert experiments.names() == ("remus100", "sim1", "sim2")
    for name in experiments.names():
        e = experiments.get(name)
        mod = e.load()
        assert callable(mod.run_experiment) and callable(mod.load_gains)
        assert e.horizon > 0 and e.dt > 0
    assert dict(experiments.get("sim1").options) == {
        "edd": "paper",
        "timing": "continuous",
        "diverge_e": None,
    }
    assert dict(experiments.get("remus100").options) == {
        "diverge_e": None,
        "waves": None,
        "wave_seed": 0,
    }
    assert experiments.get("sim2").current is None
    with pytest.raises(ValueError, match="expected one of"):
        experiments.get("sim3")


def test_remus100_gains_written_by_tune_load(tmp_path, capsys):
    # what `vcjax tune` writes for a remus100 config: loop.gains_to_json of the tuned gains
    loop = loops.make_loop("remus100", "vcm3d_ilos")
    g = loop.default_gains()
    tuned = jax.tree_util.tree_map(lambda a: a * 1.5, g)
    d = loop.gains_to_json(tuned)
    got = experiments.get("remus100").load().load_gains(d)
    for a, b in zip(jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(tuned), strict=True):
        np.testing.assert_allclose(a, b)
    bad = tmp_path / "g.json"
    bad.write_text(json.dumps({"no_such_law": {"P_G": [1.0]}}))
    out = tmp_path / "o"
    rc, _, err = _cli(capsys, "simulate", "remus100", "--gains", str(bad), "--out", str(out))
    assert rc == 2 and f"cannot use gains file {bad}" in err


@pytest.mark.slow
def test_simulate_remus100_with_tuned_gains(tmp_path, capsys):
    loop = loops.make_loop("remus100", "vcm3d_ilos")
    g = tmp_path / "gains.json"
    g.write_text(json.dumps(loop.gains_to_json(loop.default_gains())))
    out = tmp_path / "o"
    argv = ["simulate", "remus100", "--gains", str(g), "--horizon", "2", "--dt", "0.1"]
    rc, _, err = _cli(capsys, *argv, "--out", str(out))
    assert rc == 0, err
    run = json.loads((out / "run.json").read_text())
    assert run["config"]["gains"] == str(g) and run["config"]["horizon"] == 2.0
    assert set(json.loads((out / "metrics.json").read_text())["variants"]) == set(
        loops.controllers("remus100")
    )
