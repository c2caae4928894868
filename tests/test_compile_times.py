"""benchmarks/perf/compile_times.py runs end to end on one small loop and writes its JSON (no timing
assertions: the machine's load decides the times; the graph size is deterministic). Run as a
user runs it: ``python -m benchmarks compile_times ...`` in a fresh process."""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _benchmark(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "VCJAX_CACHE_DIR": "off"}
    return subprocess.run(
        [sys.executable, "-m", "benchmarks", "compile_times", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
    )


def test_compile_times_writes_json(tmp_path):
    out = tmp_path / "ct.json"
    r = _benchmark(
        *["--loops", "infante/vcm", "--steps", "5", "--tune", "none", "--no-compile"],
        *["--dtype", "float64", "--json", str(out)],
    )
    assert r.returncode == 0, r.stderr[-3000:]
    doc = json.loads(out.read_text())
    assert set(doc) == {"machine", "infante/vcm"}
    m = doc["machine"]
    assert {"cpu", "cores", "jax", "dtype"} <= set(m) and m["dtype"] == "float64"
    for kind in ("forward", "gradient"):
        r = doc["infante/vcm"][kind]
        assert set(r) == {"trace_s", "lower_s", "compile_s", "hlo_lines"}
        assert r["hlo_lines"] > 0 and r["trace_s"] >= 0 and r["lower_s"] >= 0
    # the reverse pass is a second scan: the gradient program is larger than the forward one
    assert doc["infante/vcm"]["gradient"]["hlo_lines"] > doc["infante/vcm"]["forward"]["hlo_lines"]


def test_compile_times_rejects_unknown_loop(tmp_path):
    r = _benchmark("--loops", "infante/nope", "--tune", "none", "--json", str(tmp_path / "x"))
    assert r.returncode != 0 and "unknown loop" in r.stderr
    assert not (tmp_path / "x").exists()
