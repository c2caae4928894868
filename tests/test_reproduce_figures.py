"""The committed results under ``docs/figures`` reproduce: each ``metrics.json`` /
``summary.json`` is re-made by the command that made it (run as a user would, ``python -m
vcjax.cli ...`` in a fresh process, float64) and compared number by number to 1e-9 relative.

Slow (minutes each; the tuning runs tens of minutes): ``pytest -m slow
tests/test_reproduce_figures.py -k sim1``. As a script, with a table of the largest relative
difference per file::

    python tests/test_reproduce_figures.py sim1 remus100      # or: all

Compared: every number and flag the committed file holds (a key the new file lacks fails; keys
the new file adds are extensions). Not compared: wall-clock times and the device count
(:data:`NOT_COMPARED`), which depend on the machine. Values at round-off level (the cross-track
error of a VCM on a line is ~1e-12 m) compare to :data:`ATOL` absolute (and are left out of the
largest relative difference the script prints).
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FIGURES = ROOT / "docs" / "figures"
RTOL = 1e-9
ATOL = 1e-12
#: values below this are round-off level (left out of the largest relative difference reported)
ROUND_OFF_LEVEL = 1e-9
#: keys that record the machine or the wall clock, not a result
NOT_COMPARED = {
    "wall_s",
    "devices",
    "timing",
    "tuning_wall_s",
    "total_wall_s",
    "module",  # a sweep's loop module as the config spelled its path
}

#: figure folder -> (command line after ``vcjax``, the file it writes, minutes on 2 cores)
CASES = {
    "sim1": (["simulate", "sim1"], "metrics.json", 1),
    "sim1_cross_current": (
        ["simulate", "sim1", "--current", "0.5", "0", "--horizon", "200"],
        "metrics.json",
        1,
    ),
    "sim2": (["simulate", "sim2"], "metrics.json", 1),
    "remus100": (["simulate", "remus100"], "metrics.json", 2),
    "demo": (["demo"], "metrics.json", 1),
    "sweep_puck": (["sweep", "examples/sweeps/puck.toml"], "summary.json", 1),
    "sweep": (["sweep", "examples/sweeps/quick.toml"], "summary.json", 8),
    "sweep_circle": (["sweep", "examples/sweeps/circle.toml"], "summary.json", 3),
    "sweep_survey": (["sweep", "examples/sweeps/survey.toml"], "summary.json", 3),
    "sweep_waves": (["sweep", "examples/sweeps/remus100_waves.toml"], "summary.json", 2),
    "tune": (["tune", "examples/tuning/acceptance.toml"], "summary.json", 2),
    "tune_sim2": (["tune", "examples/tuning/sim2.toml"], "summary.json", 8),
    "tune_arm": (["tune", "examples/tuning/arm.toml"], "summary.json", 14),
    "tune_waves": (["tune", "examples/tuning/remus100_waves.toml"], "summary.json", 15),
}


def differences(want, got, where: str = "") -> tuple[list[str], tuple[float, str]]:
    """``(mismatches, (largest relative difference, where))`` of ``got`` against ``want`` (JSON
    trees)."""
    bad: list[str] = []
    worst = (0.0, "")
    if isinstance(want, dict):
        if not isinstance(got, dict):
            return [f"{where}: expected an object, got {got!r}"], (math.inf, where)
        for k, w in want.items():
            if k in NOT_COMPARED:
                continue
            if k not in got:
                bad.append(f"{where}/{k}: missing")
                continue
            b, r = differences(w, got[k], f"{where}/{k}")
            bad += b
            worst = max(worst, r)
        return bad, worst
    if isinstance(want, list):
        if not isinstance(got, list) or len(got) != len(want):
            return [f"{where}: expected a list of {len(want)}, got {got!r}"], (math.inf, where)
        for i, (w, g) in enumerate(zip(want, got, strict=True)):
            b, r = differences(w, g, f"{where}[{i}]")
            bad += b
            worst = max(worst, r)
        return bad, worst
    if isinstance(want, bool) or want is None or isinstance(want, str):
        return ([] if got == want else [f"{where}: {got!r} != {want!r}"]), (0.0, where)
    if isinstance(got, bool) or not isinstance(got, int | float):
        return [f"{where}: expected a number, got {got!r}"], (math.inf, where)
    w, g = float(want), float(got)
    if math.isnan(w) or math.isnan(g):
        same = math.isnan(w) and math.isnan(g)
        return ([] if same else [f"{where}: {g!r} != {w!r}"]), (0.0, where)
    err = abs(g - w)
    rel = err / max(abs(w), abs(g)) if err else 0.0
    if err > ATOL + RTOL * max(abs(w), abs(g)):
        return [f"{where}: {g!r} != {w!r} (relative {rel:.2e})"], (rel, where)
    scale = max(abs(w), abs(g))
    return [], (rel if scale > ROUND_OFF_LEVEL else 0.0, where)


def reproduce(name: str, out: Path) -> tuple[list[str], float]:
    """Run the command of ``CASES[name]`` into ``out`` and compare its file to the committed one."""
    argv, fname, _ = CASES[name]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "VCJAX_CACHE_DIR": "off"}
    # as users run it: XLA's default optimisation level (the tests' conftest lowers it, and a
    # tune's optimiser path amplifies the last bit that changes)
    flags = re.sub(r"--xla_backend_optimization_level=\S+", "", env.get("XLA_FLAGS", ""))
    env["XLA_FLAGS"] = flags.strip()
    cmd = [sys.executable, "-m", "vcjax.cli", *argv, "--out", str(out)]
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        return [f"exit {proc.returncode}: {proc.stderr.strip()[-2000:]}"], math.inf
    want = json.loads((FIGURES / name / fname).read_text())
    got = json.loads((out / fname).read_text())
    return differences(want, got)


def test_the_comparison_catches_what_it_must():
    want = {"a": 1.0, "b": {"c": [1.0, 2.0], "ok": True}, "wall_s": 3.0, "z": 1e-13}
    assert differences(want, {**want, "wall_s": 9.0, "new": 1})[0] == []
    assert differences(want, {**want, "z": 5e-13})[0] == []  # round-off level
    assert differences(want, {**want, "a": 1.0 + 2e-9})[0]
    assert differences(want, {**want, "b": {"c": [1.0, 2.0], "ok": False}})[0]
    assert differences(want, {"a": 1.0, "wall_s": 3.0, "z": 1e-13})[0] == ["/b: missing"]
    assert differences(want, {**want, "b": {"c": [1.0], "ok": True}})[0]


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES, key=lambda n: CASES[n][2]))
def test_committed_figures_reproduce(name, tmp_path):
    bad, worst = reproduce(name, tmp_path / "out")
    assert not bad, f"{name}: {len(bad)} differences (largest relative {worst[0]:.2e}): {bad[:10]}"


def main(argv: list[str]) -> int:
    import argparse

    ap = argparse.ArgumentParser(
        prog="python tests/test_reproduce_figures.py",
        description="Re-run the commands behind docs/figures and compare to 1e-9 relative.",
    )
    ap.add_argument("names", nargs="*", help=f"some of {sorted(CASES)}, or all (default)")
    names = ap.parse_args(argv).names
    names = sorted(CASES, key=lambda n: CASES[n][2]) if names in ([], ["all"]) else names
    unknown = sorted(set(names) - set(CASES))
    if unknown:
        print(f"unknown: {unknown}; expected some of {sorted(CASES)}", file=sys.stderr)
        return 2
    failed = 0
    for name in names:
        with tempfile.TemporaryDirectory() as tmp:
            bad, worst = reproduce(name, Path(tmp) / "out")
        argv, fname, _ = CASES[name]
        verdict = "ok" if not bad else f"{len(bad)} DIFFERENCES"
        rel, at = worst
        print(
            f"{name}/{fname}: {verdict}, largest relative difference {rel:.2e} ({at})", flush=True
        )
        print(f"  vcjax {' '.join(argv)}", flush=True)
        for line in bad[:20]:
            print(f"  {line}", flush=True)
        failed += bool(bad)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
