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

from vcjax import outputs

ROOT = Path(__file__).resolve().parent.parent
LIMIT_S = 300  # per run: compile-bound, generous for a loaded machine


class Child:
    """A ``vcjax`` subprocess whose stderr is collected by a thread."""

    def __init__(self, argv, cwd):
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(ROOT), env.get("PYTHONPATH")) if p)
        env["VCJAX_CPU_DEVICES"] = "1"
        env.pop("XLA_FLAGS", None)
        self.p = subprocess.Popen(
            [sys.executable, "-m", "vcjax.cli", *argv],
            cwd=cwd,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        self.err = b""
        self._t = threading.Thread(target=self._read, daemon=True)
        self._t.start()

    def _read(self):
        while chunk := self.p.stderr.read1(4096):
            self.err += chunk

    def wait_for(self, pattern: str, limit_s: float = LIMIT_S) -> re.Match:
        end = time.monotonic() + limit_s
        while time.monotonic() < end:
            m = re.search(pattern, self.err.decode(errors="replace"))
            if m:
                return m
            if self.p.poll() is not None:
                self._t.join(5)
                m = re.search(pattern, self.err.decode(errors="replace"))
                if m:
                    return m
                raise AssertionError(f"exited {self.p.returncode} before {pattern!r}: {self.text}")
            time.sleep(0.02)
        self.p.kill()
        raise AssertionError(f"no {pattern!r} within {limit_s} s: {self.text}")

    def finish(self) -> int:
        self.out = self.p.stdout.read().decode()  # until the child closes it (exits)
        self.p.wait(timeout=LIMIT_S)
        self._t.join(LIMIT_S)
        return self.p.returncode

    @property
    def text(self) -> str:
        return self.err.decode(errors="replace")


def _interrupt_lines(text: str) -> list[str]:
    """The CLI's own lines about the interrupt (progress messages aside)."""
    lines = text.replace("\r", "\n").splitlines()
    return [ln for ln in lines if ln.startswith("vcjax:") and "interrupted" in ln]


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


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
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


def test_interrupted_fit_writes_estimates_not_converged(tmp_path):
    from tests._fit_logs import write_slow_fit  # a fit with many cheap iterations

    cfg = write_slow_fit(tmp_path)
    out = tmp_path / "out"
    c = Child(["fit", str(cfg), "--out", str(out)], tmp_path)
    c.wait_for(r"iteration\s+2\b|it\s+2\b|\b2: cost")
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
