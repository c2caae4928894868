"""Interrupted runs keep what is done (issue 24): ``vcjax sweep``, ``tune`` and ``fit`` run in a
subprocess, get SIGINT (or SIGTERM) once a *condition* shows they are mid-run (a progress line
on stderr: a chunk or an iteration done), and must then write a valid, smaller result marked
interrupted, print one line, and exit 130 without a traceback.

No fixed sleeps: the test reads the child's stderr until the condition appears (with a time
limit that fails the test instead of hanging it).
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from vcjax.runtime import outputs

ROOT = Path(__file__).resolve().parent.parent
LIMIT_S = 300  # per run: compile-bound, generous for a loaded machine


class Child:
    """A ``vcjax`` subprocess whose stderr is collected by a thread."""

    def __init__(self, argv, cwd, new_session: bool = False):
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
        env["VCJAX_CPU_DEVICES"] = "1"
        env.pop("XLA_FLAGS", None)
        for k in ("VCJAX_COORDINATOR", "VCJAX_NUM_PROCESSES", "VCJAX_PROCESS_ID"):
            env.pop(k, None)
        self.p = subprocess.Popen(
            [sys.executable, "-m", "vcjax.cli", *argv],
            cwd=cwd,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            start_new_session=new_session,  # a process group of its own (a terminal's Ctrl-C)
        )
        self.err = self.out_b = b""
        self._ts = [
            threading.Thread(target=self._read, args=(self.p.stderr, "err"), daemon=True),
            threading.Thread(target=self._read, args=(self.p.stdout, "out_b"), daemon=True),
        ]
        for t in self._ts:
            t.start()

    def _read(self, stream, attr):
        while chunk := stream.read1(4096):
            setattr(self, attr, getattr(self, attr) + chunk)

    def wait_for(self, pattern: str, limit_s: float = LIMIT_S, stream: str = "err") -> re.Match:
        """Wait until ``pattern`` appears on the child's stderr (or ``stream="out"``)."""
        end = time.monotonic() + limit_s
        get = (lambda: self.text) if stream == "err" else (lambda: self.out_b.decode())
        while time.monotonic() < end:
            if m := re.search(pattern, get()):
                return m
            if self.p.poll() is not None:
                for t in self._ts:
                    t.join(5)
                if m := re.search(pattern, get()):
                    return m
                raise AssertionError(f"exited {self.p.returncode} before {pattern!r}: {self.text}")
            time.sleep(0.02)
        self.p.kill()
        raise AssertionError(f"no {pattern!r} within {limit_s} s: {self.text}")

    def finish(self) -> int:
        self.p.wait(timeout=LIMIT_S)
        for t in self._ts:
            t.join(LIMIT_S)
        self.out = self.out_b.decode()
        return self.p.returncode

    @property
    def text(self) -> str:
        return self.err.decode(errors="replace")


def _interrupt_lines(text: str) -> list[str]:
    """The CLI's own lines about the interrupt (progress messages aside)."""
    lines = text.replace("\r", "\n").splitlines()
    return [
        ln
        for ln in lines
        if ln.startswith("vcjax:")
        and "interrupted" in ln
        and "warning:" not in ln
        and "note:" not in ln  # a config's note names its path, which may say "interrupted"
    ]


SWEEP = """
[sweep]
num_scenarios = 400
seed = 3
variants = ["ilos"]
chunk_size = 1
[simulation]
horizon = 2.0
dt = 0.1
timing = "sampled"
[output]
record_points = 5
figures = false
"""


@pytest.mark.parametrize(
    "sig", [signal.SIGINT, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)]
)
def test_interrupted_sweep_keeps_the_chunks_done(sig, tmp_path):
    from vcjax.sweep import load_results

    cfg = tmp_path / "s.toml"
    cfg.write_text(SWEEP)
    out = tmp_path / "out"
    c = Child(["sweep", str(cfg), "--out", str(out)], tmp_path)
    c.wait_for(r"chunk 3/400")  # three chunks done: mid-run
    c.p.send_signal(sig)
    rc = c.finish()
    assert rc == 130, c.text
    assert "Traceback" not in c.text
    lines = _interrupt_lines(c.text)
    assert len(lines) == 1 and lines[0].startswith(f"vcjax: sweep: interrupted ({sig.name})")
    summary = json.loads((out / "summary.json").read_text())
    n = summary["num_scenarios"]
    assert summary["interrupted"] is True and summary["num_scenarios_planned"] == 400
    assert 3 <= n < 400
    assert f"kept the {n} of 400 scenarios" in lines[0]
    assert summary["variants"]["ilos"]["n"] == n
    res = load_results(out / "results.npz")  # a valid, smaller result
    assert res.interrupted and res.index.tolist() == list(range(n))
    assert res.metrics["ilos"]["ss_abs_e"].shape == (n,)
    assert (out / "run.json").exists() and not (out / outputs.LOCK).exists()
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


