"""Host CPU split into JAX devices: which count is chosen, and sweeps give the same results on
one device and sharded over two (fresh processes: the count is fixed when JAX initialises)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vcjax.runtime.devices import ENV_VAR, cpu_device_count, usable_cores

ROOT = Path(__file__).parents[1]


def test_count_precedence_flag_env_xla_flags_cores():
    assert cpu_device_count(3, {ENV_VAR: "5"}) == 3
    assert cpu_device_count("2", {}) == 2
    assert cpu_device_count(None, {ENV_VAR: " 5 "}) == 5
    xla = {"XLA_FLAGS": "--xla_force_host_platform_device_count=4"}
    assert cpu_device_count(None, xla) is None  # the user's XLA flag is left alone
    assert cpu_device_count(None, {**xla, ENV_VAR: "2"}) == 2
    assert cpu_device_count(None, {ENV_VAR: ""}) == usable_cores()
    assert cpu_device_count(None, {}) == len(os.sched_getaffinity(0))


@pytest.mark.parametrize("bad", ["0", "-2", "two", "1.5", ""])
def test_bad_counts_name_their_source(bad):
    with pytest.raises(ValueError, match="--cpu-devices"):
        cpu_device_count(bad, {})
    if bad:
        with pytest.raises(ValueError, match=ENV_VAR):
            cpu_device_count(None, {ENV_VAR: bad})


TOML = """
[sweep]
num_scenarios = 5
seed = 4
variants = ["vcm_integral"]
chunk_size = 5

[simulation]
horizon = 4.0
dt = 0.1
timing = "sampled"

[current]
speed = [0.0, 1.0]

[initial]
x = [-5.0, 5.0]

[model_error]
relative = 0.1

[output]
figures = false
"""


def _cli(*argv, env_extra=None):
    env = {k: v for k, v in os.environ.items() if k not in (ENV_VAR, "XLA_FLAGS")}
    env["JAX_PLATFORMS"] = "cpu"
    env["PYTHONPATH"] = str(ROOT)
    env.update(env_extra or {})
    return subprocess.run(
        [sys.executable, "-m", "vcjax.cli", *argv],
        env=env,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_sweep_sharded_over_two_cpu_devices_equals_one_device(tmp_path):
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TOML)
    runs = {}
    for n, how in ((1, ["--cpu-devices", "1"]), (2, [])):
        extra = {ENV_VAR: "2"} if not how else None  # the environment variable path
        out = tmp_path / f"out{n}{len(how)}"
        r = _cli("sweep", str(cfg), "--out", str(out), *how, env_extra=extra)
        assert r.returncode == 0, r.stderr[-3000:]
        summary = json.loads((out / "summary.json").read_text())
        assert summary["devices"] == n, summary
        t = summary["variants"]["vcm_integral"]["timing"]
        assert (t["scenarios"], t["steps"], t["devices"]) == (5, 40, n)
        assert t["compile_s"] > 0 and t["run_s"] > 0
        assert t["traj_steps_per_s"] == pytest.approx(5 * 40 / t["run_s"], rel=1e-3)
        assert "M trajectory-steps/s (5 x 40 steps" in r.stderr
        with np.load(out / "results.npz") as z:
            runs[(n, len(how))] = {k: z[k] for k in z.files if k != "meta_json"}
    one = runs[(1, 2)]
    assert "vcm_integral.ss_abs_e" in one and "vcm_integral.trace_e" in one, sorted(one)
    for k, a in one.items():
        # 5 scenarios: one chunk of 5, or of 6 split 3 + 3 over 2 devices (last one padded);
        # the per-scenario arithmetic is the same: bit for bit
        np.testing.assert_array_equal(runs[(2, 0)][k], a, err_msg=k)


def test_bad_cpu_devices_is_one_line_exit_2(tmp_path):
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TOML)
    r = _cli("sweep", str(cfg), "--out", str(tmp_path / "o"), "--cpu-devices", "0")
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and "--cpu-devices" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


TUNE_TOML = """
[problem]
variant = "vcm_integral"
horizon = 6.0
dt = 0.1

[train]
size = 4
seed = 0

[heldout]
size = 4
seed = 1001

[optimizer]
name = "adam"
steps = 2

[report]
plot_scenarios = 0
"""


@pytest.mark.slow
def test_tune_sharded_over_two_cpu_devices_matches_one_device(tmp_path):
    cfg = tmp_path / "tune.toml"
    cfg.write_text(TUNE_TOML)
    out = {}
    for n in (1, 2):
        r = _cli("tune", str(cfg), "--out", str(tmp_path / f"t{n}"), "--cpu-devices", str(n))
        assert r.returncode == 0, r.stderr[-3000:]
        assert f"training batch on {n} device(s)" in r.stderr
        out[n] = json.loads((tmp_path / f"t{n}" / "summary.json").read_text())
        assert out[n]["devices"] == n
    # the batch mean is summed across devices in another order: equal to round-off
    for k in ("heldout_loss_before", "heldout_loss_after", "train_loss_after"):
        assert out[2][k] == pytest.approx(out[1][k], rel=1e-9), k


def test_default_keeps_running_jax_explicit_conflict_is_an_error(monkeypatch):
    import jax

    from vcjax.runtime.devices import use_cpu_cores

    jax.numpy.zeros(1).block_until_ready()  # JAX is running in this process
    have = len(jax.devices("cpu"))
    monkeypatch.delenv(ENV_VAR, raising=False)
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    assert use_cpu_cores() in (have, usable_cores())  # no error: the CLI called from Python
    assert use_cpu_cores(have) == have
    with pytest.raises(ValueError, match="already running"):
        use_cpu_cores(have + 1)
    monkeypatch.setenv(ENV_VAR, str(have + 1))
    with pytest.raises(ValueError, match="already running"):
        use_cpu_cores()
