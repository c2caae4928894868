"""Figures and the progress hook of tuning runs (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vcjax.plots import _plt
from vcjax.progress import ProgressBar as _Bar

__all__ = ["ProgressBar", "plot_loss_curve", "plot_before_after"]


class ProgressBar(_Bar):
    """The library's progress bar, called as an optimiser's ``progress(k, total, rec)`` hook:
    ``[#####-----] k/total ... loss L`` (and ``(rejected: non-finite)`` for a rejected step)."""

    def __call__(self, k: int, total: int | None = None, rec: dict | None = None) -> None:
        if total is not None:
            self.total = max(1, int(total))
        note = ""
        if rec:
            loss = rec.get("loss", rec.get("best_loss"))
            note = f"loss {loss:.4g}" if loss is not None else "loss nan"
            if rec.get("ok") is False:
                note += " (rejected: non-finite)"
        self.show(k, note)


def plot_loss_curve(history: list, path, title: str = "gain tuning") -> Path:
    """Training loss and gradient norm per iteration (log scale); rejected steps marked."""
    plt = _plt()
    it = np.array([h["iter"] for h in history])
    loss = np.array([np.nan if h["loss"] is None else h["loss"] for h in history])
    gn = np.array([np.nan if h["grad_norm"] is None else h["grad_norm"] for h in history])
    bad = np.array([not h["ok"] for h in history])
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    ax[0].semilogy(it, loss, "o-", ms=3)
    if bad.any():
        ax[0].plot(it[bad], np.nanmin(loss) * np.ones(bad.sum()), "rx", label="rejected step")
        ax[0].legend()
    ax[0].set(xlabel="iteration", ylabel="training loss", title=title)
    ax[1].semilogy(it, gn, "o-", ms=3, color="tab:orange")
    ax[1].set(xlabel="iteration", ylabel="gradient norm")
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_before_after(t, before, after, currents, out_dir, path_xy=None) -> list[Path]:
    """Paths and cross-track errors of a few held-out scenarios, default vs tuned gains.

    Args:
        t: (N+1,) times; before, after: dicts with ``xy`` (S, N, 2) positions [north, east]
            and ``e`` (S, N) cross-track errors; currents: (S, 2 or 3) NED currents [m/s];
        out_dir: folder; path_xy: (P, 2) points of the path [north, east] (drawn if given).
    """
    plt = _plt()
    out_dir = Path(out_dir)
    S = before["xy"].shape[0]
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, ax = plt.subplots(figsize=(8, 5))
    if path_xy is not None:
        ax.plot(path_xy[:, 1], path_xy[:, 0], color="k", lw=3, alpha=0.25, label="path")
    for i in range(S):
        c = colors[i % len(colors)]
        sp = float(np.hypot(*np.asarray(currents[i])[:2]))
        ax.plot(before["xy"][i, :, 1], before["xy"][i, :, 0], "--", color=c, lw=1)
        ax.plot(
            after["xy"][i, :, 1],
            after["xy"][i, :, 0],
            "-",
            color=c,
            lw=1.5,
            label=f"scenario {i}: |V_c| = {sp:.2f} m/s",
        )
        ax.plot(before["xy"][i, 0, 1], before["xy"][i, 0, 0], "o", color=c)
    ax.set(
        xlabel="east y [m]",
        ylabel="north x [m]",
        title="held-out scenarios: default gains (dashed) vs tuned (solid)",
    )
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    p1 = out_dir / "before_after_paths.png"
    fig.savefig(p1, dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 4))
    tt = np.asarray(t)[:-1]
    for i in range(S):
        c = colors[i % len(colors)]
        ax.plot(tt, before["e"][i], "--", color=c, lw=1)
        ax.plot(tt, after["e"][i], "-", color=c, lw=1.5, label=f"scenario {i}")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set(
        xlabel="t [s]",
        ylabel="cross-track error e [m]",
        title="default gains (dashed) vs tuned (solid)",
    )
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    p2 = out_dir / "before_after_cross_track.png"
    fig.savefig(p2, dpi=110)
    plt.close(fig)
    return [p1, p2]
