"""A one-line progress bar for long jobs (sweeps, tuning), written to stderr.

``ProgressBar(total, label)``; ``update(note)`` advances by one, ``show(k, note)`` jumps to ``k``;
each redraw shows ``label [#####---] k/total pct elapsed ~left note``. With ``sink`` (a callable)
it hands one plain line per update to it instead (logs, notebooks).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

__all__ = ["ProgressBar"]


class ProgressBar:
    """Progress of ``total`` units of work.

    Args:
        total: number of units (>= 1).
        label: text in front of the bar.
        stream: where the bar is drawn (default: ``sys.stderr``).
        width: characters of the bar.
        sink: optional ``f(line)`` that receives one plain line per update instead of a redrawn
            bar.
        warmup: number of first units whose time includes one-off work (compiling): the ETA
            is based on the units after them only (before that it reads ``ETA after warm-up``).
    """

    def __init__(
        self,
        total: int,
        label: str = "",
        stream=None,
        width: int = 24,
        sink: Callable[[str], object] | None = None,
        warmup: int = 0,
    ):
        self.total, self.label, self.width = max(1, int(total)), label, width
        self.stream = sys.stderr if stream is None else stream
        self.sink = sink
        self.done = 0
        self.t0 = time.perf_counter()
        self._closed = False
        self.warmup = max(0, int(warmup))
        self.warmup_s: float | None = None  # elapsed time when the warm-up units were done

    def update(self, note: str = "") -> None:
        """Advance by one unit."""
        self.show(self.done + 1, note)

    def show(self, k: int, note: str = "") -> None:
        """Draw the bar at ``k`` of ``total`` units (with the ETA from the elapsed time)."""
        self.done = min(int(k), self.total)
        elapsed = time.perf_counter() - self.t0
        if self.warmup and self.warmup_s is None and self.done >= self.warmup:
            self.warmup_s = elapsed
        frac = self.done / self.total
        if not self.warmup:
            left = elapsed / max(self.done, 1) * (self.total - self.done)
            timing = f"{elapsed:.1f} s, ~{left:.0f} s left"
        elif self.done <= self.warmup or self.warmup_s is None:
            timing = f"{elapsed:.1f} s (incl. compiling), ETA after warm-up"
        else:
            per = (elapsed - self.warmup_s) / (self.done - self.warmup)
            left = per * (self.total - self.done)
            timing = f"{elapsed:.1f} s, ~{left:.0f} s left ({per:.2g} s/step)"
        if self.sink is not None:
            self.sink(f"{self.label.strip()}: {self.done}/{self.total} {note} {timing}".rstrip())
            return
        n = int(round(self.width * frac))
        bar = "#" * n + "-" * (self.width - n)
        line = f"\r{self.label}[{bar}] {self.done}/{self.total} {100 * frac:3.0f}% {timing} {note}"
        self.stream.write(line.ljust(90))
        if self.done >= self.total:
            self.close()
        self.stream.flush()

    def close(self) -> None:
        """End the line (once)."""
        if not self._closed and self.sink is None:
            self.stream.write("\n")
            self.stream.flush()
        self._closed = True
