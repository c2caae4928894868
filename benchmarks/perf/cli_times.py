"""Wall time of whole ``vcjax`` commands, cold and warm (issue 20's user-facing budgets).

Each command runs ``--runs`` times in a fresh process (``python -m vcjax.cli``, with this
checkout first on the path):

* ``cold``: an empty persistent compilation cache (a new ``VCJAX_CACHE_DIR`` per run);
* ``warm``: right after a cold run, the same command again with that cache (everything it
  compiles is read back; tracing still runs).

Wall time is measured around the process (start-up and imports included), the best and the
median of the runs are reported, with the 1-minute load average at each run (the machine may be
shared: compare runs of one invocation). Each run also records ``cpu_s``, the process's CPU
time (user + system, all its threads): on a loaded machine the wall time follows the share of
the cores a run got, its CPU time much less so. Outputs go to a temporary folder.

    python -m benchmarks.perf.cli_times --runs 3 --json benchmarks/results/cli_times.json
    python -m benchmarks.perf.cli_times --commands "tune examples/tuning/remus100.toml" --runs 1

``--before REV`` measures an older revision against this checkout (or ``--after REV``) in one
run: each round runs the command cold then warm with the before tree, then with the after tree
(each revision's ``vcjax``, ``tuning``, ``benchmarks`` and ``examples`` extracted with ``git
archive``), so both sides see the same load; the JSON holds ``{command: {side: {cold, warm}}}``.
A ``PYTHONPATH`` of the caller is kept after the tree's own folder.

    python -m benchmarks.perf.cli_times --before 7a685b9 --runs 1 \
        --commands "sweep examples/sweeps/remus100.toml" --json benchmarks/results/cli_times_ba.json
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import _common as C

ROOT = Path(__file__).resolve().parents[2]
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
    p.add_argument("--before", default=None, help="git revision to compare against (same run)")
    p.add_argument(
        "--after", default=None, help="with --before: the revision measured as after (default: "
        "this checkout)"
    )  # fmt: skip
    args = p.parse_args(argv)
    if args.runs < 1:
        p.error("--runs: expected a positive int")
    return args


def run_once(command: str, cache: Path, out: Path, root: Path = ROOT) -> dict:
    """One ``vcjax`` process of the tree ``root``; ``{"wall_s", "cpu_s", "load", "rc"}``."""
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "VCJAX_CPU_DEVICES")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(root), os.environ.get("PYTHONPATH")]))
    env["VCJAX_CACHE_DIR"] = str(cache)
    cmd = [sys.executable, "-m", "vcjax.cli", *shlex.split(command), "--out", str(out)]
    cmd += ["--overwrite"]
    load = C.load_average()
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    res = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)
    if res.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({res.returncode}):\n{res.stderr[-3000:]}")
    return {"wall_s": wall, "cpu_s": round(cpu, 3), "load": load, "rc": res.returncode}


def _stats(runs: list[dict]) -> dict:
    walls, cpus = [r["wall_s"] for r in runs], [r["cpu_s"] for r in runs]
    return {
        "min_s": min(walls),
        "median_s": statistics.median(walls),
        "min_cpu_s": min(cpus),
        "median_cpu_s": statistics.median(cpus),
        "runs": runs,
    }


def before_after(args, doc: dict) -> dict:
    """``--before``: both trees, cold then warm, alternating within each round."""
    from benchmarks.perf.compile_times import _extract

    with tempfile.TemporaryDirectory() as tmp:
        roots = {"before": Path(tmp) / "before", "after": ROOT}
        roots["before"].mkdir()
        doc["machine"]["before"] = _extract(args.before, roots["before"])
        doc["machine"]["after"] = "this checkout"
        if args.after:
            roots["after"] = Path(tmp) / "after"
            roots["after"].mkdir()
            doc["machine"]["after"] = _extract(args.after, roots["after"])
        for command in args.commands:
            runs = {side: {"cold": [], "warm": []} for side in roots}
            for _ in range(args.runs):
                for side, root in roots.items():
                    with tempfile.TemporaryDirectory() as t:
                        cache, out = Path(t) / "cache", Path(t) / "out"
                        runs[side]["cold"].append(run_once(command, cache, out, root))
                        if not args.no_warm:
                            runs[side]["warm"].append(run_once(command, cache, out, root))
            doc[command] = {
                side: {k: _stats(v) for k, v in r.items() if v} for side, r in runs.items()
            }
            for kind in ("cold", "warm"):
                if kind not in doc[command]["before"]:
                    continue
                b, a = doc[command]["before"][kind], doc[command]["after"][kind]
                loads = ", ".join(f"{r['load']:.1f}" for s in (b, a) for r in s["runs"])
                print(
                    f"vcjax {command}: {kind} before {b['min_s']:.1f} s, after {a['min_s']:.1f} s "
                    f"({b['min_s'] / a['min_s']:.2f}x; CPU time, median: before "
                    f"{b['median_cpu_s']:.1f} s, after {a['median_cpu_s']:.1f} s; load {loads})",
                    flush=True,
                )
    return doc


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
    if args.before:
        before_after(args, doc)
    for command in [] if args.before else args.commands:
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
                    f"{s['median_s']:.1f} s over {len(s['runs'])} runs (CPU time, median "
                    f"{s['median_cpu_s']:.1f} s; load {loads})",
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
