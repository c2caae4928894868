"""Before/after of every loop (:mod:`benchmarks.perf.loops`) between an older vcjax revision
and this checkout, in alternating fresh processes.

``--before REV``'s ``vcjax/`` is extracted into a temporary folder; ``benchmarks.perf.loops`` runs
``--rounds`` times for each side, alternating (before, after, before, after, ...), each in a
fresh process whose ``vcjax`` is the extracted one or this checkout's (checked: the worker prints
the file it imported). For every (loop, kind) the best run of each side is kept and the ratio is
reported. The default revision is the last commit before the unrolled small solves
(``linalg.solve_small`` & co. replacing per-trajectory LAPACK calls in the 6-DOF loops).

    python -m benchmarks.compare.loops_before_after --loops odin remus100 \\
        --json benchmarks/results/loops_linalg_before_after.json
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks import _common as C
from benchmarks.compare.before_after import extract

#: last commit before the unrolled small dense solves (throughput round 2, issue 12)
BEFORE = "9855731"
ROOT = Path(__file__).resolve().parents[2]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--before", default=BEFORE, help="git revision measured as 'before'")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--loops", nargs="+", default=["odin", "remus100"])
    p.add_argument("--batch", type=int, default=256)
    p.add_argument("--steps", type=int, default=100)
    p.add_argument("--single-steps", type=int, default=2000)
    p.add_argument("--dtype", choices=("float32", "float64"), default="float32")
    p.add_argument("--json", type=Path, default=None)
    return p.parse_args(argv)


def run_side(args, lib: Path | None, out: Path) -> list[dict]:
    """``benchmarks.perf.loops`` in a fresh process (cwd outside the checkout, so that ``lib`` comes
    first on the path)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(lib), str(ROOT)] if lib else [str(ROOT)])
    env.pop("XLA_FLAGS", None)
    env.pop("VCJAX_CPU_DEVICES", None)
    probe = subprocess.run(
        [sys.executable, "-c", "import vcjax; print(vcjax.__file__)"],
        env=env,
        cwd=out.parent,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.strip()
    want = (lib / "vcjax") if lib else (ROOT / "vcjax")
    if Path(probe).parent.resolve() != want.resolve():
        raise RuntimeError(f"expected vcjax from {want}, the worker imports {probe}")
    cmd = [sys.executable, "-m", "benchmarks.perf.loops", "--loops", *args.loops]
    cmd += ["--batch", str(args.batch), "--steps", str(args.steps)]
    cmd += ["--single-steps", str(args.single_steps), "--dtype", args.dtype, "--json", str(out)]
    subprocess.run(cmd, env=env, cwd=out.parent, check=True, stdout=subprocess.DEVNULL)
    return json.loads(out.read_text())["rows"]


def main(argv=None):
    args = parse_args(argv)
    best: dict[tuple, dict] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        lib = tmp / "before"
        lib.mkdir()
        before_rev = extract(args.before, lib)
        for r in range(args.rounds):
            for side, path in (("before", lib), ("after", None)):
                rows = run_side(args, path, tmp / f"{side}_{r}.json")
                for row in rows:
                    key = (row["loop"], row["kind"])
                    cur = best.setdefault(key, {}).get(side)
                    if cur is None or row["run_s"] < cur["run_s"]:
                        best[key][side] = row
                print(f"  round {r + 1}: {side} done", flush=True)
    out = []
    for (loop, kind), v in best.items():
        b, a = v["before"], v["after"]
        out.append(
            {
                "loop": loop,
                "kind": kind,
                "batch": a["batch"],
                "cores_used": a["cores_used"],
                "before_steps_per_s": b["steps_per_s"],
                "after_steps_per_s": a["steps_per_s"],
                "speedup": a["steps_per_s"] / b["steps_per_s"],
                "before_compile_s": b["compile_s"],
                "after_compile_s": a["compile_s"],
                "load": a["load"],
            }
        )
    C.print_table(
        out,
        list(out[0]),
        f"loops: before ({before_rev[:9]}) / after (this checkout), best of "
        f"{args.rounds} alternating rounds, {args.dtype}",
    )
    C.write_json(args.json, args, out, before=before_rev)
    return out


if __name__ == "__main__":
    main()
