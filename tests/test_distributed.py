"""Multi-process runs with real processes on localhost (``vcjax.runtime.distributed``, ``vcjax launch``).

* a sweep run as two real processes (``vcjax launch -n 2 -- sweep``: each process its share of
  the chunks, process 0 merges) equals the same sweep in one process;
* the tuning loss and gradient with the training batch sharded over the global mesh of two real
  processes (gloo collectives on the CPU) equal the single-process ones;
* the launcher's plumbing: environment, failure propagation, timeouts, argument errors.

Every spawned run has a hard time limit; a hung coordinator fails the test instead of blocking it.
"""

import json
import os
import re
import socket
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

from tuning.config import load_config as load_tune_config
from tuning.loss import objective
from tuning.run import build
from vcjax import cli
from vcjax.runtime import distributed
from vcjax.sweep import load_config, load_results, run_sweep

ROOT = Path(__file__).resolve().parent.parent
TIMEOUT_S = 400  # per spawned run; compile-bound, generous for a loaded CI machine

SWEEP_TOML = """
[sweep]
num_scenarios = 4
seed = 11
variants = ["ilos"]
chunk_size = 1

[simulation]
horizon = 3.0
dt = 0.1
timing = "sampled"

[current]
speed = [0.0, 1.0]
direction_deg = [0.0, 360.0]

[initial]
x = [-3.0, 3.0]
heading_deg = [60.0, 120.0]

[output]
record_points = 10
figures = false
"""

TUNE_TOML = """
[problem]
variant = "vcm_integral"
horizon = 1.0
dt = 0.1
integrator = "euler"
timing = "sampled"
[train]
size = 4
[heldout]
size = 2
[optimizer]
name = "adam"
steps = 1
[report]
plot_scenarios = 0
"""


@pytest.fixture
def child_env(monkeypatch):
    """Spawned interpreters import this checkout and see one CPU device each."""
    path = os.environ.get("PYTHONPATH", "")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(p for p in (str(ROOT), path) if p))
    # no device-count flags; the tests' XLA optimisation level (conftest) kept, so that the
    # children compile what this process compiles
    level = re.search(r"--xla_backend_optimization_level=\S+", os.environ.get("XLA_FLAGS", ""))
    if level:
        monkeypatch.setenv("XLA_FLAGS", level.group(0))
    else:
        monkeypatch.delenv("XLA_FLAGS", raising=False)
    monkeypatch.delenv("VCJAX_CPU_DEVICES", raising=False)
    for k in (distributed.ENV_COORDINATOR, distributed.ENV_NUM_PROCESSES, "SLURM_STEP_ID"):
        monkeypatch.delenv(k, raising=False)


def test_two_process_sweep_equals_one_process(tmp_path, child_env, capsys):
    cfg = tmp_path / "sweep.toml"
    cfg.write_text(SWEEP_TOML)
    out = tmp_path / "two"
    argv = ["launch", "-n", "2", "--cpu-devices", "1", "--timeout", str(TIMEOUT_S), "--"]
    argv += ["sweep", str(cfg)]
    assert cli.main([*argv, "--out", str(out)]) == 0
    # each process wrote its share; process 0 merged them and recorded the run
    assert (out / "results.part0-of-2.npz").exists() and (out / "results.part1-of-2.npz").exists()
    run = json.loads((out / "run.json").read_text())
    assert run["processes"]["count"] == 2 and run["devices"]["count"] == 2
    assert run["command"] == "sweep" and run["seeds"] == {"sweep": 11}
    two = load_results(out / "results.npz")

    spec, _ = load_config(cfg)
    one = run_sweep(spec, progress=False, process_index=0, process_count=1)
    for k, v in one.scenarios.items():
        np.testing.assert_array_equal(two.scenarios[k], v, err_msg=k)
    for k, v in one.metrics["ilos"].items():
        np.testing.assert_allclose(two.metrics["ilos"][k], v, rtol=1e-12, atol=0, err_msg=k)
    np.testing.assert_allclose(two.traces["ilos"]["e"], one.traces["ilos"]["e"], rtol=1e-12)


@pytest.mark.slow  # 17 s; two-process sweep stays default
def test_two_process_tuning_loss_and_gradient_equal_one_process(tmp_path, child_env):
    cfg = tmp_path / "tune.toml"
    cfg.write_text(TUNE_TOML)
    worker = [sys.executable, str(ROOT / "tests" / "_mp_worker.py"), str(cfg), str(tmp_path)]
    codes = distributed.spawn(2, worker, cpu_devices=1, timeout_s=TIMEOUT_S)
    assert codes == [0, 0]
    recs = [json.loads((tmp_path / f"proc{i}.json").read_text()) for i in range(2)]
    # one device per process, half the batch on each, disjoint devices
    assert [r["local_rows"] for r in recs] == [2, 2]
    assert set(recs[0]["shard_devices"]).isdisjoint(recs[1]["shard_devices"])
    assert all(r["processes"] == 2 and r["devices"] == 2 for r in recs)

    problem, _, data, train, _ = build(load_tune_config(cfg))
    f = jax.jit(jax.value_and_grad(lambda th, d, s: objective(th, d, s, problem)[0]))
    loss, grad = f(data.theta_ref, data, train)
    for r in recs:
        assert r["loss"] == pytest.approx(float(loss), rel=1e-12)
        np.testing.assert_allclose(r["grad"], np.asarray(grad), rtol=1e-10, atol=1e-12)
        # tiled gains (vcjax tune on a sharded batch): the same loss and gradient
        assert r["loss_tiled"] == pytest.approx(float(loss), rel=1e-12)
        np.testing.assert_allclose(r["grad_tiled"], np.asarray(grad), rtol=1e-10, atol=1e-12)
        # the tuner's step compiled once across processes (parameters start replicated)
        assert r["step_compiles"] == 1
    assert recs[0]["tuned_loss"] == recs[1]["tuned_loss"] < float(loss)


