"""The one entry point of the benchmarks.

    python -m benchmarks                         # list them, by question
    python -m benchmarks NAME [ARGS ...]         # run one (ARGS go to it; NAME --help)
    python -m benchmarks --all [--python PY]     # every measurement of benchmarks/README.md
    python -m benchmarks --all --dry-run         # ... only listed, not run

Every benchmark is a module of ``benchmarks/perf`` (how fast), ``benchmarks/compare`` (git A/B:
an older revision against this checkout) or ``benchmarks/studies`` (questions answered by
running the library many times). Each runs in a fresh process (it chooses the dtype and the
number of CPU devices before JAX starts) and writes its JSON into ``benchmarks/results/`` when
asked (``--json FILE``). ``--all`` runs the README's measurements one after the other (~25 min
on a quiet 2-core machine), from the repository root.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
#: folder -> the question its benchmarks answer
GROUPS = {
    "perf": "performance: throughput, compile time, program size, per-step cost",
    "compare": "git A/B: an older revision against this checkout",
    "studies": "studies: running the library many times to answer a question",
}
R = "benchmarks/results"

#: ``--all``: (benchmark or ``vcjax``, arguments, file the console output goes to, environment);
#: a ``vcjax sweep`` writes into a temporary ``{tmp}`` folder whose ``summary.json`` is kept as
#: the ``.json`` beside its console output
ALL = [
    ("before_after", ["--json", f"{R}/before_after_float32.json"], None, {}),
    (
        "before_after",  # the streamed sweep against the last commit storing whole trajectories
        ["--before", "b39f07b", "--kinds", "sweep", "--batch", "8192", "--steps", "3000"]
        + ["--json", f"{R}/before_after_sweep_float32.json"],
        f"{R}/before_after_sweep_float32.txt",
        {},
    ),
    *(
        (
            "vcjax",
            ["sweep", "benchmarks/configs/sweep_8192x3000.toml", "--no-x64", "--overwrite"]
            + ["--out", "{tmp}"],  # its summary.json is kept as the JSON below
            f"{R}/sweep_8192x3000_devices{n}.txt",
            {"VCJAX_CPU_DEVICES": str(n)},
        )
        for n in (1, 2)
    ),
    *(
        (
            "throughput",
            ["--timing", t, "--cpu-devices", str(n), "--batches", "1", "16", "256", "4096"]
            + ["16384", "--json", f"{R}/throughput_float32_{t}_{n}core.json"],
            f"{R}/throughput_float32_{t}_{n}core.txt",
            {},
        )
        for t in ("sampled", "continuous")
        for n in (1, 2)
    ),
    (
        "plot_throughput",
        [
            f"{R}/throughput_float32_{t}_{n}core.json"
            for t in ("sampled", "continuous")
            for n in (1, 2)
        ]
        + ["--out", f"{R}/throughput.png"],
        None,
        {},
    ),
    (
        "loops",
        ["--loops", "infante", "--json", f"{R}/loops_float32.json"],
        f"{R}/loops_float32.txt",
        {},
    ),
    *(
        (
            "loops",
            [
                "--loops",
                v,
                "--batch",
                "256",
                "--steps",
                "100",
                "--json",
                f"{R}/loops_{v}_float32.json",
            ],
            f"{R}/loops_{v}_float32.txt",
            {},
        )
        for v in ("odin", "remus100")
    ),
    (
        "numpy_remus100",
        ["--cpu-devices", "2", "--json", f"{R}/remus100_float32.json"],
        f"{R}/remus100_float32.txt",
        {},
    ),
    ("cost_analysis", ["--quick", "--json", f"{R}/cost_float32.json"], f"{R}/cost_float32.txt", {}),
    (
        "gradient_cost",
        ["--batches", "1024", "--no-memory", "--json", f"{R}/gradient_b1024_float32.json"],
        f"{R}/gradient_b1024_float32.txt",
        {},
    ),
    (
        "gradient_cost",
        ["--batches", "1024", "--no-memory", "--timing", "sampled"]
        + ["--json", f"{R}/gradient_b1024_sampled_float32.json"],
        f"{R}/gradient_b1024_sampled_float32.txt",
        {},
    ),
    ("layout", ["--json", f"{R}/layout_float32.json"], f"{R}/layout_float32.txt", {}),
    (
        "loops_before_after",  # the unrolled small solves on the 6-DOF loops
        ["--json", f"{R}/loops_linalg_before_after.json"],
        f"{R}/loops_linalg_before_after.txt",
        {},
    ),
    (
        "sharded_gradient",  # the tuner's gradient on a sharded batch: shared vs tiled gains
        ["--json", f"{R}/sharded_gradient_float32.json"],
        f"{R}/sharded_gradient_float32.txt",
        {},
    ),
]


def benchmarks() -> dict[str, tuple[str, str]]:
    """``{name: (group, first line of its docstring)}``, read from the sources (nothing is
    imported: each benchmark sets up JAX itself)."""
    out = {}
    for group in GROUPS:
        for path in sorted((HERE / group).glob("*.py")):
            if path.name.startswith("_"):
                continue
            doc = ast.get_docstring(ast.parse(path.read_text())) or ""
            out[path.stem] = (group, " ".join(doc.split("\n\n")[0].split()))
    return out


def module(name: str) -> str:
    """The module path of benchmark ``name`` (``ValueError`` listing the known ones)."""
    known = benchmarks()
    if name not in known:
        raise ValueError(f"unknown benchmark {name!r}; expected one of {sorted(known)}")
    return f"benchmarks.{known[name][0]}.{name}"


def listing() -> str:
    known = benchmarks()
    lines = []
    for group, what in GROUPS.items():
        lines.append(f"{group}/  ({what})")
        for name, (g, doc) in known.items():
            if g == group:
                short = doc if len(doc) <= 88 else doc[:85] + "..."
                lines.append(f"  {name:<20} {short}")
    return "\n".join(lines)


def command(name: str, args: list[str], python: str = sys.executable) -> list[str]:
    """The command line of one benchmark (``vcjax``: the CLI)."""
    target = "vcjax.cli" if name == "vcjax" else module(name)
    return [python, "-m", target, *args]


def run_all(python: str = sys.executable, dry_run: bool = False) -> int:
    """Every measurement of ``benchmarks/README.md``, one after the other (stop at a failure);
    ``dry_run``: only print them (with ``> FILE``, where the console output goes)."""
    env = {**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH") or str(ROOT)}
    for i, (name, args, stdout, extra) in enumerate(ALL):
        with tempfile.TemporaryDirectory() as tmp:
            cmd = command(name, [a.replace("{tmp}", tmp) for a in args], python)
            print(f"[{i + 1}/{len(ALL)}] {' '.join(cmd[1:])}", flush=True)
            if dry_run:
                print(f"  > {stdout}" if stdout else "  > -", flush=True)
                continue
            sink = open(ROOT / stdout, "w") if stdout else None  # noqa: SIM115
            try:
                rc = subprocess.run(cmd, cwd=ROOT, env={**env, **extra}, stdout=sink).returncode
            finally:
                if sink:
                    sink.close()
            if rc:
                print(f"benchmarks: {name} exited {rc}", file=sys.stderr)
                return rc
            if "{tmp}" in args:
                shutil.copyfile(Path(tmp) / "summary.json", ROOT / stdout.replace(".txt", ".json"))
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help", "--list"):
        print(__doc__.strip() + "\n\n" + listing())
        return 0
    if argv[0] == "--all":
        dry_run = "--dry-run" in argv
        argv = [a for a in argv if a != "--dry-run"]
        python = argv[2] if argv[1:2] == ["--python"] and len(argv) > 2 else sys.executable
        return run_all(python, dry_run)
    try:
        cmd = command(argv[0], argv[1:])
    except ValueError as err:
        print(f"benchmarks: {err}", file=sys.stderr)
        return 2
    env = {**os.environ, "PYTHONPATH": os.environ.get("PYTHONPATH") or str(ROOT)}
    return subprocess.run(cmd, cwd=ROOT, env=env).returncode


if __name__ == "__main__":
    sys.exit(main())
