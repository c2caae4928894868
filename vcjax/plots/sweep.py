"""Figures of a Monte-Carlo sweep ([`vcjax.sweep`][vcjax.sweep]; Agg backend, files, never windows).

* ``sweep_error_vs_current.png``: steady-state |e| of every run against the mean current speed
  and against the current direction, one colour per variant, with binned medians;
* ``sweep_metrics.png``: box plots of the main metrics per variant;
* ``sweep_envelopes.png``: cross-track error against time, median and 25–75 % / 5–95 % bands
  per variant, all panels on one y scale;
* ``sweep_paths.png``: a sample of the paths travelled, per variant (equal axis scales);
* ``sweep_error_vs_waves.png`` (sweeps with ``[waves]``): RMS cross-track and depth errors of
  every run against the significant wave height, and against the depth of the NED origin below
  the mean surface when it varies, with binned medians.

Runs flagged ``diverged`` are left out of every panel (their count is in the titles).
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from vcjax.plots import STYLE, pyplot, save

__all__ = ["sweep_figures"]

_FLOOR = 1e-6  # log-scale floor for errors [m]


def _variants(result):
    return [v for v in STYLE if v in result.metrics] + [v for v in result.metrics if v not in STYLE]


def _style(v, result=None) -> dict:
    """The variant's line style (the paper's colours; others from the colour cycle). The paper's
    equation numbers label the variants only on the paper's vehicle (INFANTE); elsewhere the
    label is the variant's name."""
    if v in STYLE:
        choice = getattr(getattr(result, "spec", None), "choice", None)
        vehicle = getattr(choice, "vehicle", "infante")
        return STYLE[v] if vehicle == "infante" else {**STYLE[v], "label": v}
    cycle = ("tab:purple", "tab:brown", "tab:pink", "tab:olive", "tab:cyan")
    return {"color": cycle[sum(map(ord, v)) % len(cycle)], "ls": "-", "label": v}


def _path_xy(result):
    """(P, 2) [north, east] points of the sweep's path (None if it cannot be drawn)."""
    from vcjax import loops

    try:
        choice = result.spec.choice
        cls = loops.loop_class(choice.vehicle)
        path, coeffs = cls.default_path() if choice.path is None else choice.path.build()
        xy = np.asarray(result.traces[next(iter(result.traces))]["xy"], np.float64)
        pts = loops.path_polyline(path, coeffs, xy.reshape(-1, 2) if xy.size else None)
        return np.asarray(pts)[:, :2]
    except (ValueError, AttributeError, StopIteration):
        return None


def _ok(result, v):
    return ~np.asarray(result.metrics[v]["diverged"], dtype=bool)


def _binned_median(x, y, edges):
    mid, med = [], []
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (x >= lo) & (x <= hi)
        if np.any(sel):
            mid.append(0.5 * (lo + hi))
            med.append(np.median(y[sel]))
    return np.array(mid), np.array(med)


def _error_vs_current(result, out: Path) -> Path:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True)
    speed = np.asarray(result.scenarios["current_speed"], dtype=np.float64)
    direction = np.degrees(np.asarray(result.scenarios["current_direction"], np.float64)) % 360
    n = speed.size
    alpha = float(np.clip(30.0 / max(n, 1), 0.05, 0.6))
    for ax, x, label in (
        (axes[0], speed, "mean current speed [m/s]"),
        (axes[1], direction, "current direction (towards, from north) [deg]"),
    ):
        span = (x.min(), x.max()) if n else (0.0, 1.0)
        edges = np.linspace(span[0], span[1] + 1e-12, 11)
        for v in _variants(result):
            ok = _ok(result, v)
            y = np.maximum(np.asarray(result.metrics[v]["ss_abs_e"], np.float64)[ok], _FLOOR)
            st = _style(v, result)
            ax.scatter(x[ok], y, s=6, color=st["color"], alpha=alpha, lw=0)
            if np.ptp(x) > 0:
                mx, my = _binned_median(x[ok], y, edges)
                ax.plot(mx, my, color=st["color"], ls=st["ls"], lw=2, label=st["label"])
            else:
                ax.plot([], [], color=st["color"], ls=st["ls"], lw=2, label=st["label"])
        ax.set_xlabel(label)
        if any(_ok(result, v).any() for v in _variants(result)):  # no data: no log scale
            ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("steady-state mean |e| [m] (last %.0f %%)" % (100 * result.spec.tail))
    fails = ", ".join(f"{v}: {int((~_ok(result, v)).sum())}" for v in _variants(result))
    title = f"{n} scenarios; lines: binned medians; diverged runs (left out): {fails}"
    fig.suptitle("\n".join(textwrap.wrap(title, 110)), fontsize=10)
    axes[0].set_title("against the current's speed", fontsize=10)
    axes[1].set_title("against the current's direction", fontsize=10)
    axes[0].legend(fontsize=8)
    return save(fig, out / "sweep_error_vs_current.png")