def _slurm_port() -> int:
    """A free port in the range JAX's SLURM auto-detection derives from the job id."""
    lo = 65535 - 2**12 + 1
    for port in range(lo + 1000, 65536):
        try:
            with socket.socket() as sock:
                sock.bind(("localhost", port))
            return port
        except OSError:
            continue
    pytest.skip("no free port in JAX's SLURM range")


@pytest.mark.slow
def test_launch_inside_an_emulated_srun_step_uses_jax_auto_detection(tmp_path, child_env):
    """``srun vcjax launch -- sweep ...`` on a cluster: each task sees SLURM's variables, spawns
    nothing, and joins the step through ``jax.distributed.initialize()``'s SLURM detection. Two
    local processes with the variables srun sets stand in for the two tasks."""
    cfg = tmp_path / "sweep.toml"
    cfg.write_text(SWEEP_TOML)
    port = _slurm_port()
    base = {
        **os.environ,
        "SLURM_JOB_ID": str(port - (65535 - 2**12 + 1)),  # JAX: port = 61440 + id % 4096
        "SLURM_STEP_ID": "0",
        "SLURM_STEP_NODELIST": "localhost",
        "SLURM_STEP_NUM_NODES": "1",
        "SLURM_NTASKS": "2",
        "VCJAX_CPU_DEVICES": "1",
    }
    argv = [sys.executable, "-m", "vcjax.cli", "launch", "--", "sweep", str(cfg)]
    argv += ["--out", str(tmp_path / "out")]
    procs = [
        subprocess.Popen(argv, env={**base, "SLURM_PROCID": str(i), "SLURM_LOCALID": str(i)})
        for i in range(2)
    ]
    try:
        codes = [p.wait(timeout=TIMEOUT_S) for p in procs]
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    assert codes == [0, 0]
    run = json.loads((tmp_path / "out" / "run.json").read_text())
    assert run["processes"]["count"] == 2
    spec, _ = load_config(cfg)
    one = run_sweep(spec, progress=False, process_index=0, process_count=1)
    two = load_results(tmp_path / "out" / "results.npz")
    np.testing.assert_allclose(
        two.metrics["ilos"]["iae_e"], one.metrics["ilos"]["iae_e"], rtol=1e-12
    )


@pytest.mark.slow
def test_two_process_vcjax_tune_equals_one_process(tmp_path, child_env):
    """The whole ``vcjax tune`` as two processes (one device each) equals one process with two
    devices: the same SPMD program (the batch sharded in two halves, gains tiled), so the only
    cross-device reduction adds *two* partial sums per quantity, and ``a + b == b + a`` exactly
    in IEEE arithmetic -- the reduction order cannot matter, and the runs agree to round-off of
    the gradient's norm (a sum of squares, 1e-13) rather than to a tolerance fitted to a
    measurement. (Against one process with *one* device the batch mean is summed in another
    order: 4 terms instead of 2 + 2, and the observed difference of 4.8e-10 in the gains after
    three Adam steps has no bound worth asserting; that comparison is the non-slow
    ``test_two_process_tuning_loss_and_gradient_equal_one_process``, one gradient, 1e-10.)"""
    cfg = tmp_path / "tune.toml"
    cfg.write_text(TUNE_TOML.replace("steps = 1", "steps = 3"))
    argv = ["launch", "-n", "2", "--cpu-devices", "1", "--timeout", str(TIMEOUT_S), "--"]
    argv += ["tune", str(cfg)]
    assert cli.main([*argv, "--out", str(tmp_path / "two")]) == 0
    one = [sys.executable, "-m", "vcjax.cli", "tune", str(cfg), "--out", str(tmp_path / "one")]
    env = {**os.environ, "VCJAX_CPU_DEVICES": "2"}  # one process, two devices
    subprocess.run(one, env=env, check=True, timeout=TIMEOUT_S, capture_output=True)
    s1, s2 = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("one", "two"))
    assert s1["devices"] == s2["devices"] == 2  # the same sharded program in both
    h1, h2 = (json.loads((tmp_path / d / "history.json").read_text()) for d in ("one", "two"))
    for a, b in zip(h1["iterations"], h2["iterations"], strict=True):
        assert b["loss"] == pytest.approx(a["loss"], rel=1e-13)
        assert b["grad_norm"] == pytest.approx(a["grad_norm"], rel=1e-13)
    g1, g2 = (json.loads((tmp_path / d / "gains.json").read_text()) for d in ("one", "two"))
    for k, v in g1["vcm"].items():
        np.testing.assert_allclose(g2["vcm"][k], v, rtol=1e-13)
    assert json.loads((tmp_path / "two" / "run.json").read_text())["processes"]["count"] == 2


