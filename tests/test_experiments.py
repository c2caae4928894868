"""The experiment registry behind ``vcjax simulate NAME`` and ``vcjax demo``: the same common
options for every experiment, its own options (flags generated from its typed options) only
where they apply (anything else: exit 2 naming the option, nothing written), REMUS 100 gains
from ``vcjax tune`` load; an experiment written in this file runs through the same machinery."""

import dataclasses
import json
import subprocess
import sys
from typing import Literal

import jax
import numpy as np
import pytest

from vcjax import cli, experiments, loops, metrics
from vcjax.experiments import Experiment, Options
from vcjax.experiments.base import option


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
        (["sim1", "--waves", "1", "8", "0"], "--waves"),
        (["sim1", "--wave-seed", "2"], "--wave-seed"),
        (["arm", "--diverge-e", "3"], "--diverge-e"),
        (["arm", "--gains", "g.json"], "--gains"),
        (["arm", "--current", "0", "1"], "--current"),
    ],
)
def test_an_option_that_does_not_apply_is_refused(capsys, tmp_path, argv, option):
    out = tmp_path / "o"
    rc, _, err = _cli(capsys, "simulate", *argv, "--out", str(out))
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"vcjax: simulate {argv[0]}: {option} ")
    assert not out.exists()


def test_demo_refuses_what_the_arm_does_not_take(capsys, tmp_path):
    out = tmp_path / "o"
    rc, _, err = _cli(capsys, "demo", "--edd", "paper", "--out", str(out))
    assert rc == 2 and err.strip() == (
        "vcjax: demo: --edd does not apply to arm (its own options: none)"
    )
    rc, _, err = _cli(capsys, "simulate", "sim2", "--bogus", "1", "--out", str(out))
    assert rc == 2 and err.strip() == "vcjax: simulate sim2: unrecognized arguments: --bogus 1"
    assert not out.exists()


def _flags_of(parser, *path):
    """The option strings of the (sub)parser reached by ``path``."""
    for name in path:
        sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
        parser = sub.choices[name]
    return {s for a in parser._actions for s in a.option_strings}


COMMON = {"-h", "--help", "--out", "--horizon", "--dt", "--no-x64", "--max-steps", "--overwrite"}


def test_registry_declares_every_experiment_and_the_flags_follow_its_options():
    assert experiments.names() == ("arm", "remus100", "sim1", "sim2")
    own = {
        "sim1": {"--edd", "--timing", "--diverge-e"},
        "sim2": {"--actuation", "--diverge-e", "--waves", "--wave-seed"},
        "remus100": {"--diverge-e", "--waves", "--wave-seed"},
        "arm": set(),
    }
    parser = cli.build_parser()
    for name in experiments.names():
        e = experiments.get(name)
        assert isinstance(e, Experiment) and e.horizon > 0 and e.dt > 0
        assert {f for f, _ in experiments.flags(e.options)} == own[name]
        takes = {"--gains"} if e.gains else set()
        takes |= {"--current"} if e.current is not None else set()
        assert _flags_of(parser, "simulate", name) == COMMON | takes | own[name]
    assert experiments.get("sim2").current is None and not experiments.get("arm").gains
    assert _flags_of(parser, "demo") == _flags_of(parser, "simulate", "arm")
    with pytest.raises(ValueError, match="expected one of"):
        experiments.get("sim3")
    with pytest.raises(ValueError, match="actuation: expected one of"):
        experiments.get("sim2").setup(actuation="both")
    with pytest.raises(TypeError, match="sim1: no option 'actuation'"):
        experiments.get("sim1").setup(actuation="full")  # not one of sim1's options


def test_importing_the_registry_starts_no_jax_backend():
    """The CLI builds its parser from the registry before it picks the precision, the XLA
    flags and the devices: importing the experiments may create no array."""
    code = (
        "import vcjax.experiments, vcjax.cli; vcjax.cli.build_parser()\n"
        "from jax._src import xla_bridge as xb; print(bool(xb._backends))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


@dataclasses.dataclass(frozen=True)
class _PuckOptions(Options):
    side: Literal["left", "right"] = option("left", "which side of the line the puck starts")
    offset: float | None = option(None, "start this far off the line [m]", "M")


@dataclasses.dataclass(frozen=True)
class _Puck(Experiment):
    """An experiment defined here: the ``infante`` loop with integral action, started beside
    its default line ``x = 10 m`` heading along it."""

    def variants(self, options=None):
        return ("vcm_integral",)

    def loop(self, variant, options=None):
        return loops.make_loop("infante", variant)

    def scenario(self, variant, setup=None):
        setup = self.setup() if setup is None else setup
        sign = 1.0 if setup.options.side == "left" else -1.0
        off = 1.0 if setup.options.offset is None else setup.options.offset
        eta0 = (10.0 - sign * off, 0.0, np.pi / 2)
        return loops.make_scenario(self.loop(variant), eta0=eta0, nu0=(2.0, 0.0, 0.0))

    def metrics(self, outcome, setup):
        sig = outcome.loop.signals(outcome.traj, outcome.scenario)
        m = metrics.run_metrics(sig, outcome.traj.finite, setup.dt)
        return {"max_abs_e": float(m["max_abs_e"]), "healthy": bool(~m["diverged"])}

    def figures(self, outcomes, setup, out):
        return []


def test_an_experiment_defined_in_a_test_file_gets_flags_and_runs(tmp_path, capsys):
    puck = _Puck("puck", "a puck off its path", horizon=2.0, dt=0.05, options=_PuckOptions)
    flags = dict(experiments.flags(_PuckOptions))
    assert flags["--side"]["choices"] == ["left", "right"] and flags["--offset"]["type"] is float
    setup = puck.setup(offset=0.5, side="right")
    res = puck.run(tmp_path, setup=setup, progress=lambda s: None)
    (v,) = puck.variants()
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m == json.loads(json.dumps(res["metrics"])) and m[v]["healthy"]
    assert 0.5 - 1e-9 <= m[v]["max_abs_e"] < 0.75  # starts 0.5 m off (then closes in)
    assert res["unhealthy"] == [] and res["files"] == [tmp_path / "metrics.json"]


def test_remus100_gains_written_by_tune_load(tmp_path, capsys):
    # what `vcjax tune` writes for a remus100 config: loop.gains_to_json of the tuned gains
    loop = loops.make_loop("remus100", "vcm3d_ilos")
    g = loop.default_gains()
    tuned = jax.tree_util.tree_map(lambda a: a * 1.5, g)
    d = loop.gains_to_json(tuned)
    got = experiments.get("remus100").load_gains(d)
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