def _error_vs_waves(result, out: Path) -> Path:
    plt = pyplot()
    sc = result.scenarios
    hs = np.asarray(sc["wave_hs"], np.float64)
    depth = np.asarray(sc["wave_origin_depth"], np.float64)
    columns = [(hs, "significant wave height Hs [m]")]
    if np.ptp(depth) > 0:
        columns.append((depth, "origin_depth: depth of the NED origin below the surface [m]"))
    rows = [
        ("rms_cross_track_e", "RMS cross-track error [m]"),
        ("rms_depth_err", "RMS depth error [m]"),
    ]
    fig, axes = plt.subplots(
        2, len(columns), figsize=(6 * len(columns), 8), squeeze=False, sharey="row"
    )
    n = hs.size
    alpha = float(np.clip(60.0 / max(n, 1), 0.2, 0.6))
    for j, (x, xlabel) in enumerate(columns):
        edges = np.linspace(x.min(), x.max() + 1e-12, 7) if n else np.linspace(0.0, 1.0, 7)
        for i, (key, ylabel) in enumerate(rows):
            ax = axes[i, j]
            ys = []
            for v in _variants(result):
                ok = _ok(result, v)
                y = np.maximum(np.asarray(result.metrics[v][key], np.float64)[ok], _FLOOR)
                ys.append(y)
                st = _style(v, result)
                ax.scatter(x[ok], y, s=6, color=st["color"], alpha=alpha, lw=0)
                if np.ptp(x) > 0 and ok.any():
                    mx, my = _binned_median(x[ok], y, edges)
                    ax.plot(mx, my, color=st["color"], ls=st["ls"], lw=2, label=st["label"])
                else:
                    ax.plot([], [], color=st["color"], ls=st["ls"], lw=2, label=st["label"])
            y_all = np.concatenate(ys)
            if y_all.size and np.ptp(y_all) > 0:  # no data, or one value (planar: no depth)
                ax.set_yscale("log")
            ax.set_xlabel(xlabel)
            ax.set_ylabel(ylabel)
            ax.grid(True, which="both", alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fails = ", ".join(f"{v}: {int((~_ok(result, v)).sum())}" for v in _variants(result))
    title = (
        f"{n} scenarios, errors over the last {100 * result.spec.tail:.0f} % of each run; "
        f"lines: binned medians; diverged runs (left out): {fails}"
    )
    fig.suptitle("\n".join(textwrap.wrap(title, 110)), fontsize=10)
    return save(fig, out / "sweep_error_vs_waves.png")


def _metric_boxes(result, out: Path) -> Path:
    plt = pyplot()
    panels = [
        ("ss_abs_e", "steady-state |e| [m]", True),
        ("ss_abs_u_err", "steady-state |u - u_d| [m/s]", True),
        ("iae_e", "IAE of e [m s]", True),
        ("max_abs_e", "max |e| [m]", True),
        (_actuator_key(result), _actuator_key(result).replace("max_abs_", "max |") + "|", False),
        ("sat_fraction", "fraction of steps saturated", False),
    ]
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    vs = _variants(result)
    for ax, (key, title, log) in zip(axes.ravel(), panels, strict=True):
        data = []
        for v in vs:
            y = np.asarray(result.metrics[v][key], np.float64)[_ok(result, v)]
            data.append(np.maximum(y, _FLOOR) if log else y)
        bp = ax.boxplot(data, whis=(5, 95), showfliers=False, patch_artist=True)
        for patch, v in zip(bp["boxes"], vs, strict=True):
            patch.set_facecolor(_style(v, result)["color"])
            patch.set_alpha(0.5)
        ax.set_xticks(range(1, len(vs) + 1), vs, fontsize=8)
        ax.set_title(title, fontsize=10)
        if log and any(d.size for d in data):
            ax.set_yscale("log")
        ax.grid(True, axis="y", alpha=0.3)
    fig.suptitle("Sweep metrics per variant (boxes: quartiles; whiskers: 5-95 %)")
    return save(fig, out / "sweep_metrics.png")


def _actuator_key(result) -> str:
    """The first ``max_abs_<actuator>`` metric (the rudder for INFANTE-class)."""
    keys = next(iter(result.metrics.values())).keys()
    act = [k for k in keys if k.startswith("max_abs_") and k != "max_abs_e"]
    return "max_abs_rudder_deg" if "max_abs_rudder_deg" in act else (act or ["max_abs_e"])[0]


def _grid(plt, n, sharey=False):
    rows = 1 if n <= 2 else 2
    cols = int(np.ceil(n / rows))
    fig, axes = plt.subplots(
        rows, cols, figsize=(5.5 * cols, 4.2 * rows), squeeze=False, sharey=sharey
    )
    return fig, axes.ravel()


def _envelopes(result, out: Path) -> Path:
    plt = pyplot()
    vs = _variants(result)
    fig, axes = _grid(plt, len(vs), sharey=True)  # one y scale: the variants compare by eye
    t = np.asarray(result.trace_t)
    for ax, v in zip(axes, vs, strict=False):
        e = np.asarray(result.traces[v]["e"], np.float64)[_ok(result, v)]
        st = _style(v, result)
        if e.shape[0]:
            q = np.percentile(e, [5, 25, 50, 75, 95], axis=0)
            ax.fill_between(t, q[0], q[4], color=st["color"], alpha=0.15, label="5-95 %")
            ax.fill_between(t, q[1], q[3], color=st["color"], alpha=0.35, label="25-75 %")
            ax.plot(t, q[2], color=st["color"], lw=1.5, label="median")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(f"{st['label']} ({e.shape[0]} runs)", fontsize=10)
        ax.set_xlabel("t [s]")
        ax.set_ylabel("cross-track error e [m]")
        ax.yaxis.set_tick_params(labelleft=True)
        ax.grid(True, alpha=0.3)
        if e.shape[0]:
            ax.legend(fontsize=8)
    for ax in axes[len(vs) :]:
        ax.set_visible(False)
    fig.suptitle("Cross-track error envelopes (shared y-axis)", fontsize=11)
    return save(fig, out / "sweep_envelopes.png")


_COMPUTE = object()  # _paths' default: the path's points from the result's own spec


def _paths(result, out: Path, max_paths: int = 60, path_xy=_COMPUTE) -> Path:
    plt = pyplot()
    vs = _variants(result)
    if path_xy is _COMPUTE:
        path_xy = _path_xy(result)
    fig, axes = _grid(plt, len(vs))
    for ax, v in zip(axes, vs, strict=False):
        xy = np.asarray(result.traces[v]["xy"], np.float64)
        ok = np.flatnonzero(_ok(result, v))[:max_paths]
        bad = np.flatnonzero(~_ok(result, v))[:max_paths]
        st = _style(v, result)
        for i in ok:
            ax.plot(xy[i, :, 1], xy[i, :, 0], color=st["color"], lw=0.6, alpha=0.5)
        for i in bad:
            ax.plot(xy[i, :, 1], xy[i, :, 0], color="k", lw=0.6, alpha=0.5)
        if path_xy is not None:
            ax.plot(path_xy[:, 1], path_xy[:, 0], "k--", lw=1.2, alpha=0.8, label="path", zorder=3)
        ax.set_title(f"{st['label']}: {len(ok)} paths (black: diverged)", fontsize=10)
        ax.set_xlabel("y (east) [m]")
        ax.set_ylabel("x (north) [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    for ax in axes[len(vs) :]:
        ax.set_visible(False)
    return save(fig, out / "sweep_paths.png")


def _plain(result) -> SimpleNamespace:
    """What the figures read of a sweep result, as plain data (NumPy arrays, strings, numbers):
    what a [`FigureHelper`][vcjax.plots.helper.FigureHelper] process is given, with no config
    class or path function to import there."""
    choice = getattr(result.spec, "choice", None)
    spec = SimpleNamespace(
        choice=SimpleNamespace(vehicle=getattr(choice, "vehicle", "infante")),
        tail=float(result.spec.tail),
    )
    return SimpleNamespace(
        spec=spec,
        metrics={v: {k: np.asarray(a) for k, a in m.items()} for v, m in result.metrics.items()},
        traces={v: {k: np.asarray(a) for k, a in t.items()} for v, t in result.traces.items()},
        scenarios={k: np.asarray(a) for k, a in result.scenarios.items()},
        trace_t=np.asarray(result.trace_t),
    )


def sweep_figures(result, out: Path, helper=None) -> list[Path]:
    """Write the sweep figures for a [`SweepResult`][vcjax.sweep.results.SweepResult] into ``out``.

    The envelope and path figures need recorded traces (``record_points > 0``). With a
    ``helper`` ([`FigureHelper`][vcjax.plots.helper.FigureHelper], the CLI's), the metrics' and
    the paths' figures are drawn in its process while this one draws the others; the same
    files, byte for byte (what the helper fails to draw is drawn here).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    traces = bool(np.asarray(result.trace_t).size)
    path_xy = _path_xy(result) if traces else None  # once, for here or the helper
    far = []
    if helper is not None:
        view = _plain(result)
        calls = {"metrics": (__name__, "_metric_boxes", (view, out))}
        if traces:
            calls["paths"] = (__name__, "_paths", (view, out, 60, path_xy))
        if helper.submit(calls.values()):
            far = list(calls)

    def draw_here(name: str) -> Path:
        return _metric_boxes(result, out) if name == "metrics" else _paths(result, out, 60, path_xy)

    files = {"current": _error_vs_current(result, out)}
    if "metrics" not in far:
        files["metrics"] = draw_here("metrics")
    if "wave_hs" in result.scenarios:
        files["waves"] = _error_vs_waves(result, out)
    if traces:
        files["envelopes"] = _envelopes(result, out)
        if "paths" not in far:
            files["paths"] = draw_here("paths")
    for name in far:  # in the order submitted; drawn here where the helper failed
        got = helper.result()
        files[name] = Path(got) if got is not None else draw_here(name)
    order = ("current", "metrics", "waves", "envelopes", "paths")
    return [files[k] for k in order if k in files]
