"""Figures (Matplotlib, Agg backend: files, never windows): public helpers and one module per
experiment and one for sweeps.

* [`pyplot`][vcjax.plots.pyplot] -- ``matplotlib.pyplot`` with the Agg backend selected;
* [`save`][vcjax.plots.save] -- lay a figure out, write it (PNG, 120 dpi), close it; returns the
path;
* ``STYLE`` -- the line style of each INFANTE-class controller (experiments and sweeps);
* [`vcjax.plots.sim1`][vcjax.plots.sim1], [`vcjax.plots.sim2`][vcjax.plots.sim2],
[`vcjax.plots.remus100`][vcjax.plots.remus100],
  [`vcjax.plots.arm`][vcjax.plots.arm] -- the figures of each experiment
  ([`vcjax.experiments`][vcjax.experiments]);
* [`vcjax.plots.sweep`][vcjax.plots.sweep] -- the figures of a Monte-Carlo sweep (the CLI draws them
from the
  result [`vcjax.sweep.run_sweep_config`][vcjax.sweep.config.run_sweep_config] returns).

Layering: figures sit above loops, sweep and tuning; they read results (trajectories, sweep
results) and never run a simulation. Only experiments, the CLI and the tuning/fit reports import
them.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["pyplot", "save", "STYLE"]

#: Line styles of the INFANTE-class controllers, Simulation 1's variants (the paper: solid blue
#: with integral action, dashed red without); sweeps use them too.
STYLE = {
    "vcm_integral": dict(color="C0", ls="-", label="VCM + integral (41)"),
    "vcm": dict(color="C3", ls="--", label="VCM (31)/(38)"),
    "ilos": dict(color="C2", ls="-.", label="ILOS (40)"),
    "los_pid": dict(color="C1", ls=":", label="LOS + PID yaw (39)"),
    "vcm_ilos": dict(color="C4", ls=(0, (5, 1, 1, 1)), label="VCM + (41) + ILOS angle (ext.)"),
    "alos": dict(color="C5", ls=(0, (3, 1, 1, 1, 1, 1)), label="ALOS (Fossen 2023)"),
}


def pyplot():
    """``matplotlib.pyplot`` with the non-interactive Agg backend."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save(fig, path) -> Path:
    """Lay ``fig`` out, write it to ``path`` (120 dpi; atomically: a temporary file renamed, so
    an interrupted run never leaves half a PNG) and close it; returns ``Path(path)``."""
    from vcjax.runtime.outputs import savefig_atomic

    path = Path(path)
    fig.tight_layout()
    savefig_atomic(fig, path, dpi=120)
    pyplot().close(fig)
    return path
