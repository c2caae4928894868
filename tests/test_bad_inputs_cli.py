"""Bad inputs of the ``vcjax`` commands (issue 24): output folders, locks, atomic writes,
oversized work, seeds, ``launch`` options, and logs ``vcjax fit`` must not trust.

Each case asserts its exact outcome: the exit code, a substring of the one-line message, and
which files are (or are not) there. The CLI is called in-process (:func:`vcjax.cli.main`);
every bad input here is refused before anything is compiled, so the file runs in seconds.
Exit codes: 2 = bad input, 130 = interrupted (see tests/test_interrupts.py).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from vcjax import cli
from vcjax.runtime import outputs

COMMANDS = ("sweep", "tune", "fit")
ALL_COMMANDS = COMMANDS + ("simulate", "demo")


EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _argv(command: str, out, tmp_path) -> list[str]:
    """A valid command line writing to ``out`` (every input is checked before ``--out``, so
    the inputs must be good for ``--out`` to be what is refused)."""
    if command == "simulate":
        return ["simulate", "sim1", "--out", str(out)]
    if command == "demo":
        return ["demo", "--out", str(out)]
    if command == "fit":
        return ["fit", str(_fit_case(tmp_path, lambda c: None)), "--out", str(out), "--quiet"]
    config = {"sweep": "sweeps/quick.toml", "tune": "tuning/quick.toml"}[command]
    return [command, str(EXAMPLES / config), "--out", str(out)]


def _run(argv, capsys) -> tuple[int, str]:
    rc = cli.main(list(argv))
    return rc, capsys.readouterr().err


# ------------------------------------------------------------------ --out creatable, writable


@pytest.mark.parametrize("command", ALL_COMMANDS)
def test_out_that_is_a_file_is_refused_first(command, tmp_path, capsys):
    f = tmp_path / "taken"
    f.write_text("user data\n")
    rc, err = _run(_argv(command, f, tmp_path), capsys)
    assert rc == 2
    assert f"--out {f}: exists and is not a directory" in err
    assert f.read_text() == "user data\n"


@pytest.mark.parametrize("command", ALL_COMMANDS)
def test_out_below_a_file_is_refused(command, tmp_path, capsys):
    f = tmp_path / "file"
    f.write_text("x")
    rc, err = _run(_argv(command, f / "sub", tmp_path), capsys)
    assert rc == 2
    assert f"cannot create the directory: {f} is a file" in err


@pytest.mark.parametrize("command", ALL_COMMANDS)
def test_out_that_cannot_be_created_is_refused(command, tmp_path, capsys):
    target = Path("/sys/vcjax-test-out")
    try:
        target.mkdir()
        target.rmdir()
        pytest.skip("/sys is writable here")
    except OSError:
        pass
    rc, err = _run(_argv(command, target, tmp_path), capsys)
    assert rc == 2
    assert f"--out {target}: cannot create the directory" in err


@pytest.mark.parametrize("command", ALL_COMMANDS)
def test_out_that_is_not_writable_is_refused(command, tmp_path, capsys):
    if os.geteuid() == 0:  # root writes anywhere: use a read-only file system instead
        ro = Path("/sys/kernel")
        if os.access(ro, os.W_OK) and _probe_ok(ro):
            pytest.skip("no read-only folder to test with")
    else:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
    rc, err = _run(_argv(command, ro, tmp_path), capsys)
    assert rc == 2
    assert f"--out {ro}: not writable" in err


def _probe_ok(d: Path) -> bool:
    try:
        (d / ".probe").write_text("")
        (d / ".probe").unlink()
        return True
    except OSError:
        return False


def test_empty_out_is_refused(capsys):
    rc, err = _run(["sweep", str(EXAMPLES / "sweeps/quick.toml"), "--out", ""], capsys)
    assert rc == 2
    assert "--out: expected a folder name" in err


# ------------------------------------------------------------------ another run's files


@pytest.mark.parametrize("command", ALL_COMMANDS)
@pytest.mark.parametrize("marker", ["run.json", "summary.json", "results.npz", "fit.json"])
def test_out_holding_another_run_is_refused(command, marker, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / marker).write_text("{}")
    rc, err = _run(_argv(command, out, tmp_path), capsys)
    assert rc == 2
    assert f"--out {out}: holds another vcjax run's files ({marker})" in err
    assert "--overwrite" in err
    assert (out / marker).read_text() == "{}"  # nothing removed
    assert not (out / outputs.LOCK).exists()  # lock released


def test_out_holding_only_user_files_is_used_as_is(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    d = outputs.prepare_out(out, overwrite=False, command="test")
    try:
        assert (out / outputs.LOCK).exists()
        assert (out / "notes.txt").read_text() == "mine"
    finally:
        d.release()
    assert not (out / outputs.LOCK).exists()


def test_overwrite_removes_vcjax_files_and_keeps_user_files(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "user_plot.png").write_text("user figure")
    d = outputs.prepare_out(out, overwrite=False, command="first")
    for name in (
        "run.json",
        "summary.json",
        "results.npz",
        "results.nc",
        "results.part1-of-2.npz",
        "a.png",
    ):
        (out / name).write_text("old")
    d.record_written()
    d.release()
    manifest = json.loads((out / outputs.MANIFEST).read_text())["files"]
    assert "a.png" in manifest and "notes.txt" not in manifest
    assert "user_plot.png" not in manifest

    with pytest.raises(outputs.OutputError, match="holds another vcjax run's files"):
        outputs.prepare_out(out, overwrite=False, command="second")
    d = outputs.prepare_out(out, overwrite=True, command="second")
    d.release()
    left = sorted(p.name for p in out.iterdir())
    assert left == ["notes.txt", "user_plot.png"]
    assert {p.name for p in d.removed} == {
        "run.json",
        "summary.json",
        "results.npz",
        "results.nc",
        "results.part1-of-2.npz",
        "a.png",
        outputs.MANIFEST,
    }


def test_overwrite_without_manifest_removes_nothing(tmp_path):
    """A folder from an older vcjax (no manifest): refused without --overwrite; with it,
    nothing is removed (nothing says vcjax wrote these files: matched by name only, they
    might be the user's); the new run's files replace those of the same name."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text("{}")
    (out / "metrics.json").write_text("mine")
    (out / "paths.png").write_text("?")
    with pytest.raises(outputs.OutputError, match="holds another vcjax run's files"):
        outputs.prepare_out(out, overwrite=False, command="t")
    d = outputs.prepare_out(out, overwrite=True, command="t")
    d.release()
    assert d.removed == []
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "paths.png", "run.json"]