TUNE = """
[problem]
variant = "vcm_integral"
horizon = 1.0
dt = 0.1
integrator = "euler"
timing = "sampled"
[train]
size = 2
[heldout]
size = 2
[optimizer]
name = "adam"
steps = 100000
[report]
plot_scenarios = 1
"""


@pytest.mark.slow  # ~20 s: compiles a tuning step in a subprocess
def test_interrupted_tune_writes_best_gains_history_and_summary(tmp_path):
    cfg = tmp_path / "t.toml"
    cfg.write_text(TUNE)
    out = tmp_path / "out"
    c = Child(["tune", str(cfg), "--out", str(out)], tmp_path)
    c.wait_for(r" [3-9]/100000 | \d\d+/100000 ")  # a few steps done
    c.p.send_signal(signal.SIGINT)
    rc = c.finish()
    assert rc == 130, c.text
    assert "Traceback" not in c.text
    lines = _interrupt_lines(c.text)
    assert len(lines) == 1 and lines[0].startswith("vcjax: tune: interrupted (SIGINT)")
    summary = json.loads((out / "summary.json").read_text())
    hist = json.loads((out / "history.json").read_text())
    gains = json.loads((out / "gains.json").read_text())
    k = summary["iterations"]
    assert summary["interrupted"] is True and summary["reason"] == "interrupted"
    assert 3 <= k < 100000 and len(hist["iterations"]) == k and hist["reason"] == "interrupted"
    assert f"after {k} of 100000 steps" in lines[0]
    # the best gains so far: the lowest training loss of the history (or the last iterate)
    losses = [h["loss"] for h in hist["iterations"] if h["loss"] is not None]
    assert summary["train_loss_after"] <= min(losses) + 1e-12
    assert np.isfinite(summary["heldout_loss_after"])
    assert "vcm" in gains or gains  # the loop's gains JSON
    assert (out / "loss_curve.png").exists() and (out / "run.json").exists()


@pytest.mark.slow  # 6 s; the interrupted sweep and tune stay default
def test_interrupted_fit_writes_estimates_not_converged(tmp_path):
    """The REMUS 100 reference log, four coefficients from 30 % off: 16 iterations to converge;
    SIGINT once the first is printed."""
    csv = ROOT / "tests" / "data" / "remus100_pvs_reference.csv"
    cfg = tmp_path / "fit.toml"
    cfg.write_text(
        f'[data]\nfiles = ["{csv}"]\n[model]\nvehicle = "remus100"\nstep = "pvs"\n'
        "current_speed = 0.5\ncurrent_direction_deg = 170.0\n[fit]\n"
        'params = ["CD_0", "CL_delta_r", "CL_delta_s", "cf_coeff"]\ninitial_scale = 1.3\n'
        "segment_steps = 50\n"
    )
    out = tmp_path / "out"
    c = Child(["fit", str(cfg), "--out", str(out)], tmp_path)
    c.wait_for(r"stage 1 iteration +1:", stream="out")
    c.p.send_signal(signal.SIGINT)
    rc = c.finish()
    assert rc == 130, c.text
    assert "Traceback" not in c.text
    lines = _interrupt_lines(c.text)
    assert len(lines) == 1 and lines[0].startswith("vcjax: fit: interrupted (SIGINT)")
    fit = json.loads((out / "fit.json").read_text())
    assert fit["converged"] is False and fit["reason"] == "interrupted"
    assert any("interrupted" in w for w in fit["warnings"])
    assert all(np.isfinite(v) for v in fit["estimates"].values())
    assert 1 <= fit["iterations"] < 16 and f"after {fit['iterations']} iterations" in lines[0]
    assert "warning: interrupted after" in c.text  # the warning on stderr too


@pytest.mark.slow  # ~30 s: two processes compile a tuning step
def test_ctrl_c_in_a_two_process_tune_stops_both_at_the_same_step(tmp_path):
    """``vcjax launch -n 2 -- tune``, Ctrl-C to the whole process group (what a terminal does):
    the processes agree on the step to stop at (an all-gather of the flag after each step), so
    none waits in a collective for one that stopped; process 0 writes the best gains so far."""
    cfg = tmp_path / "t.toml"
    cfg.write_text(TUNE)
    out = tmp_path / "out"
    argv = ["launch", "-n", "2", "--cpu-devices", "1", "--timeout", "600", "--"]
    c = Child([*argv, "tune", str(cfg), "--out", str(out)], tmp_path, new_session=True)
    c.wait_for(r" [3-9]/100000 | \d\d+/100000 ")
    os.killpg(c.p.pid, signal.SIGINT)
    rc = c.finish()
    assert rc == 130, c.text
    assert "Traceback" not in c.text
    summary = json.loads((out / "summary.json").read_text())
    hist = json.loads((out / "history.json").read_text())
    assert summary["interrupted"] is True and len(hist["iterations"]) == summary["iterations"]
    assert (out / "gains.json").exists() and not (out / outputs.LOCK).exists()
    assert "vcjax: launch: interrupted: exit codes [130, 0]" in c.text


