"""Reading an optimised HLO module's text: the ``while`` bodies (a rollout's scan), the kernels
of the largest one, the all-reduces inside them. Shared by the tests (``test_bench_kernels``,
``test_tuning``) and the benchmarks that report them (``benchmarks/perf/cost_analysis.py``,
``benchmarks/perf/sharded_gradient.py``)."""

from __future__ import annotations

import re

__all__ = ["KERNEL_OPS", "while_bodies", "while_body_kernels", "loop_allreduces"]

#: opcodes of a ``while`` body's top-level instructions that each run as one kernel on the CPU
KERNEL_OPS = ("fusion", "dot", "custom-call", "call", "convolution", "sort", "scatter", "gather")


def while_bodies(hlo_text: str) -> list[str]:
    """The text of every ``while`` body computation in an optimised HLO module's text."""
    names = re.findall(r"\bwhile\(.*?body=%?([\w.\-]+)", hlo_text)
    blocks = dict(re.findall(r"^%?([\w.\-]+) [^\n]*\{\n(.*?)^\}", hlo_text, re.S | re.M))
    return [blocks.get(n, "") for n in names]


def while_body_kernels(hlo_text: str) -> dict:
    """Count the kernels of the largest ``while`` body in an optimised HLO module's text: its
    top-level instructions by opcode (``KERNEL_OPS``; everything else, e.g. tuples, bitcasts,
    parameters and constants, launches nothing)."""
    best = {}
    for body in while_bodies(hlo_text):
        counts = dict.fromkeys(KERNEL_OPS, 0)
        for line in body.splitlines():
            m = re.match(r"\s*(?:ROOT )?%?[\w.\-]+ = [^=]*?\s([a-z\-]+)\(", line)
            if m and m.group(1) in counts:
                counts[m.group(1)] += 1
        counts = {k: v for k, v in counts.items() if v}
        if sum(counts.values()) > sum(best.values()):
            best = counts
    return {**best, "total": sum(best.values())}


def loop_allreduces(hlo_text: str) -> int:
    """``all-reduce`` instructions inside the ``while`` bodies of an HLO module's text."""
    return sum(body.count("all-reduce(") for body in while_bodies(hlo_text))
