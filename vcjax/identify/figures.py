"""Figures of ``vcjax fit``: measured vs predicted states, and the cost history."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np

from vcjax.plots import pyplot

__all__ = ["prediction_figure", "cost_history_figure"]


def prediction_figure(result, log, pred_initial, pred_fitted, path, index: int = 0) -> Path:
    """Every state channel of one log: measured, and the free simulation from the first sample
    with the initial and with the fitted parameters (angles in degrees)."""
    plt = pyplot()
    model = result.problem.model
    cols, units = model.state_columns, model.units
    n = len(cols)
    ncol = 3
    nrow = math.ceil(n / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(12, 2.1 * nrow), sharex=True)
    axes = np.atleast_1d(axes).ravel()
    t = log.t
    for i, (c, unit) in enumerate(zip(cols, units, strict=True)):
        ax = axes[i]
        conv = (180.0 / math.pi) if unit in ("rad", "rad/s") else 1.0
        label_unit = {"rad": "deg", "rad/s": "deg/s"}.get(unit, unit)
        ax.plot(t, log.x[:, i] * conv, color="0.5", lw=2.2, alpha=0.6, label="measured")
        ax.plot(t, pred_initial[:, i] * conv, color="C3", ls=":", lw=1.2, label="initial model")
        ax.plot(t, pred_fitted[:, i] * conv, color="C0", ls="--", lw=1.2, label="fitted model")
        ax.set_ylabel(f"{c} [{label_unit}]")
        ax.grid(alpha=0.3)
    for ax in axes[n:]:
        ax.set_visible(False)
    for ax in axes[max(n - ncol, 0) : n]:
        ax.set_xlabel("t [s]")
        ax.xaxis.set_tick_params(labelbottom=True)
    axes[0].legend(fontsize=8)
    fig.suptitle(
        f"{log.name}: measured vs free simulation from the first sample "
        f"({model.vehicle}, step {result.problem.step_name!r})"
    )
    return _save_fit(fig, Path(path), result)


def cost_history_figure(result, path) -> Path:
    """The multiple-shooting cost per Levenberg–Marquardt iteration, both stages."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    h = np.asarray(result.cost_history)
    k = 0
    for stage, n in enumerate(result.stage_iterations, start=1):
        seg = h[k : k + n + 1]
        ax.semilogy(
            np.arange(k, k + seg.size),
            np.maximum(seg, 1e-300),
            "o-",
            ms=3,
            label=f"stage {stage} ({'spread' if stage == 1 else 'noise'} weights)",
        )
        k += seg.size
    ax.set_xlabel("iteration (both stages)")
    ax.set_ylabel("cost 0.5 |r|^2 (weighted)")
    ax.set_title(
        f"vcjax fit: cost history ({result.iterations} iterations, {result.wall_time_s:.1f} s)"
    )
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    return _save_fit(fig, Path(path), result)


def _save_fit(fig, path: Path, result) -> Path:
    """Lay out, write the fit's warnings (and an untrusted optimum) into the figure in red,
    save atomically ([`savefig_atomic`][vcjax.runtime.outputs.savefig_atomic]), close."""
    from vcjax.runtime.outputs import savefig_atomic

    bottom = _warnings_text(fig, result)
    fig.tight_layout(rect=(0.0, bottom, 1.0, 1.0))
    savefig_atomic(fig, path, dpi=120)
    pyplot().close(fig)
    return path


def _warnings_text(fig, result) -> float:
    """Write the warnings at the bottom of ``fig``; returns the height they take (0: none)."""
    if not result.warnings and result.converged:
        return 0.0
    lines = ([] if result.converged else ["NOT CONVERGED / NOT TRUSTWORTHY"]) + [
        f"warning: {w}" for w in result.warnings
    ]
    text = "\n".join(textwrap.shorten(x, 150, placeholder=" ...") for x in lines[:6])
    fig.text(0.01, 0.005, text, color="C3", fontsize=6, va="bottom", ha="left")
    return min(0.04 + 0.025 * min(len(lines), 6), 0.3)