def test_non_zero_process_does_not_lock_or_clear(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text("{}")
    d = outputs.prepare_out(out, overwrite=True, command="t", writer=False)
    assert not d.writer and (out / "run.json").exists() and not (out / outputs.LOCK).exists()


def test_rank_comes_from_the_distributed_runtime_not_the_environment(monkeypatch):
    from vcjax.runtime import distributed

    for k, v in {"SLURM_PROCID": "1", "SLURM_NTASKS": "2", "VCJAX_PROCESS_ID": "3"}.items():
        monkeypatch.setenv(k, v)
    monkeypatch.delenv("SLURM_STEP_ID", raising=False)
    assert not distributed.joined()
    assert outputs.process_rank() == 0


@pytest.mark.parametrize("env", [{"SLURM_PROCID": "1", "SLURM_NTASKS": "2"}])
def test_slurm_variables_outside_a_step_do_not_skip_the_out_checks(env, tmp_path, monkeypatch):
    """SLURM_PROCID/SLURM_NTASKS set outside a real step (no run joined): the process is
    still the writer, so an earlier run in --out is refused, not silently replaced."""
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    monkeypatch.delenv("SLURM_STEP_ID", raising=False)
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text('{"earlier": true}')
    rc = cli.main(["demo", "--out", str(out), "--horizon", "0.1"])
    assert rc == 2
    assert (out / "run.json").read_text() == '{"earlier": true}'


# ------------------------------------------------------------------ the lock


def test_second_writer_of_one_out_gets_exit_2(tmp_path, capsys):
    """Two processes, one --out: the second is refused while the first holds the lock."""
    out = tmp_path / "out"
    code = (
        "import sys; from vcjax.runtime import outputs\n"
        f"d = outputs.prepare_out({str(out)!r}, False, 'sweep')\n"
        "print('locked', flush=True); sys.stdin.readline()\n"
    )
    p = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    try:
        assert p.stdout.readline().strip() == "locked"  # a condition, not a sleep
        rc, err = _run(["sweep", str(EXAMPLES / "sweeps/quick.toml"), "--out", str(out)], capsys)
        assert rc == 2
        assert f"--out {out}: in use by process {p.pid}" in err
        assert "(sweep;" in err
    finally:
        p.stdin.write("\n")
        p.stdin.flush()
        p.wait(timeout=60)
    assert p.returncode == 0
    assert not (out / outputs.LOCK).exists()  # released at exit


def test_stale_lock_of_a_dead_process_is_taken_over(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    p = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True)
    dead = int(p.stdout)
    import socket

    (out / outputs.LOCK).write_text(json.dumps({"pid": dead, "host": socket.gethostname()}))
    d = outputs.prepare_out(out, False, "t")
    assert json.loads((out / outputs.LOCK).read_text())["pid"] == os.getpid()
    d.release()
    assert not (out / outputs.LOCK).exists()


def test_lock_of_a_live_process_on_this_host_is_respected(tmp_path):
    import socket

    out = tmp_path / "out"
    out.mkdir()
    start = outputs._start_time(os.getppid())  # as a vcjax process records it
    (out / outputs.LOCK).write_text(
        json.dumps(
            {"pid": os.getppid(), "host": socket.gethostname(), "command": "tune", "start": start}
        )
    )
    with pytest.raises(outputs.OutputError, match=rf"in use by process {os.getppid()}"):
        outputs.prepare_out(out, False, "t")
    assert json.loads((out / outputs.LOCK).read_text())["pid"] == os.getppid()


def test_cli_releases_the_lock_after_a_failed_command(tmp_path, capsys):
    out = tmp_path / "out"
    rc, err = _run(["sweep", str(tmp_path / "missing.toml"), "--out", str(out)], capsys)
    assert rc == 2 and "missing.toml" in err
    assert not (out / outputs.LOCK).exists()


# ------------------------------------------------------------------ atomic writes


def test_write_json_atomic_keeps_the_old_file_when_serialisation_fails(tmp_path):
    f = tmp_path / "a.json"
    outputs.write_json_atomic(f, {"a": 1})
    with pytest.raises(TypeError):
        outputs.write_json_atomic(f, {"a": object()})
    with pytest.raises(ValueError):
        outputs.write_json_atomic(f, {"a": float("nan")}, allow_nan=False)
    assert json.loads(f.read_text()) == {"a": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json"]  # no temporary left


def test_write_atomic_keeps_the_old_file_when_the_writer_dies_half_way(tmp_path):
    """``outputs.write_atomic`` (used for ``results.nc``): a writer that fails after writing
    part of its file leaves the old file whole and no temporary; a writer that finishes
    replaces it."""
    f = tmp_path / "results.nc"
    f.write_bytes(b"old")

    def half(tmp):
        Path(tmp).write_bytes(b"new, half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        outputs.write_atomic(f, half)
    assert f.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results.nc"]
    assert outputs.write_atomic(f, lambda tmp: Path(tmp).write_bytes(b"new")) == f
    assert f.read_bytes() == b"new" and sorted(p.name for p in tmp_path.iterdir()) == ["results.nc"]


def test_save_npz_atomic_round_trip_and_no_temporary(tmp_path):
    f = tmp_path / "r.npz"
    outputs.save_npz_atomic(f, x=np.arange(3.0), name=np.array("a"))
    with np.load(f) as z:
        assert z["x"].tolist() == [0.0, 1.0, 2.0] and str(z["name"]) == "a"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.npz"]


def test_savefig_atomic_writes_the_format_of_the_suffix(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1])
    f = outputs.savefig_atomic(fig, tmp_path / "fig.png")
    plt.close(fig)
    assert f.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig.png"]


# ------------------------------------------------------------------ work sized before it starts

SWEEP = "[sweep]\nnum_scenarios = {n}\nseed = {seed}\n[simulation]\nhorizon = {h}\ndt = 0.05\n"
TUNE = (
    "[problem]\nvariant = 'vcm_integral'\nhorizon = {h}\ndt = 0.05\n{extra}"
    "[train]\nsize = {b}\nseed = {seed}\n[heldout]\nsize = 4\nseed = 1001\n"
    "[optimizer]\nname = 'adam'\nsteps = 2\n[report]\nplot_scenarios = 0\n"
)


def _cfg(tmp_path, text: str) -> Path:
    f = tmp_path / "c.toml"
    f.write_text(text)
    return f


@pytest.mark.parametrize(
    "n, h, flags, message",
    [
        # the cases: 1e9 scenarios (memory), horizon 1e9 (steps per run)
        (1_000_000_000, 60.0, [], "GB of memory (host results"),
        (4, 1e9, [], "20000000000 steps per run (horizon / dt) exceeds the limit of 10000000"),
        (
            4,
            600.0,
            ["--max-steps", "1000"],
            "12000 steps per run (horizon / dt) exceeds the limit of 1000",
        ),
        (100_000, 60.0, ["--max-memory-gb", "0.01"], "but the limit is 0.01 GB"),
        ("1e9", 60.0, [], "[sweep] num_scenarios: expected an integer, got 1000000000.0"),
        (4, 60.0, ["--max-steps", "0"], "--max-steps: expected an integer >= 1, got 0"),
        (4, 60.0, ["--max-memory-gb", "-1"], "--max-memory-gb: expected a finite number > 0"),
        (4, 60.0, ["--max-memory-gb", "nan"], "--max-memory-gb: expected a finite number > 0"),
    ],
)
def test_oversized_sweep_is_refused_with_estimate_and_limit(n, h, flags, message, tmp_path, capsys):
    cfg = _cfg(tmp_path, SWEEP.format(n=n, seed=0, h=h))
    out = tmp_path / "out"
    rc, err = _run(["sweep", str(cfg), "--out", str(out), *flags], capsys)
    assert rc == 2
    assert message in err
    if "memory" in message and "expected" not in message:
        assert "--max-memory-gb" in err
    assert not (out / "summary.json").exists() and not (out / outputs.LOCK).exists()


@pytest.mark.parametrize(
    "h, b, extra, flags, message",
    [
        # the case: horizon 1e7 in a tune
        (1e7, 4, "", [], "200000000 steps per run (horizon / dt) exceeds the limit of 10000000"),
        (5e5, 64, "", [], "GB of memory (gradient tape"),
        (60.0, 4, "", ["--max-memory-gb", "1e-6"], "but the limit is 1e-06 GB"),
    ],
)
def test_oversized_tune_is_refused_with_estimate_and_limit(
    h, b, extra, flags, message, tmp_path, capsys
):
    cfg = _cfg(tmp_path, TUNE.format(h=h, b=b, seed=0, extra=extra))
    rc, err = _run(["tune", str(cfg), "--out", str(tmp_path / "o"), *flags], capsys)
    assert rc == 2
    assert message in err
    assert not (tmp_path / "o" / "gains.json").exists()


def test_checkpointing_shrinks_the_tune_tape_estimate():
    from vcjax.runtime import sizing

    base = {
        "problem": {"horizon": 1000.0, "dt": 0.1, "checkpoint": False, "checkpoint_every": 100},
        "train": {"size": 8},
        "heldout": {"size": 4},
        "optimizer": {"steps": 2, "grad_mode": "reverse"},
    }
    full = sizing.tune_estimate(base)["parts"]["gradient tape"]
    assert full == 8 * 10_000 * sizing.STATE_FLOATS * 8 * 4  # hand count: B x N x state x stages
    base["problem"]["checkpoint"] = True
    ck = sizing.tune_estimate(base)["parts"]["gradient tape"]
    assert ck == 8 * (100 + 100) * sizing.STATE_FLOATS * 8 * 4


def test_sweep_estimate_hand_count():
    from vcjax.runtime import sizing
    from vcjax.sweep import SweepSpec

    spec = SweepSpec(
        num_scenarios=10, variants=("vcm", "ilos"), horizon=10.0, dt=0.1, record_points=5
    )
    e = sizing.sweep_estimate(spec)
    assert e["steps_per_run"] == 100 and e["runs"] == 20 and e["trajectory_steps"] == 2000
    host = 10 * (2 * (sizing.METRIC_FLOATS * 8 + 5 * 3 * 4) + sizing.SCENARIO_FLOATS * 8)
    assert e["parts"]["host results"] == host
    assert e["parts"]["device chunk"] == 10 * 20 * sizing.STATE_FLOATS * 8 * 4  # stride 20
    # an explicit, larger limit lets it through
    sizing.check_estimate(e, "x", max_steps=100, max_memory_gb=1.0)
    with pytest.raises(sizing.SizeError, match="exceeds the limit of 99"):
        sizing.check_estimate(e, "x", max_steps=99)


_RANGE = "is outside the seed range 0 .. 4294967295"


@pytest.mark.parametrize(
    "seed, flags, message",
    [
        # the sampler keys its PRNG with jnp.uint32(seed): 2**32 .. 2**63 - 1 used to pass the
        # range check and crash in jnp.asarray (traceback), in float64 mode as with --no-x64
        (2**32, [], f"[sweep] seed: {2**32} {_RANGE}"),
        (2**63 - 1, [], f"[sweep] seed: {2**63 - 1} {_RANGE}"),
        (2**40, ["--no-x64"], f"[sweep] seed: {2**40} {_RANGE}"),
        (2**63, [], f"[sweep] seed: {2**63} {_RANGE}"),
        (-1, [], f"[sweep] seed: -1 {_RANGE}"),
    ],
)
def test_sweep_seed_outside_the_sampler_range(seed, flags, message, tmp_path, capsys):
    cfg = _cfg(tmp_path, SWEEP.format(n=4, seed=seed, h=10.0))
    rc, err = _run(["sweep", str(cfg), "--out", str(tmp_path / "o"), *flags], capsys)
    assert rc == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize("seed, flags", [(2**32, ["--no-x64"]), (2**63 - 1, []), (2**63, [])])
def test_tune_seed_outside_the_sampler_range(seed, flags, tmp_path, capsys):
    cfg = _cfg(tmp_path, TUNE.format(h=10.0, b=4, seed=seed, extra=""))
    rc, err = _run(["tune", str(cfg), "--out", str(tmp_path / "o"), *flags], capsys)
    assert rc == 2
    assert f"[train] seed: {seed} {_RANGE}" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.parametrize("seed", [2**32, 2**63 - 1, -1])
def test_tune_heldout_seed_outside_the_sampler_range(seed, tmp_path, capsys):
    text = TUNE.format(h=10.0, b=4, seed=0, extra="").replace("seed = 1001", f"seed = {seed}")
    cfg = _cfg(tmp_path, text)
    rc, err = _run(["tune", str(cfg), "--out", str(tmp_path / "o")], capsys)
    assert rc == 2
    assert f"[heldout] seed: {seed} {_RANGE}" in err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


@pytest.mark.slow  # 13 s; the range's refusals stay default
def test_largest_seed_runs_a_sweep_in_both_precisions(tmp_path, capsys):
    """SEED_MAX itself is a seed the sampler takes: the CLI runs a tiny sweep with it, in
    float64 mode and with --no-x64 (where the older check refused everything above 2**31 - 1),
    and the draws equal those of the same key built by hand."""
    import jax
    import numpy as np

    from vcjax import loops
    from vcjax.config import SEED_MAX
    from vcjax.sweep import ScenarioSpec, sample_scenarios

    assert SEED_MAX == 2**32 - 1
    for flags in (["--no-x64"], []):  # float64 last: the in-process CLI sets the mode
        text = SWEEP.format(n=2, seed=SEED_MAX, h=0.2) + "[output]\nfigures = false\n"
        cfg = _cfg(tmp_path, text)
        out = tmp_path / f"o{len(flags)}"
        rc, err = _run(["sweep", str(cfg), "--out", str(out), *flags], capsys)
        assert rc == 0, err
        assert json.loads((out / "summary.json").read_text())["spec"]["seed"] == SEED_MAX
    spec = ScenarioSpec(current_speed=(0.0, 1.0))
    sc = sample_scenarios(spec, SEED_MAX, np.arange(2))
    key = jax.random.fold_in(jax.random.PRNGKey(np.uint32(SEED_MAX)), 1)
    n = 3 + len(loops.make_loop("infante", "vcm").initial_keys)  # speed, direction, keys, u_d
    u = jax.random.uniform(jax.random.split(key, 9)[0], (n,), np.float64)
    assert float(sc.current_speed[1]) == float(u[0])


# ------------------------------------------------------------------ vcjax launch


@pytest.mark.parametrize(
    "argv, message",
    [
        (["-n", "1000"], "-n 1000: more processes than the number of usable CPU cores"),
        (["-n", "3", "--max-processes", "2"], "-n 3: more processes than --max-processes (2)"),
        (["-n", "1", "--max-processes", "0"], "--max-processes: expected an integer >= 1, got 0"),
        (
            ["-n", "1", "--timeout", "0"],
            "--timeout: expected a finite number of seconds > 0, got 0",
        ),
        (
            ["-n", "1", "--timeout", "-5"],
            "--timeout: expected a finite number of seconds > 0, got -5",
        ),
        (["-n", "1", "--timeout", "nan"], "--timeout: expected a finite number of seconds > 0"),
        (["-n", "0"], "-n N (number of processes, >= 1) is required"),
        (["-n", "-2"], "-n N (number of processes, >= 1) is required"),
    ],
)
def test_launch_bounds(argv, message, capsys):
    """(-n 1000 is beyond any machine here; at least 2 processes are always allowed)"""
    rc, err = _run(["launch", *argv, "--", "sweep", "x.toml"], capsys)
    assert rc == 2
    assert message in err


# ------------------------------------------------------------------ vcjax fit: logs it must not trust

PVS_CSV = Path(__file__).parent / "data" / "remus100_pvs_reference.csv"


def _fit_case(tmp_path, edit, rows: int = 301) -> Path:
    """A fit config on the first ``rows`` samples of the REMUS 100 reference log after
    ``edit(cols)`` (a dict of column arrays)."""
    import csv

    with open(PVS_CSV) as f:
        lines = f.read().splitlines()
    prov, header = lines[0], lines[1].split(",")
    data = np.array([[float(c) for c in r] for r in csv.reader(lines[2 : 2 + rows])])
    cols = {h: data[:, j].copy() for j, h in enumerate(header)}
    cols = edit(cols) or cols
    log = tmp_path / "log.csv"
    with open(log, "w") as f:
        f.write(prov + "\n" + ",".join(cols) + "\n")
        np.savetxt(f, np.column_stack(list(cols.values())), delimiter=",", fmt="%.12g")
    cfg = tmp_path / "fit.toml"
    cfg.write_text(
        f'[data]\nfiles = ["{log}"]\n[model]\nvehicle = "remus100"\nstep = "pvs"\n'
        "current_speed = 0.5\ncurrent_direction_deg = 170.0\n[fit]\n"
        'params = ["CD_0", "CL_delta_r"]\nsegment_steps = 25\n'
    )
    return cfg


def _deg(*names):
    def edit(cols):
        for n in names:
            cols[n] = np.degrees(cols[n])

    return edit


def _drop_rows(lo, hi):
    def edit(cols):
        keep = np.r_[0:lo, hi : len(cols["t"])]
        return {k: v[keep] for k, v in cols.items()}

    return edit


@pytest.mark.parametrize(
    "edit, message",
    [
        # the degrees log: every angle and rate in degrees -> the pitch is named first
        (
            _deg(
                "phi",
                "theta",
                "psi",
                "p",
                "q",
                "r",
                "delta_r",
                "delta_s",
                "delta_r_cmd",
                "delta_s_cmd",
            ),
            "column 'theta' reaches",
        ),  # fmt: skip
        (_deg("theta"), "an angle beyond pi rad only makes sense in degrees"),
        (_deg("delta_r"), "'delta_r' is in degrees, 'delta_r_cmd' in radians"),
        (_deg("delta_r_cmd"), "'delta_r_cmd' is in degrees, 'delta_r' in radians"),
        (_deg("psi"), "'psi' is in degrees, 'r' in radians"),
        (_deg("theta", "q"), "column 'theta' reaches"),
        (_deg("q"), "column 'q' reaches"),
        (_deg("r"), "log.csv: column 'r' is "),
        (_deg("r"), "x the rate of 'psi' (180/pi = 57.3): 'r' is in degrees"),
        (_deg("p"), "'p' is in degrees, 'phi' in radians"),
        (lambda c: {**c, "q": c["q"] * 100}, "rates must be in rad/s"),
        # the time in milliseconds
        (lambda c: {**c, "t": c["t"] * 1000.0}, "only makes sense if t is in milliseconds"),
        (lambda c: {**c, "t": c["t"] * 1000.0}, "the median time step is 20 s"),
        # the 0.24 s gap in a 0.02 s log (12 samples missing)
        (_drop_rows(100, 112), "sampling is not uniform: the step is 0.02 s"),
        (_drop_rows(100, 112), "from sample 99 to 100 (data rows 100 and 101; t = 1.98 -> 2.24 s"),
        (_drop_rows(200, 201), "a step of 0.04 s"),
        # jitter of 1 % in one step
        (
            lambda c: {**c, "t": np.where(np.arange(len(c["t"])) >= 50, c["t"] + 2e-4, c["t"])},
            "1 step(s) differ, the first from sample 49 to 50",
        ),  # fmt: skip
    ],
)
def test_fit_refuses_logs_it_cannot_trust(edit, message, tmp_path, capsys):
    cfg = _fit_case(tmp_path, edit)
    out = tmp_path / "out"
    rc, err = _run(["fit", str(cfg), "--out", str(out), "--quiet"], capsys)
    assert rc == 2, err
    assert message in err
    assert err.startswith("vcjax: fit: ") and "Traceback" not in err
    assert not (out / "fit.json").exists()


def test_a_gains_file_alone_is_not_another_run(tmp_path):
    (tmp_path / "gains.json").write_text("{}")  # a user's input, e.g. from vcjax tune
    outputs.prepare_out(tmp_path, False, "simulate").release()
    assert (tmp_path / "gains.json").exists()


def test_overwrite_never_removes_the_commands_inputs(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text("{}")
    (out / "gains.json").write_text("{}")
    (out / outputs.MANIFEST).write_text(json.dumps({"files": ["gains.json", "run.json"]}))
    d = outputs.prepare_out(out, True, "simulate", keep=[str(out / "gains.json")])
    d.release()
    assert sorted(p.name for p in out.iterdir()) == ["gains.json"]


def test_launch_bound_is_the_cores_and_at_least_two():
    from vcjax.runtime import sizing

    sizing.check_launch(2, None, None, cores=1)  # two processes may always be tried
    with pytest.raises(sizing.SizeError, match="-n 3: more processes than the number of usable"):
        sizing.check_launch(3, None, None, cores=2)
    sizing.check_launch(8, 1.0, None, cores=8)
    sizing.check_launch(64, None, 64, cores=8)  # --max-processes allows more


@pytest.mark.slow  # ~10 s: two demo runs (the logic is covered by the fast tests above)
def test_demo_twice_into_one_out_then_overwrite(tmp_path, capsys):
    """End to end: a second run into a used --out is refused; with --overwrite it replaces the
    first run's files (figures included, from its manifest) and keeps the user's own file."""
    out = tmp_path / "demo"
    assert cli.main(["demo", "--out", str(out), "--horizon", "0.5"]) == 0
    first = {p.name for p in out.iterdir()}
    assert {"run.json", outputs.MANIFEST} <= first and any(n.endswith(".png") for n in first)
    manifest = set(json.loads((out / outputs.MANIFEST).read_text())["files"])
    assert manifest == first - {outputs.MANIFEST}  # every file it wrote, nothing else
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert cli.main(["demo", "--out", str(out), "--horizon", "0.5"]) == 2
    assert "holds another vcjax run's files" in capsys.readouterr().err
    stale = out / "arm_old_figure.png"
    stale.write_text("from the first run")  # pretend the first run wrote it too
    m = json.loads((out / outputs.MANIFEST).read_text())
    outputs.write_json_atomic(out / outputs.MANIFEST, {"files": [*m["files"], stale.name]})
    assert cli.main(["demo", "--out", str(out), "--horizon", "0.5", "--overwrite"]) == 0
    assert not stale.exists()  # the earlier run's figure is gone, not left beside the new ones
    assert (out / "notes.txt").read_text() == "mine"
    assert not (out / outputs.LOCK).exists()


@pytest.mark.parametrize(
    "flags, message",
    [
        (["--max-memory-gb", "1e-7"], "fit: needs about 0.00"),
        (["--max-memory-gb", "1e-7"], "GB of memory (residuals and Jacobians"),
        (["--max-memory-gb", "0"], "--max-memory-gb: expected a finite number > 0, got 0"),
    ],
)
def test_fit_sized_before_it_starts(flags, message, tmp_path, capsys):
    cfg = _fit_case(tmp_path, lambda c: None)
    rc, err = _run(["fit", str(cfg), "--out", str(tmp_path / "o"), "--quiet", *flags], capsys)
    assert rc == 2
    assert message in err


def test_fit_estimate_hand_count():
    from vcjax.runtime import sizing

    e = sizing.fit_estimate(segments=4, segment_steps=25, n_x=15, n_params=2)
    assert e["memory_bytes"] == 3 * 8 * (4 * 25 * 15) * (1 + 2 + 15)


def test_atomic_writes_get_the_permissions_of_a_plain_write(tmp_path):
    """A temporary file from mkstemp is private (0600); what vcjax writes must not be."""
    plain = tmp_path / "plain.json"
    plain.write_text("{}")
    f = tmp_path / "a.json"
    outputs.write_json_atomic(f, {"a": 1})
    outputs.save_npz_atomic(tmp_path / "r.npz", x=np.arange(3.0))
    expected = plain.stat().st_mode & 0o777
    assert f.stat().st_mode & 0o777 == expected
    assert (tmp_path / "r.npz").stat().st_mode & 0o777 == expected