def test_spawn_sets_the_environment_and_stops_the_others_on_failure(tmp_path, child_env):
    # every process writes its file (atomically: a complete file or none); the failing one
    # fails only once its siblings' files are there (a condition, not a start-up race), and
    # gives up waiting after 60 s (the assertion on the files then fails, not the wait)
    script = (
        "import os, sys, time, json\n"
        "keys = ('VCJAX_COORDINATOR', 'VCJAX_NUM_PROCESSES', 'VCJAX_PROCESS_ID', 'XLA_FLAGS')\n"
        "i = os.environ['VCJAX_PROCESS_ID']\n"
        f"d = r'{tmp_path}'\n"
        "open(f'{d}/tmp' + i, 'w').write(json.dumps({k: os.environ.get(k) for k in keys}))\n"
        "os.replace(f'{d}/tmp' + i, f'{d}/env' + i)\n"
        "end = time.monotonic() + 60\n"
        "while i == '2' and time.monotonic() < end and not all(\n"
        "    os.path.exists(f'{d}/env{j}') for j in '01'):\n"
        "    time.sleep(0.01)\n"
        "sys.exit(3) if i == '2' else time.sleep(120)\n"
    )
    codes = distributed.spawn(3, [sys.executable, "-c", script], cpu_devices=2, timeout_s=60)
    assert codes[2] == 3 and codes[0] != 0 and codes[1] != 0  # the sleepers were terminated
    envs = [json.loads((tmp_path / f"env{i}").read_text()) for i in range(3)]
    assert {e["VCJAX_COORDINATOR"] for e in envs} == {envs[0]["VCJAX_COORDINATOR"]}
    assert envs[0]["VCJAX_COORDINATOR"].startswith("localhost:")
    assert [e["VCJAX_PROCESS_ID"] for e in envs] == ["0", "1", "2"]
    assert all(e["VCJAX_NUM_PROCESSES"] == "3" for e in envs)
    assert all("device_count=2" in e["XLA_FLAGS"] for e in envs)
    # a time limit ends a run that never finishes
    codes = distributed.spawn(
        1, [sys.executable, "-c", "import time; time.sleep(120)"], timeout_s=1
    )
    assert codes[0] != 0


def test_environment_errors_and_slurm_detection():
    assert distributed.initialize_from_env({}) is False  # not part of a run: nothing happens
    with pytest.raises(ValueError, match="VCJAX_PROCESS_ID"):
        distributed.initialize_from_env(
            {distributed.ENV_COORDINATOR: "localhost:1", distributed.ENV_NUM_PROCESSES: "2"}
        )
    bad = {
        distributed.ENV_COORDINATOR: "localhost:1",
        distributed.ENV_NUM_PROCESSES: "2",
        distributed.ENV_PROCESS_ID: "2",
    }
    with pytest.raises(ValueError, match="VCJAX_PROCESS_ID < VCJAX_NUM_PROCESSES"):
        distributed.initialize_from_env(bad)
    step = {"SLURM_JOB_ID": "1", "SLURM_STEP_ID": "0", "SLURM_PROCID": "0", "SLURM_NTASKS": "4"}
    assert distributed.in_slurm_step(step)
    assert not distributed.in_slurm_step({**step, "SLURM_NTASKS": "1"})
    assert not distributed.in_slurm_step({"SLURM_JOB_ID": "1"})  # inside sbatch, before srun


def test_launch_argument_errors(capsys, child_env):
    assert cli.main(["launch", "--", "sweep", "x.toml"]) == 2
    assert "-n N" in capsys.readouterr().err
    assert cli.main(["launch", "-n", "2", "--", "fly"]) == 2
    assert "expected a command" in capsys.readouterr().err
    assert cli.main(["launch", "-n", "2", "--cpu-devices", "0", "--", "sweep", "x.toml"]) == 2
    assert cli.main(["launch", "-n", "2", "--", "simulate", "sim1"]) == 2  # nothing to split
    assert "runs across processes" in capsys.readouterr().err


def test_shard_batch_validates_axes_and_batch():
    mesh = distributed.global_mesh()
    with pytest.raises(ValueError, match="axes"):
        distributed.shard_batch({"a": np.zeros(4)}, mesh, {"a": 1})
    with pytest.raises(ValueError, match="leading axis"):
        distributed.shard_batch({"a": np.zeros(4), "b": np.zeros(3)}, mesh)
    sh = distributed.shard_batch({"a": np.arange(4.0), "c": np.ones(2)}, mesh, {"a": 0, "c": None})
    np.testing.assert_array_equal(np.asarray(sh["a"]), np.arange(4.0))
    assert sh["c"].sharding.is_fully_replicated
