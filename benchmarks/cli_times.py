"""Wall time of whole ``vcjax`` commands, cold and warm (issue 20's user-facing budgets).

Each command runs ``--runs`` times in a fresh process (``python -m vcjax.cli``, with this
checkout first on the path):

* ``cold``: an empty persistent compilation cache (a new ``VCJAX_CACHE_DIR`` per run);
* ``warm``: right after a cold run, the same command again with that cache (everything it
  compiles is read back; tracing still runs).

Wall time is measured around the process (start-up and imports included), the best and the
median of the runs are reported, with the 1-minute load average at each run (the machine may be
shared: compare runs of one invocation). Outputs go to a temporary folder.

    python -m benchmarks.cli_times --runs 3 --json benchmarks/results/cli_times.json
    python -m benchmarks.cli_times --commands "tune examples/tuning/remus100.toml" --runs 1
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import _common as C

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_JSON = ROOT / "benchmarks" / "results" / "cli_times.json"
#: the commands of the budgets: ``vcjax tune`` cold and warm, ``vcjax sweep`` cold
COMMANDS = ("tune examples/tuning/remus100.toml", "sweep examples/sweeps/remus100.toml")


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument(
        "--commands",
        nargs="+",
        default=list(COMMANDS),
        help="vcjax commands without --out (each quoted), default: the budgets' tune and sweep",
    )
    p.add_argument("--runs", type=int, default=3, help="runs of each (default 3)")
    p.add_argument("--no-warm", action="store_true", help="cold runs only")
    p.add_argument("--json", type=Path, default=DEFAULT_JSON, help="output JSON file")
    args = p.parse_args(argv)
    if args.runs < 1:
        p.error("--runs: expected a positive int")
    return args


def run_once(command: str, cache: Path, out: Path) -> dict:
    """One ``vcjax`` process; ``{"wall_s", "load", "rc"}``."""
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "VCJAX_CPU_DEVICES")}
    env["PYTHONPATH"] = str(ROOT)
    env["VCJAX_CACHE_DIR"] = str(cache)
    cmd = [sys.executable, "-m", "vcjax.cli", *shlex.split(command), "--out", str(out)]
    cmd += ["--overwrite"]
    load = C.load_average()
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({res.returncode}):\n{res.stderr[-3000:]}")
    return {"wall_s": wall, "load": load, "rc": res.returncode}


def _stats(runs: list[dict]) -> dict:
    walls = [r["wall_s"] for r in runs]
    return {"min_s": min(walls), "median_s": statistics.median(walls), "runs": runs}


def main(argv=None) -> dict:
    args = parse_args(argv)
    doc: dict = {
        "machine": {
            "cpu": C.cpu_model(),
            "cores": os.cpu_count(),
            "python": sys.version.split()[0],
            "load_average_1min_at_start": C.load_average(),
        }
    }
    for command in args.commands:
        cold, warm = [], []
        for _ in range(args.runs):
            with tempfile.TemporaryDirectory() as tmp:
                cache, out = Path(tmp) / "cache", Path(tmp) / "out"
                cold.append(run_once(command, cache, out))
                if not args.no_warm:
                    warm.append(run_once(command, cache, out))
        doc[command] = {"cold": _stats(cold)}
        if warm:
            doc[command]["warm"] = _stats(warm)
        for kind in ("cold", "warm"):
            if kind in doc[command]:
                s = doc[command][kind]
                loads = ", ".join(f"{r['load']:.1f}" for r in s["runs"])
                print(
                    f"vcjax {command}: {kind} min {s['min_s']:.1f} s, median "
                    f"{s['median_s']:.1f} s over {len(s['runs'])} runs (load {loads})",
                    flush=True,
                )
    doc["machine"]["load_average_1min_at_end"] = C.load_average()
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
        print(f"wrote {args.json}")
    return doc


if __name__ == "__main__":
    main()
