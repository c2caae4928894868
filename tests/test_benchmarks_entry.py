"""The benchmarks' one entry point (``python -m benchmarks``, run as a user runs it, in a fresh
process): it finds every benchmark of the three folders, refuses an unknown name, every step of
``--all`` names one that exists, and every benchmark runs (:data:`SMOKE`: its quickest mode at tiny sizes, outputs into a temporary folder;
nothing timed or compared), so a refactor cannot silently break one."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GROUPS = ("perf", "compare", "studies")


def _entry(*args: str) -> subprocess.CompletedProcess:
    """``python -m benchmarks ARGS`` from the repository root, as a user runs it."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "VCJAX_CACHE_DIR": "off"}
    return subprocess.run(
        [sys.executable, "-m", "benchmarks", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
    )


@pytest.fixture(scope="module")
def listed() -> dict[str, tuple[str, str]]:
    """``{name: (group, its line)}`` of ``python -m benchmarks --list``."""
    r = _entry("--list")
    assert r.returncode == 0, r.stderr
    out, group = {}, None
    for line in r.stdout.splitlines():
        if m := re.match(r"(\w+)/  \(", line):
            group = m.group(1)
        elif group and (m := re.match(r"  (\w+) +(.*)$", line)):
            out[m.group(1)] = (group, m.group(2))
    return out


def test_every_benchmark_is_listed_under_its_question(listed):
    found = {p.stem: p.parent.name for g in GROUPS for p in (ROOT / "benchmarks" / g).glob("*.py")}
    found = {k: v for k, v in found.items() if not k.startswith("_")}
    assert {k: g for k, (g, _) in listed.items()} == found
    assert all(doc for _, doc in listed.values()), "a benchmark without a docstring"
    assert not list((ROOT / "benchmarks").glob("[!_]*.py")), "a benchmark outside the folders"


def test_every_step_of_all_names_a_benchmark_and_writes_into_results(listed):
    r = _entry("--all", "--dry-run")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    steps = [(a, b) for a, b in zip(lines[::2], lines[1::2], strict=True)]
    assert steps and all(re.match(r"\[\d+/\d+\] -m ", a) for a, _ in steps)
    for line, sink in steps:
        args = line.split()[2:]
        name = args[0].rsplit(".", 1)[-1]
        assert args[0] == "vcjax.cli" or args[0] == f"benchmarks.{listed[name][0]}.{name}"
        stdout = sink.removeprefix("  > ")
        assert stdout == "-" or stdout.startswith("benchmarks/results/")
        if "--json" in args:
            assert args[args.index("--json") + 1].startswith("benchmarks/results/")


def test_unknown_name_exits_2_with_one_line():
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks", "nope"], cwd=ROOT, capture_output=True, text=True
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown benchmark 'nope'" in lines[0]


#: a tuning problem small enough to compile in seconds (2 s of Simulation 1, Euler, 2 scenarios)
TINY_TUNE = """
[problem]
variant = "vcm_integral"
horizon = 2.0
dt = 0.1
integrator = "euler"
timing = "sampled"
[train]
size = 2
seed = 0
[heldout]
size = 2
seed = 1001
[optimizer]
name = "lbfgs"
steps = 2
"""

#: every benchmark's smoke run: its arguments ({tmp}: a temporary folder; {tune}: TINY_TUNE
#: written there), and the reason when it is too long for the default suite (marked slow)
SMOKE = {
    "cli_times": (["--commands", "tune {tune}", "--runs", "1", "--no-warm"]
                  + ["--json", "{tmp}/c.json"],
                  "a whole vcjax tune in a fresh process: 12 s on a quiet 2-core machine"),
    "compile_times": (["--loops", "infante", "--kinds", "forward", "--steps", "10"]
                      + ["--tune", "{tune}", "--no-compile", "--json", "{tmp}/c.json"], None),
    "cost_analysis": (["--repeats", "1", "--batch", "4", "--steps", "10", "--matmul-n", "8"]
                      + ["--iters", "2", "--json", "{tmp}/c.json"],
                      "compiles ~15 programs (horizons x timings, kernels, 7 component loops) "
                      "whatever the sizes: 80 s on a loaded 2-core machine"),
    "gradient_cost": (["--quick", "--no-memory", "--batches", "1", "--steps", "10"]
                      + ["--repeats", "1", "--json", "{tmp}/c.json"],
                      "compiles every gradient variant (reverse, checkpointed, forward) whatever "
                      "the sizes: 95 s on a loaded 2-core machine"),
    "layout": (["--repeats", "1", "--batch", "4", "--steps", "10", "--json", "{tmp}/c.json"],
               None),
    "loops": (["--repeats", "1", "--loops", "infante/vcm", "--cpu-devices", "1", "--batch", "4"]
              + ["--steps", "10", "--single-steps", "10", "--json", "{tmp}/c.json"], None),
    "numpy_baseline": (["--repeats", "1", "--np-steps", "10", "--np-batch", "4"]
                       + ["--np-batch-steps", "5", "--jax-steps", "10", "--jax-batch", "4"]
                       + ["--json", "{tmp}/c.json"], None),
    "numpy_remus100": (["--repeats", "1", "--np-steps", "10", "--np-batch", "4"]
                       + ["--np-batch-steps", "5", "--jax-batch", "4", "--json", "{tmp}/c.json"],
                       None),
    "plot_throughput": (["benchmarks/results/throughput_float32_sampled_1core.json"]
                        + ["--out", "{tmp}/t.png"], None),
    "sharded_gradient": (["--repeats", "1", "--batch", "4", "--steps", "10"]
                         + ["--json", "{tmp}/c.json"],
                         "compiles the tuner's gradient twice on two devices (shared and tiled "
                         "gains) whatever the sizes: 5 min on a loaded 2-core machine"),
    "throughput": (["--quick", "--repeats", "1", "--batches", "4", "--steps", "10"]
                   + ["--compile-horizons", "10", "20", "--compile-batch", "4"]
                   + ["--json", "{tmp}/c.json"], None),
    "waves_cost": (["--repeats", "1", "--batch", "4", "--steps", "10", "--components", "4"]
                   + ["--sweep-batch", "4", "--sweep-steps", "10", "--json", "{tmp}/c.json"],
                   "compiles the sea's plant rows and a closed-loop sweep whatever the sizes: "
                   "8 min on a loaded 2-core machine"),
    "before_after": (["--kinds", "single", "--timings", "sampled", "--rounds", "1"]
                     + ["--repeats", "1", "--single-steps", "10", "--json", "{tmp}/c.json"],
                     "extracts an older revision (git archive) and compiles it and this checkout "
                     "in alternating fresh processes"),
    "loops_before_after": (["--rounds", "1", "--loops", "odin", "--batch", "4", "--steps", "10"]
                           + ["--single-steps", "10", "--json", "{tmp}/c.json"],
                           "extracts an older revision (git archive) and compiles it and this "
                           "checkout in alternating fresh processes"),
    "tuners": (["{tune}", "--quick", "--tuners", "gradient,cmaes,bayes", "--out", "{tmp}"]
               + ["--json", "{tmp}/t.json"], None),
}  # fmt: skip


def smoke_args(name: str, tmp) -> list[str]:
    """The smoke-run arguments of benchmark ``name`` with its temporary folder ``tmp``."""
    tune = Path(tmp) / "tiny_tune.toml"
    tune.write_text(TINY_TUNE)
    return [a.replace("{tmp}", str(tmp)).replace("{tune}", str(tune)) for a in SMOKE[name][0]]


def test_every_benchmark_has_a_smoke_run(listed):
    assert set(SMOKE) == set(listed)


@pytest.mark.parametrize(
    "name",
    [
        pytest.param(n, marks=pytest.mark.slow(reason=why)) if why else n
        for n, (_, why) in SMOKE.items()
    ],
)
def test_every_benchmark_runs_in_its_smoke_mode(name, tmp_path):
    """``python -m benchmarks NAME ...`` exits 0 (no compilation cache: nothing outside
    ``tmp_path`` is written)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT), "VCJAX_CACHE_DIR": "off"}
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks", name, *smoke_args(name, tmp_path)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 0, f"{name} exited {r.returncode}:\n{r.stderr[-3000:]}"
    for out in ("c.json", "t.json", "t.png"):  # what it was asked to write, it wrote
        if f"{{tmp}}/{out}" in SMOKE[name][0]:
            assert (tmp_path / out).stat().st_size > 0, f"{name}: no {out}"
    if name == "tuners":
        rep = json.loads((tmp_path / "t.json").read_text())
        assert list(rep["runs"]["cold"]) == ["gradient", "cmaes", "bayes"]
        assert rep["summary"]["target"] == min(
            r["best_heldout"] for r in rep["runs"]["cold"].values()
        )
