"""The benchmarks' one entry point (``python -m benchmarks``): it finds every benchmark of the
three folders, refuses an unknown name, and every step of ``--all`` names one that exists."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from benchmarks import __main__ as entry  # noqa: E402


def test_every_benchmark_is_listed_under_its_question():
    found = {
        p.stem: p.parent.name for g in entry.GROUPS for p in (ROOT / "benchmarks" / g).glob("*.py")
    }
    found = {k: v for k, v in found.items() if not k.startswith("_")}
    listed = entry.benchmarks()
    assert {k: g for k, (g, _) in listed.items()} == found
    assert all(doc for _, doc in listed.values()), "a benchmark without a docstring"
    assert not list((ROOT / "benchmarks").glob("[!_]*.py")), "a benchmark outside the folders"
    assert entry.module("tuners") == "benchmarks.studies.tuners"
    with pytest.raises(ValueError, match="unknown benchmark 'nope'"):
        entry.module("nope")


def test_every_step_of_all_names_a_benchmark_and_writes_into_results():
    for name, args, stdout, _ in entry.ALL:
        assert name == "vcjax" or entry.module(name)
        assert stdout is None or stdout.startswith("benchmarks/results/")
        if "--json" in args:
            assert args[args.index("--json") + 1].startswith("benchmarks/results/")


def test_unknown_name_exits_2_with_one_line():
    r = subprocess.run(
        [sys.executable, "-m", "benchmarks", "nope"], cwd=ROOT, capture_output=True, text=True
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "unknown benchmark 'nope'" in lines[0]