def _until(cond, what):
    """Wait for ``cond()`` (a signal's Python handler runs between bytecodes: at once, but
    not necessarily within the statement that sent it)."""
    t0 = time.monotonic()
    while not cond():
        assert time.monotonic() - t0 < LIMIT_S, what
        time.sleep(0.001)


def test_the_interrupts_duplicate_after_the_guard_is_swallowed_and_a_later_one_is_not(
    monkeypatch,
):
    """A terminal's Ctrl-C reaches every process of ``vcjax launch`` and the launcher forwards
    it too: the duplicate may arrive after a process has left its guard (one that writes
    nothing stops at once), where a KeyboardInterrupt in JAX's exit handler would leave the
    other processes waiting at their shutdown barrier (run 2 of the loaded slow suite:
    ``launch`` exit codes [-6, 0]). Within SAME_INTERRUPT_S of the interrupt it is swallowed;
    a later signal gets the old handler, which is restored."""
    from vcjax.runtime import interrupts

    seen = []

    def old(signum, frame):
        seen.append(signum)

    previous = signal.signal(signal.SIGINT, old)
    try:
        with interrupts.interrupt_guard():
            os.kill(os.getpid(), signal.SIGINT)
            _until(interrupts.stop_requested, "the guard's flag")
        assert interrupts.stop_signal() == "SIGINT" and not interrupts.stop_requested()
        os.kill(os.getpid(), signal.SIGINT)  # the forwarded duplicate, just after the guard
        for _ in range(1000):  # bytecodes for the handler to run between
            pass
        assert seen == [] and signal.getsignal(signal.SIGINT) is not old
        # a signal long after the interrupt is a new one: the old handler's
        monkeypatch.setattr(interrupts, "_stop_time", [time.monotonic() - 10.0])
        os.kill(os.getpid(), signal.SIGINT)
        _until(lambda: seen == [signal.SIGINT], "the old handler")
        assert signal.getsignal(signal.SIGINT) is old
        # a guard that was not interrupted restores the old handler itself
        with interrupts.interrupt_guard():
            pass
        assert signal.getsignal(signal.SIGINT) is old
    finally:
        signal.signal(signal.SIGINT, previous)


def test_second_interrupt_while_sweep_figures_are_written_keeps_run_json_and_manifest(
    tmp_path, monkeypatch, capsys
):
    """Two SIGINTs more than SAME_INTERRUPT_S apart while the figures are drawn: the second
    stops the run at once (exit 130), yet ``run.json`` (``ended_early``) and the manifest are
    written; the next ``--overwrite`` removes the stray figure and keeps the user's file."""
    from vcjax import cli
    from vcjax.plots import sweep as sweep_plots
    from vcjax.runtime import interrupts

    cfg = tmp_path / "s.toml"
    cfg.write_text(
        SWEEP.replace("num_scenarios = 400", "num_scenarios = 2").replace(
            "figures = false", "figures = true"
        )
    )
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    monkeypatch.setattr(interrupts, "SAME_INTERRUPT_S", -1.0)  # every signal is a new one

    def draw(result, out_dir):
        (Path(out_dir) / "sweep_stray.png").write_text("the first of the figures")
        signal.raise_signal(signal.SIGINT)  # the first: asks the (finished) loop to stop
        signal.raise_signal(signal.SIGINT)  # the second: stops at once
        raise AssertionError("not reached")

    monkeypatch.setattr(sweep_plots, "sweep_figures", draw)
    assert cli.main(["sweep", str(cfg), "--out", str(out)]) == 130
    assert "stopped at once" in capsys.readouterr().err
    info = json.loads((out / "run.json").read_text())
    assert info["ended_early"] == "KeyboardInterrupt" and info["interrupted"] is True
    manifest = json.loads((out / outputs.MANIFEST).read_text())["files"]
    assert "sweep_stray.png" in manifest and "run.json" in manifest
    assert "notes.txt" not in manifest and not (out / outputs.LOCK).exists()

    monkeypatch.setattr(sweep_plots, "sweep_figures", lambda result, out_dir: [])
    assert cli.main(["sweep", str(cfg), "--out", str(out), "--overwrite"]) == 0
    assert not (out / "sweep_stray.png").exists()
    assert (out / "notes.txt").read_text() == "mine"
