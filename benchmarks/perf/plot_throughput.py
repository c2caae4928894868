"""Figure of the throughput benchmark: trajectory-steps/s against batch size, one curve per
file (dtype, controller timing, cores used).

Reads the ``--json`` files written by :mod:`benchmarks.perf.throughput` and writes a PNG::

    python -m benchmarks.perf.plot_throughput benchmarks/results/throughput_*.json \
        --out benchmarks/results/throughput.png
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

TARGET_BATCH = 6e6  # issue 12: >= 6 M steps/s (sampled controller, 8192 scenarios, float32)
TARGET_SINGLE = 400e3  # issue 12: a single trajectory >= 400 k steps/s (sampled)


def main(argv=None) -> Path:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("json", nargs="+", help="throughput JSON files (one per dtype)")
    p.add_argument("--out", default="benchmarks/results/throughput.png")
    p.add_argument(
        "--per-cpu",
        action="store_true",
        help="plot trajectory-steps per CPU-second (batch x steps / process CPU time of the "
        "timed call): on a machine shared with other jobs, what a core does, not what the "
        "run got",
    )
    args = p.parse_args(argv)

    def rate(r):
        if not args.per_cpu:
            return r["steps_per_s"]
        return r["batch"] * r["steps"] / r["cpu_s"]

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    device = ""
    for f in args.json:
        rows = json.loads(Path(f).read_text())["rows"]
        vmap = sorted((r for r in rows if r["kind"] == "vmap"), key=lambda r: r["batch"])
        single = [r for r in rows if r["kind"] == "single"]
        if not vmap:
            raise SystemExit(f"{f}: no 'vmap' rows")
        dtype, device = vmap[0]["dtype"], vmap[0]["device"]
        timing = vmap[0].get("timing", "continuous")
        cores = max(r.get("cores_used", 1) for r in vmap)
        tag = f"{dtype}, {timing}, {cores} core{'s' if cores > 1 else ''}"
        if "round1" in Path(f).stem:
            tag += ", round 1 (before)"
        b = np.array([r["batch"] for r in vmap])
        (line,) = ax.loglog(b, [rate(r) for r in vmap], "o-", label=f"vmap, {tag}")
        if single:
            ax.loglog(
                [1],
                [rate(single[0])],
                "s",
                color=line.get_color(),
                label=f"single (no vmap), {dtype}, {timing}",
            )
    ax.axhline(TARGET_BATCH, color="k", ls="--", lw=0.8, label="target, sampled, batch 8192")
    ax.axhline(TARGET_SINGLE, color="k", ls=":", lw=0.8, label="target, single, sampled")
    ax.set_xlabel("batch size (trajectories)")
    ax.set_ylabel("trajectory-steps per " + ("CPU-second" if args.per_cpu else "second"))
    ax.set_title(f"Simulation 1 closed loop, RK4 — {device}")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(args.out)
    fig.savefig(out, dpi=120)
    plt.close(fig)
    print(f"wrote {out}")
    return out


if __name__ == "__main__":
    main()
