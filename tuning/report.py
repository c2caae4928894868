"""Figures and the progress hook of tuning runs (matplotlib, Agg backend)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vcjax.plots import pyplot
from vcjax.runtime.outputs import savefig_atomic
from vcjax.runtime.progress import ProgressBar as _Bar

__all__ = [
    "ProgressBar",
    "change_text",
    "plot_loss_curve",
    "plot_before_after",
    "plot_loss_terms",
    "time_to_target",
    "MERGE_KEYS",
    "merge_runs",
]


def change_text(before: float, after: float) -> str:
    """``"12.3 % lower"`` / ``"4.5 % higher"`` / ``"unchanged"``: how ``after`` compares with
    ``before`` (a held-out loss that rose is never called lower)."""
    if not (np.isfinite(before) and np.isfinite(after)) or before == 0:
        return "not comparable" if after != before else "unchanged"
    pct = 100.0 * (after - before) / abs(before)
    if abs(pct) < 0.05:
        return "unchanged"
    return f"{abs(pct):.1f} % {'lower' if pct < 0 else 'higher'}"


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
    plt = pyplot()
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
    savefig_atomic(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_before_after(t, before, after, currents, out_dir, path_xy=None) -> list[Path]:
    """Paths and cross-track errors of a few held-out scenarios, default vs tuned gains.

    Args:
        t: (N+1,) times; before, after: dicts with ``xy`` (S, N, 2) positions [north, east]
            and ``e`` (S, N) cross-track errors; currents: (S, 2 or 3) NED currents [m/s];
        out_dir: folder; path_xy: (P, 2) points of the path [north, east] (drawn if given).
    """
    plt = pyplot()
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
    savefig_atomic(fig, p1, dpi=110)
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
    savefig_atomic(fig, p2, dpi=110)
    plt.close(fig)
    return [p1, p2]


def plot_loss_terms(t, before, after, terms, weights, actuators, path) -> Path:
    """What the tuning loss measures, default gains (dashed) vs tuned (solid), on a few
    held-out scenarios, and the held-out mean of each weighted loss term.

    Panels: path error ``sqrt(s² + e²)``, speed error ``ũ``, heading error ``ψ̃``, and every
    actuator command divided by its limit (the dotted line at 1 is the limit: beyond it the
    ``sat_excess`` / ``sat_time`` terms grow); last, ``w_k term_k`` before vs after.

    Args:
        t: (N+1,) times; before, after: dicts with ``eps`` (S, N, 2), ``u_err`` (S, N),
            ``psi_err`` (S, N), ``cmd_ratio`` (S, N, A); terms: ``(terms_before,
            terms_after)``, dicts name -> held-out mean; weights: dict name -> weight;
        actuators: A names of the actuators (or ``None``); path: the PNG to write.
    """
    plt = pyplot()
    tt = np.asarray(t)[:-1]
    S = before["eps"].shape[0]
    A = before["cmd_ratio"].shape[-1]
    names = (
        list(actuators)
        if actuators and len(actuators) == A
        else [f"actuator {j}" for j in range(A)]
    )
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    n_panels = 3 + A + 1
    cols = 3
    rows = int(np.ceil(n_panels / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(15, 3.6 * rows), squeeze=False)
    axes = axes.ravel()
    series = [
        ("path error √(s² + e²) [m]", lambda d: np.hypot(d["eps"][..., 0], d["eps"][..., 1])),
        ("speed error ũ [m/s]", lambda d: d["u_err"]),
        ("heading error ψ̃ [deg]", lambda d: np.degrees(d["psi_err"])),
    ]
    series += [
        (f"{names[j]} command / limit", lambda d, j=j: d["cmd_ratio"][..., j]) for j in range(A)
    ]
    for ax, (title, f) in zip(axes, series, strict=False):
        for i in range(S):
            c = colors[i % len(colors)]
            ax.plot(tt, f(before)[i], "--", color=c, lw=1)
            ax.plot(tt, f(after)[i], "-", color=c, lw=1.3, label=f"scenario {i}")
        if "limit" in title:
            for y in (-1.0, 1.0):
                ax.axhline(y, color="k", ls=":", lw=1.2, label="limit" if y > 0 else None)
        ax.set_title(title, fontsize=10)
        ax.set_xlabel("t [s]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7)
    axes[3].legend(fontsize=7)
    ax = axes[len(series)]
    tb, ta = terms
    keys = [k for k in weights if weights[k] > 0]
    vb = np.array([weights[k] * tb[k] for k in keys])
    va = np.array([weights[k] * ta[k] for k in keys])
    x = np.arange(len(keys))
    ax.bar(x - 0.2, vb, 0.4, label=f"default (sum {vb.sum():.3g})", color="0.6")
    ax.bar(x + 0.2, va, 0.4, label=f"tuned (sum {va.sum():.3g})", color="C0")
    ax.set_xticks(x, keys, rotation=30, fontsize=8)
    ax.set_yscale("symlog", linthresh=1e-3)
    ax.set_ylim(
        0.0, 5.0 * max(float(np.max(vb, initial=0.0)), float(np.max(va, initial=0.0)), 1e-3)
    )
    ax.set_title("held-out weighted loss terms w_k term_k", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, axis="y", alpha=0.3)
    for ax in axes[len(series) + 1 :]:
        ax.set_visible(False)
    fig.suptitle("What the loss measures: default gains (dashed) vs tuned (solid)", fontsize=11)
    fig.tight_layout()
    path = Path(path)
    savefig_atomic(fig, path, dpi=110)
    plt.close(fig)
    return path


def _reach(curve, level, key):
    for rec in curve:
        if rec["heldout_best"] <= level:
            return rec[key]
    return None


def time_to_target(
    runs: dict,
    reach_pct=(1.0, 5.0),
    gradient=("lbfgs", "adam", "gradient"),
    blackbox=("cmaes", "bayes", "random"),
) -> dict:
    """How fast tuners reach the best loss any of them found (the tuner comparison,
    ``benchmarks/studies/tuners.py``).

    Args:
        runs: ``{cache: {tuner: run}}``, each run with ``best_heldout``, ``first_step_s`` and
            its ``curve``: records of ``wall_s``, ``rollouts`` and ``heldout_best`` (the best
            held-out loss so far).
        reach_pct: the tolerances, percent above the target.
        gradient, blackbox: the tuners whose times are compared, gradient over black-box.

    Returns:
        ``target`` (the lowest held-out loss of any run), ``table`` (per cache and tuner: the
        wall-clock seconds and rollouts to within each tolerance of it, ``None``: not reached)
        and ``ratios_wall_s_to_1%`` (gradient over black-box tuner times at 1 %).
    """
    target = min(r["best_heldout"] for c in runs.values() for r in c.values())
    table: dict = {}
    for c, by_tuner in runs.items():
        table[c] = {}
        for name, r in by_tuner.items():
            row = {"best_heldout": r["best_heldout"], "first_step_s": r["first_step_s"]}
            for p in reach_pct:
                level = target * (1 + p / 100)
                row[f"wall_s_to_{p:g}%"] = _reach(r["curve"], level, "wall_s")
                row[f"rollouts_to_{p:g}%"] = _reach(r["curve"], level, "rollouts")
            table[c][name] = row
    ratios: dict = {}
    for c, by_tuner in runs.items():  # at 1 % whatever the table's tolerances
        to_1 = {n: _reach(r["curve"], target * 1.01, "wall_s") for n, r in by_tuner.items()}
        for g in gradient:
            for b in blackbox:
                if g in to_1 and b in to_1:
                    tg, tb = to_1[g], to_1[b]
                    ratios[f"{c}: {g}/{b} at 1%"] = tg / tb if tg is not None and tb else None
    return {"target": target, "table": table, "ratios_wall_s_to_1%": ratios}


#: keys of two reports of the tuner study (``python -m benchmarks.studies.tuners``) that must
#: agree for ``--merge``: the same problem, measured the same way
MERGE_KEYS = (
    "config", "seconds", "rollouts_budget", "grad_ratio", "grad_mode", "x64", "sigma0",
    "random_radius", "seed",
)  # fmt: skip


def merge_runs(earlier: dict, rep: dict) -> dict:
    """``rep``'s runs with those of the ``earlier`` report added: per cache, a tuner of
    ``rep`` replaces the earlier run of the same name. ``ValueError`` naming the first key of
    ``MERGE_KEYS`` on which the two reports differ."""
    for k in MERGE_KEYS:
        if earlier.get(k) != rep.get(k):
            raise ValueError(
                f"--merge: the earlier report has {k} = {earlier.get(k)!r}, this run "
                f"{rep.get(k)!r}: not the same problem measured the same way"
            )
    a, b = earlier.get("config_sha256"), rep.get("config_sha256")
    if a is not None and b is not None and a != b:
        raise ValueError(
            f"--merge: {rep.get('config')} changed since the earlier report (its contents "
            "differ): not the same problem"
        )
    runs = {c: dict(by) for c, by in earlier.get("runs", {}).items()}
    for c, by in rep["runs"].items():
        runs.setdefault(c, {}).update(by)
    return runs
