"""Tests that kill the survivors of a mutation run of the tuner's command and its figures
(``tuning/run.py``, ``tuning/report.py``; issue 31, item 8; docs/development/testing.md,
"Mutation testing"): what ``summary.json`` and ``history.json`` say (an interrupted run
included: its counts, its best-so-far gains, its held-out numbers), computed here by hand from
the run's history and from stand-ins for the tune's stages (no rollout is compiled), and the
numbers the figures draw (their lines, bars, labels and sizes, read back from the figure before
it is written; not the pixels). Each test names the bugs it kills.
"""

from __future__ import annotations

import dataclasses
import io
import json
import re
import time

import jax
import numpy as np
import pytest

from tuning import report
from tuning.loss import TERMS

# ------------------------------------------------------------------ figures (matplotlib only)


@pytest.fixture
def saved(monkeypatch):
    """``tuning.report``'s ``savefig_atomic``, recording ``(fig, path, kwargs)`` instead of
    writing (the figure is closed after it: its artists stay readable); no layout pass (the
    slow part of a figure; it moves no data)."""
    from matplotlib.figure import Figure

    monkeypatch.setattr(Figure, "tight_layout", lambda self, *a, **kw: None)
    out = []
    monkeypatch.setattr(
        report, "savefig_atomic", lambda fig, path, **kw: out.append((fig, path, kw))
    )
    return out


def _rgb(color):
    from matplotlib.colors import to_rgb

    return to_rgb(color)


def _grid(ax, axis="x"):
    line = getattr(ax, f"{axis}axis").get_gridlines()[0]
    return line.get_visible(), line.get_alpha()


def _history():
    """Four steps: the second rejected (no loss), the third without a gradient norm."""
    return [
        {"iter": 0, "loss": 4.0, "grad_norm": 1.0, "ok": True},
        {"iter": 1, "loss": None, "grad_norm": 0.5, "ok": False},
        {"iter": 2, "loss": 3.0, "grad_norm": None, "ok": True},
        {"iter": 3, "loss": 2.5, "grad_norm": 0.25, "ok": True},
    ]


def test_the_loss_curve_draws_the_losses_the_norms_and_the_rejected_steps(saved, tmp_path):
    """Kills: a missing loss or norm drawn as itself (not NaN), the rejected steps' marks at the
    accepted steps or at another height than the lowest loss, the panels swapped, the marker,
    size, grid, figure size or resolution changed."""
    path = report.plot_loss_curve(_history(), tmp_path / "c.png", "adam tuning")
    assert path == tmp_path / "c.png"
    ((fig, p, kw),) = saved
    assert p == tmp_path / "c.png" and kw == {"dpi": 110}
    np.testing.assert_array_equal(fig.get_size_inches(), [10.0, 3.6])
    a, b = fig.axes
    loss, rejected = a.lines
    np.testing.assert_array_equal(loss.get_xdata(), [0, 1, 2, 3])
    np.testing.assert_array_equal(loss.get_ydata(), [4.0, np.nan, 3.0, 2.5])
    assert (loss.get_marker(), loss.get_linestyle(), loss.get_markersize()) == ("o", "-", 3)
    np.testing.assert_array_equal(rejected.get_xdata(), [1])
    np.testing.assert_array_equal(rejected.get_ydata(), [2.5])  # the lowest loss
    assert (rejected.get_marker(), rejected.get_color(), rejected.get_label()) == (
        "x",
        "r",
        "rejected step",
    )
    assert [t.get_text() for t in a.get_legend().get_texts()] == ["rejected step"]
    assert (a.get_xlabel(), a.get_ylabel(), a.get_title()) == (
        "iteration",
        "training loss",
        "adam tuning",
    )
    (norm,) = b.lines
    np.testing.assert_array_equal(norm.get_ydata(), [1.0, 0.5, np.nan, 0.25])
    assert (norm.get_marker(), norm.get_markersize(), norm.get_color()) == ("o", 3, "tab:orange")
    assert (b.get_xlabel(), b.get_ylabel(), b.get_title()) == ("iteration", "gradient norm", "")
    assert b.get_legend() is None
    for ax in (a, b):
        assert ax.get_yscale() == "log"
        assert _grid(ax) == (True, 0.3) and _grid(ax, "y") == (True, 0.3)


def test_a_loss_curve_without_rejected_steps_has_no_marks(saved, tmp_path):
    report.plot_loss_curve([h for h in _history() if h["ok"]], tmp_path / "c.png")
    ((fig, _, _),) = saved
    a, _ = fig.axes
    assert len(a.lines) == 1 and a.get_legend() is None and a.get_title() == "gain tuning"


def _runs(S=2, N=3, seed=0):
    rng = np.random.default_rng(seed)
    before = {"xy": rng.normal(size=(S, N, 2)), "e": rng.normal(size=(S, N))}
    after = {"xy": rng.normal(size=(S, N, 2)), "e": rng.normal(size=(S, N))}
    return before, after


def test_the_before_after_figures_draw_each_scenario_north_up(saved, tmp_path):
    """Kills: north and east swapped (a path is drawn east along x, north along y), the start
    mark off the first sample, the current's speed from other components, the colours, line
    widths, the cross-track times (the first N of N+1), the zero line, the file names, sizes
    and resolution."""
    S, N = 2, 3
    before, after = _runs(S, N)
    t = 0.5 * np.arange(N + 1)
    currents = np.array([[0.3, 0.4, 5.0], [-0.6, 0.8, 5.0]])  # |V_c| 0.5 and 1.0 (w ignored)
    path_xy = np.array([[0.0, 1.0], [2.0, 3.0], [4.0, 5.0]])
    files = report.plot_before_after(t, before, after, currents, tmp_path, path_xy)
    assert files == [tmp_path / "before_after_paths.png", tmp_path / "before_after_cross_track.png"]
    (f1, p1, kw1), (f2, p2, kw2) = saved
    assert (p1, p2) == tuple(files) and kw1 == kw2 == {"dpi": 110}
    np.testing.assert_array_equal(f1.get_size_inches(), [8.0, 5.0])
    np.testing.assert_array_equal(f2.get_size_inches(), [8.0, 4.0])
    (ax,) = f1.axes
    path, *lines = ax.lines
    np.testing.assert_array_equal(path.get_xdata(), [1.0, 3.0, 5.0])  # east
    np.testing.assert_array_equal(path.get_ydata(), [0.0, 2.0, 4.0])  # north
    assert (path.get_color(), path.get_linewidth(), path.get_alpha(), path.get_label()) == (
        "k",
        3,
        0.25,
        "path",
    )
    assert len(lines) == 3 * S
    for i in range(S):
        dashed, solid, start = lines[3 * i : 3 * i + 3]
        np.testing.assert_array_equal(dashed.get_xdata(), before["xy"][i, :, 1])
        np.testing.assert_array_equal(dashed.get_ydata(), before["xy"][i, :, 0])
        np.testing.assert_array_equal(solid.get_xdata(), after["xy"][i, :, 1])
        np.testing.assert_array_equal(solid.get_ydata(), after["xy"][i, :, 0])
        np.testing.assert_array_equal(start.get_xdata(), [before["xy"][i, 0, 1]])
        np.testing.assert_array_equal(start.get_ydata(), [before["xy"][i, 0, 0]])
        assert (dashed.get_linestyle(), dashed.get_linewidth()) == ("--", 1)
        assert (solid.get_linestyle(), solid.get_linewidth()) == ("-", 1.5)
        assert start.get_marker() == "o"
        assert {_rgb(x.get_color()) for x in (dashed, solid, start)} == {_rgb(f"C{i}")}
    assert solid.get_label() == "scenario 1: |V_c| = 1.00 m/s"
    assert [x.get_text() for x in ax.get_legend().get_texts()] == [
        "path",
        "scenario 0: |V_c| = 0.50 m/s",
        "scenario 1: |V_c| = 1.00 m/s",
    ]
    assert ax.get_legend().get_texts()[0].get_fontsize() == 8
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("east y [m]", "north x [m]")
    assert ax.get_title() == "held-out scenarios: default gains (dashed) vs tuned (solid)"
    assert _grid(ax) == (True, 0.3)
    (ax,) = f2.axes
    *lines, zero = ax.lines
    assert len(lines) == 2 * S
    for i in range(S):
        dashed, solid = lines[2 * i : 2 * i + 2]
        for line, e in ((dashed, before["e"][i]), (solid, after["e"][i])):
            np.testing.assert_array_equal(line.get_xdata(), t[:N])
            np.testing.assert_array_equal(line.get_ydata(), e)
        assert (dashed.get_linestyle(), dashed.get_linewidth()) == ("--", 1)
        assert (solid.get_linestyle(), solid.get_linewidth()) == ("-", 1.5)
        assert _rgb(dashed.get_color()) == _rgb(solid.get_color()) == _rgb(f"C{i}")
        assert solid.get_label() == f"scenario {i}"
    np.testing.assert_array_equal(zero.get_ydata(), [0.0, 0.0])
    assert (zero.get_color(), zero.get_linewidth()) == ("k", 0.8)
    assert ax.get_legend().get_texts()[0].get_fontsize() == 8
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("t [s]", "cross-track error e [m]")
    assert ax.get_title() == "default gains (dashed) vs tuned (solid)"
    assert _grid(ax) == (True, 0.3)


def test_the_paths_figure_without_a_path_draws_the_runs_only(saved, tmp_path):
    before, after = _runs(1, 2)
    report.plot_before_after(np.arange(3.0), before, after, np.array([[0.0, 0.0]]), tmp_path)
    (ax,) = saved[0][0].axes
    assert len(ax.lines) == 3 and ax.lines[0].get_linestyle() == "--"


def _signals(S, N, A, seed):
    rng = np.random.default_rng(seed)
    return {
        "eps": rng.normal(size=(S, N, 2)),
        "u_err": rng.normal(size=(S, N)),
        "psi_err": rng.normal(size=(S, N)),
        "cmd_ratio": rng.normal(size=(S, N, A)),
    }


@pytest.mark.parametrize("A", [2, 3])
def test_the_loss_terms_figure_draws_what_the_loss_measures(saved, tmp_path, A):
    """Kills: the path error from other components of ``eps`` than (s, e), the heading not in
    degrees, the panels' count and layout (3 + A + 1 in rows of 3: A = 2 and 3 tell the
    mutants of that count apart), the limit lines and their one label, the weighted terms'
    bars (weight times term, terms of zero weight left out, their places, widths, labels),
    the axis scale and limits, the hidden spare panels, sizes and resolution."""
    S, N = 2, 4
    before, after = _signals(S, N, A, 1), _signals(S, N, A, 2)
    t = 0.25 * np.arange(N + 1)
    names = ["thrust", "rudder", "stern"][:A]
    weights = {"a": 1.0, "b": 0.0, "c": 0.5, "d": 2.0}
    tb = {"a": 0.01, "b": 7.0, "c": 0.02, "d": 0.001}
    ta = {"a": 0.004, "b": 9.0, "c": 0.01, "d": 0.0005}
    path = report.plot_loss_terms(t, before, after, (tb, ta), weights, names, tmp_path / "l.png")
    assert path == tmp_path / "l.png"
    ((fig, p, kw),) = saved
    assert p == path and kw == {"dpi": 110}
    rows = 2 if A == 2 else 3  # 6 or 7 panels
    np.testing.assert_array_equal(fig.get_size_inches(), [15.0, 3.6 * rows])
    axes = fig.axes
    assert len(axes) == 3 * rows
    assert [a.get_visible() for a in axes] == [True] * (4 + A) + [False] * (3 * rows - 4 - A)
    assert fig._suptitle.get_text() == (
        "What the loss measures: default gains (dashed) vs tuned (solid)"
    )
    assert fig._suptitle.get_fontsize() == 11
    want = [
        ("path error √(s² + e²) [m]", lambda d: np.hypot(d["eps"][..., 0], d["eps"][..., 1])),
        ("speed error ũ [m/s]", lambda d: d["u_err"]),
        ("heading error ψ̃ [deg]", lambda d: d["psi_err"] * 180.0 / np.pi),
    ] + [(f"{names[j]} command / limit", lambda d, j=j: d["cmd_ratio"][..., j]) for j in range(A)]
    for k, (ax, (title, f)) in enumerate(zip(axes, want, strict=False)):
        assert ax.get_title() == title and ax.title.get_fontsize() == 10
        assert ax.get_xlabel() == "t [s]" and _grid(ax) == (True, 0.3)
        runs, limits = ax.lines[: 2 * S], ax.lines[2 * S :]
        for i in range(S):
            dashed, solid = runs[2 * i : 2 * i + 2]
            for line, d in ((dashed, before), (solid, after)):
                np.testing.assert_array_equal(line.get_xdata(), t[:N])
                np.testing.assert_allclose(line.get_ydata(), f(d)[i], rtol=1e-14)
            assert (dashed.get_linestyle(), dashed.get_linewidth()) == ("--", 1)
            assert (solid.get_linestyle(), solid.get_linewidth()) == ("-", 1.3)
            assert _rgb(dashed.get_color()) == _rgb(solid.get_color()) == _rgb(f"C{i}")
            assert solid.get_label() == f"scenario {i}"
        if k < 3:
            assert limits == []
        else:
            lo, hi = limits
            assert [lo.get_ydata()[0], hi.get_ydata()[0]] == [-1.0, 1.0]
            for line in (lo, hi):
                assert (line.get_color(), line.get_linestyle(), line.get_linewidth()) == (
                    "k",
                    ":",
                    1.2,
                )
            assert hi.get_label() == "limit" and lo.get_label().startswith("_")
        legend = ax.get_legend()
        if k in (0, 3):
            shown = [x.get_text() for x in legend.get_texts()]
            assert shown == ["scenario 0", "scenario 1"] + (["limit"] if k == 3 else [])
            assert legend.get_texts()[0].get_fontsize() == 7
        else:
            assert legend is None
    ax = axes[3 + A]
    keys = ["a", "c", "d"]  # "b" weighs nothing
    vb = [0.01, 0.01, 0.002]
    va = [0.004, 0.005, 0.001]
    default, tuned = ax.patches[:3], ax.patches[3:]
    assert len(ax.patches) == 6
    for j in range(3):
        for bar, x0, v in ((default[j], j - 0.4, vb[j]), (tuned[j], j, va[j])):
            assert bar.get_x() == pytest.approx(x0, abs=1e-15)
            assert bar.get_width() == pytest.approx(0.4, abs=1e-15)
            assert bar.get_height() == pytest.approx(v, rel=1e-14)
        assert default[j].get_facecolor() == (0.6, 0.6, 0.6, 1.0)
        assert _rgb(tuned[j].get_facecolor()) == _rgb("C0")
    assert [x.get_text() for x in ax.get_legend().get_texts()] == [
        "default (sum 0.022)",
        "tuned (sum 0.01)",
    ]
    assert ax.get_legend().get_texts()[0].get_fontsize() == 8
    ticks = ax.get_xticklabels()
    assert [x.get_text() for x in ticks] == keys
    assert {(x.get_rotation(), x.get_fontsize()) for x in ticks} == {(30.0, 8)}
    assert ax.get_yscale() == "symlog" and ax.yaxis.get_transform().linthresh == 1e-3
    assert ax.get_ylim() == pytest.approx((0.0, 0.05), rel=1e-14)  # 5 x the tallest bar
    assert ax.get_title() == "held-out weighted loss terms w_k term_k"
    assert ax.title.get_fontsize() == 10
    assert _grid(ax, "y") == (True, 0.3)


def test_the_loss_terms_figure_floors_its_scale_and_names_unnamed_actuators(saved, tmp_path):
    """Kills: the 1e-3 floor of the bars' axis changed; the actuators' names used when their
    count is not the commands' (they are then numbered)."""
    before, after = _signals(1, 2, 2, 3), _signals(1, 2, 2, 4)
    terms = ({"a": 1e-5}, {"a": 2e-5})
    for names in (None, ["thrust"], ["thrust", "rudder", "stern"]):
        report.plot_loss_terms(np.arange(3.0), before, after, terms, {"a": 1.0}, names, tmp_path)
        axes = saved[-1][0].axes
        assert [a.get_title() for a in axes[3:5]] == [
            "actuator 0 command / limit",
            "actuator 1 command / limit",
        ]
        assert axes[5].get_ylim() == pytest.approx((0.0, 5e-3), rel=1e-14)


# ------------------------------------------------------------------ progress and text


def test_the_progress_hook_shows_the_step_its_loss_and_rejections():
    """Kills: the hook's total not taken (or not floored at 1), the best loss not shown when a
    record has no loss, a missing loss shown as a number, a rejected step not marked (or an
    accepted one marked), an empty record given a loss."""
    lines = []
    bar = report.ProgressBar(5, label="tune ", sink=lines.append)
    bar(1)
    bar(2, 10, {"loss": 1.23456})
    bar(3, None, {"best_loss": 2.0, "ok": True})
    bar(4, None, {"loss": None, "ok": False})
    bar(5, None, {})
    bar(0, 0, {"loss": 0.5})
    head = [re.sub(r" [0-9.]+ s, ~[0-9]+ s left$", "", x).strip() for x in lines]
    assert head == [
        "tune: 1/5",
        "tune: 2/10 loss 1.235",
        "tune: 3/10 loss 2",
        "tune: 4/10 loss nan (rejected: non-finite)",
        "tune: 5/10",
        "tune: 0/1 loss 0.5",
    ]
    stream = io.StringIO()
    report.ProgressBar(2, stream=stream)(1, 1, {"loss": 3.0})
    assert " 1/1 " in stream.getvalue() and stream.getvalue().endswith("\n")


@pytest.mark.parametrize(
    "before, after, text",
    [
        (float("nan"), 1.0, "not comparable"),
        (1.0, float("inf"), "not comparable"),
        (float("inf"), float("inf"), "unchanged"),
        (0.0, 0.0, "unchanged"),
        (-10.0, -5.0, "50.0 % higher"),
        (-10.0, -15.0, "50.0 % lower"),
        (1000.0, 1000.5, "0.1 % higher"),  # 0.05 % exactly: the first change shown
        (1000.0, 999.5, "0.1 % lower"),
        (1000.0, 1000.4, "unchanged"),
        (4.0, 5.0, "25.0 % higher"),
        (5.0, 4.0, "20.0 % lower"),
    ],
)
def test_change_text_by_hand(before, after, text):
    """Kills: the percentage's scale, sign or base (``abs(before)``: a negative loss), the
    0.05 % threshold and which side of it is shown, the comparability test."""
    assert report.change_text(before, after) == text


# ------------------------------------------------------------------ the tune command's outputs
# The tune's stages (build, training, held-out evaluation) are replaced by stand-ins whose
# numbers are chosen here: what summary.json and history.json must then say is computed by hand.

TUNE = """
[scenario]
controller = "vcm_integral"
[simulation]
horizon = 1.0
dt = 0.1
integrator = "euler"
timing = "sampled"
[train]
size = 4
seed = 0
[heldout]
size = 5
seed = 1001
[optimizer]
name = "adam"
steps = 1000
[report]
plot_scenarios = 2
"""


@pytest.fixture(scope="module")
def setting(tmp_path_factory):
    """``(config file, config, problem, held-out problem, data)`` of a small tune."""
    from tuning.config import load_config
    from tuning.loss import TuningProblem, problem_data
    from tuning.params import GainSpace

    path = tmp_path_factory.mktemp("cfg") / "t.toml"
    path.write_text(TUNE)
    cfg = load_config(path)
    problem = TuningProblem(space=GainSpace(), num_steps=10, integrator="euler", timing="sampled")
    eval_problem = dataclasses.replace(problem, smooth=False, checkpoint=False, surface=True)
    return path, cfg, problem, eval_problem, problem_data(problem)


#: a run's history: the loss of step k's input, the gains after it (what ``on_step`` adds)
HISTORY = [
    {"iter": 0, "loss": 9.0, "grad_norm": 3.0, "ok": True, "evals": 1, "wall_s": 4.0},
    {"iter": 1, "loss": 6.0, "grad_norm": 2.0, "ok": True, "evals": 1, "wall_s": 4.5},
    {"iter": 2, "loss": None, "grad_norm": None, "ok": False, "evals": 1, "wall_s": 5.0},
    {"iter": 3, "loss": 7.0, "grad_norm": 1.0, "ok": True, "evals": 2, "wall_s": 6.25},
]

#: held-out per-scenario losses and terms of the default and of the tuned gains (5 scenarios)
HELD = {
    "default": (
        np.array([1.0, 2.0, 4.0, 8.0, 5.0]),
        np.array([0.0, 0.25, 0.0, 1.0, 0.0]),  # above the surface: 2 of 5 runs, one whole
        np.array([0.4, -0.1, 0.2, -0.3, 0.5]),
    ),
    "tuned": (
        np.array([0.5, 1.0, 1.0, 3.0, 1.5]),
        np.zeros(5),  # none above the surface
        np.array([0.4, 0.1, 0.2, 0.3, 0.5]),
    ),
}


def _stand_in_tune(setting, monkeypatch, reason, n_dev=3, robust=None):
    """``run_tune_config``'s stages replaced: ``_prepare`` gives a ``_Tune`` of ``setting``
    (n_dev devices), ``_train`` a result whose best parameters are the default gains with
    ``Delta`` doubled, the held-out evaluation ``HELD`` (default gains at ``theta_ref``);
    the figures' functions record their arguments. Returns ``(calls, best gains)``."""
    from types import SimpleNamespace

    from tuning import run as tcli
    from tuning.optim import TuneResult

    path, cfg, problem, eval_problem, data = setting
    space = problem.space
    vcm = data.base.vcm._replace(Delta=2.0 * data.base.vcm.Delta, P_int=np.array([0.05, 0.01]))
    best = data.base._replace(vcm=vcm)
    theta = np.asarray(space.encode(best))
    calls = {"eval": [], "curve": [], "before_after": [], "terms": [], "traj": [], "poly": []}
    currents = np.arange(15.0).reshape(5, 3)
    heldout = SimpleNamespace(current=currents, eta0=np.zeros((5, 3)))

    def eval_fn(th, d, batch):
        calls["eval"].append((np.asarray(th), d, batch))
        which = "default" if np.allclose(np.asarray(th), np.asarray(data.theta_ref)) else "tuned"
        losses, above, clearance = HELD[which]
        terms = {
            k: np.full(5, 0.1 * (i + 1) * (1 if which == "default" else 0.5))
            for i, k in enumerate(TERMS)
        }
        terms.update(above_surface_fraction=above, min_surface_clearance=clearance)
        return np.mean(losses) + 0.25, (losses, terms)

    def prepare(c, say):
        calls["cfg"] = c
        t = tcli._Tune(cfg, problem, eval_problem, data, "train", heldout, n_dev=n_dev)
        t.eval_fn, t.robust, t.trajectories = eval_fn, robust, "program"
        return t

    res = TuneResult(
        theta=theta, loss=6.0, history=[dict(h) for h in HISTORY], n_bad=1, aborted=False,
        reason=reason, evals=5,
    )  # fmt: skip
    monkeypatch.setattr(tcli, "_prepare", prepare)
    monkeypatch.setattr(
        tcli,
        "_train",
        lambda t, progress, say: (res, tcli._evaluate(t.eval_fn, data.theta_ref, data, heldout)),
    )

    def curve(history, p, title):
        calls["curve"].append((history, p, title))
        return p

    def trajectories(problem_, gains_list, batch, dt, n, run=None):
        calls["traj"].append((problem_, gains_list, batch, dt, n, run))
        xy = [np.full((n, 3, 2), 1.0 + k) for k in range(2)]
        return np.arange(4.0), [{"xy": x, "tag": k} for k, x in enumerate(xy)]

    def polyline(loop, batch, xy_before, xy_after):
        calls["poly"].append((loop, batch, xy_before, xy_after))
        return "polyline"

    def before_after(t_, tb, ta, cur, out, path_xy):
        calls["before_after"].append((t_, tb, ta, cur, out, path_xy))
        return [out / "p1.png", out / "p2.png"]

    def loss_terms(t_, tb, ta, terms, weights, actuators, p):
        calls["terms"].append((t_, tb, ta, terms, weights, actuators, p))
        return p

    monkeypatch.setattr(tcli, "plot_loss_curve", curve)
    monkeypatch.setattr(tcli, "_trajectories", trajectories)
    monkeypatch.setattr(tcli, "_path_polyline", polyline)
    monkeypatch.setattr(tcli, "plot_before_after", before_after)
    monkeypatch.setattr(tcli, "plot_loss_terms", loss_terms)
    return calls, best


def _flat(gains):
    return np.concatenate([np.ravel(x) for x in jax.tree.leaves(gains)])


def test_an_interrupted_tune_writes_its_best_gains_counts_and_held_out_numbers(
    setting, monkeypatch, tmp_path
):
    """Kills: after an interrupt, summary.json without ``interrupted`` / ``steps_planned`` (or
    a false flag), the before/after figures drawn (new compiles), the gains written not the
    best so far, the counts (iterations, rollouts = evaluations x training size, rejected
    steps), the training losses (the first step's, the best), the held-out numbers (the mean
    loss, its reduction in percent, the terms' means, the per-scenario median and maximum, the
    runs above the sea surface and the warning that says so), the wall times, the files and
    where they go, the messages."""
    from tuning import run as tcli

    path, cfg, problem, eval_problem, data = setting
    calls, best = _stand_in_tune(setting, monkeypatch, "interrupted")
    stream = io.StringIO()
    out = tmp_path / "a" / "out"  # parents made
    t0 = time.perf_counter()
    result = tcli.run_tune_config(path, out, progress=stream)
    elapsed = time.perf_counter() - t0
    assert calls["cfg"] == cfg and calls["cfg"] is not cfg  # parsed from the file
    names = ["gains.json", "history.json", "loss_curve.png", "summary.json"]
    assert result["files"] == [out / n for n in names]
    assert calls["curve"] == [(HISTORY, out / "loss_curve.png", "adam tuning")]
    assert calls["traj"] == calls["before_after"] == calls["terms"] == []  # stopped: no figures
    loop = problem.space.loop
    gains = json.loads((out / "gains.json").read_text())
    want = loop.gains_to_json(best)
    assert gains.keys() == want.keys()
    np.testing.assert_allclose(
        _flat(loop.gains_from_json(gains)), _flat(best), rtol=1e-12, atol=1e-11
    )
    hist = json.loads((out / "history.json").read_text())
    assert (out / "history.json").read_text().startswith('{\n "config"')  # indent=1
    assert hist == json.loads(json.dumps({
        "config": cfg.to_dict(), "labels": problem.space.labels(),
        "initial_gains": loop.gains_to_json(data.base), "iterations": HISTORY, "n_bad": 1,
        "aborted": False, "reason": "interrupted", "evals": 5, "rollouts": 20,
    }))  # fmt: skip
    s = json.loads((out / "summary.json").read_text())
    assert s == json.loads(json.dumps(result["summary"]))
    lb, la = np.mean(HELD["default"][0]) + 0.25, np.mean(HELD["tuned"][0]) + 0.25  # 4.25, 1.65
    assert (s["heldout_loss_before"], s["heldout_loss_after"]) == (lb, la)
    assert s["heldout_reduction_pct"] == pytest.approx(100.0 * 2.6 / 4.25, rel=1e-14)
    assert s["heldout_terms_before"] == {
        k: pytest.approx(0.1 * (i + 1)) for i, k in enumerate(TERMS)
    }
    assert s["heldout_terms_after"] == {
        k: pytest.approx(0.05 * (i + 1)) for i, k in enumerate(TERMS)
    }
    assert s["heldout_scenario_loss_before"] == {"median": 4.0, "max": 8.0}
    assert s["heldout_scenario_loss_after"] == {"median": 1.0, "max": 3.0}
    assert s["heldout_surface_before"] == {
        "n_above_surface": 2, "n": 5, "max_above_surface_fraction": 1.0,
        "min_surface_clearance_m": -0.3,
    }  # fmt: skip
    assert s["heldout_surface_after"] == {
        "n_above_surface": 0, "n": 5, "max_above_surface_fraction": 0.0,
        "min_surface_clearance_m": 0.1,
    }  # fmt: skip
    assert s["heldout_smooth_saturation"] is False
    assert (s["train_loss_before"], s["train_loss_after"]) == (9.0, 6.0)
    assert s["loop"] == "infante / vcm_integral on a line"
    assert s["initial_gains"] == problem.space.values(data.base)
    np.testing.assert_allclose(s["tuned_gains"]["Delta"], 10.0, rtol=1e-12)
    np.testing.assert_allclose(s["tuned_gains"]["P_G"], [1.0, 0.5, 0.5], rtol=1e-12)
    assert (s["iterations"], s["n_bad"], s["aborted"], s["reason"]) == (4, 1, False, "interrupted")
    assert (s["evals"], s["rollouts"], s["devices"]) == (5, 20, 3)
    assert s["tuning_wall_s"] == 6.25 and 0.0 <= s["total_wall_s"] <= elapsed
    assert s["interrupted"] is True and s["steps_planned"] == 1000
    assert "waves" not in s and "robust" not in s
    said = stream.getvalue().splitlines()
    assert said[0] == "stopped: interrupted; evaluating the tuned gains on the held-out batch ..."
    assert said[1] == (
        "warning: held-out, default gains: in 2 of 5 runs the vehicle was above the local sea "
        "surface (up to 100 % of a run, up to 0.30 m): outside the submerged model, whose losses "
        "describe no real vehicle there (summary.json heldout_surface_*); start the runs deeper"
    )
    assert said[2:] == [f"wrote 4 files to {out}"]  # no warning for the tuned gains
    # the held-out batch evaluated at the default gains, then at the best ones
    (th0, d0, b0), (th1, d1, b1) = calls["eval"]
    np.testing.assert_array_equal(th0, data.theta_ref)
    np.testing.assert_allclose(th1, problem.space.encode(best), rtol=1e-15)
    assert d0 is d1 is data and b0 is b1


@pytest.mark.parametrize("reason", ["steps", "converged"])  # after and before "interrupted"
def test_a_finished_tune_draws_its_figures_and_says_nothing_of_an_interrupt(
    setting, monkeypatch, tmp_path, reason
):
    """Kills: the before/after figures skipped after a run that was not interrupted, drawn for
    another count than ``min(plot_scenarios, held-out size)`` or with other gains, currents,
    terms, weights or actuator names, their files left out; ``interrupted`` in the summary of a
    finished run; a surface warning for runs that stayed below it; the files' order."""
    from tuning import run as tcli

    path, cfg, problem, eval_problem, data = setting
    calls, best = _stand_in_tune(setting, monkeypatch, reason, n_dev=1)
    result = tcli.run_tune_config("not read", tmp_path, progress=None, cfg=cfg)
    assert calls["cfg"] is cfg  # the config given, not the file parsed again
    s = result["summary"]
    assert "interrupted" not in s and "steps_planned" not in s and s["devices"] == 1
    names = ["gains.json", "history.json", "loss_curve.png", "p1.png", "p2.png"]
    names += ["before_after_loss_terms.png", "summary.json"]
    assert result["files"] == [tmp_path / n for n in names]
    ((prob, gains_list, batch, dt, n, run),) = calls["traj"]
    assert prob is eval_problem and n == 2 and run == "program" and dt is data.dt
    assert gains_list[0] is data.base
    np.testing.assert_allclose(_flat(gains_list[1]), _flat(best), rtol=1e-12, atol=1e-11)
    ((loop, b, xy_b, xy_a),) = calls["poly"]
    assert loop is problem.space.loop and b is batch
    assert float(xy_b[0, 0, 0]) == 1.0 and float(xy_a[0, 0, 0]) == 2.0
    ((t_, tb, ta, cur, out, path_xy),) = calls["before_after"]
    np.testing.assert_array_equal(t_, np.arange(4.0))
    assert (tb["tag"], ta["tag"], out, path_xy) == (0, 1, tmp_path, "polyline")
    np.testing.assert_array_equal(cur, np.arange(6.0).reshape(2, 3))  # the first two currents
    ((_, tb, ta, terms, weights, actuators, p),) = calls["terms"]
    assert (tb["tag"], ta["tag"], p) == (0, 1, tmp_path / "before_after_loss_terms.png")
    assert terms == (s["heldout_terms_before"], s["heldout_terms_after"])
    assert weights == {k: float(getattr(data.weights, k)) for k in TERMS}
    assert actuators == ("thrust", "rudder")


def test_other_processes_of_a_run_write_nothing_and_stay_silent(setting, monkeypatch, tmp_path):
    """Kills: a process other than 0 writing the outputs (or printing), process 0 not."""
    from tuning import run as tcli

    _stand_in_tune(setting, monkeypatch, "steps")
    monkeypatch.setattr(tcli.jax, "process_index", lambda: 1)
    stream = io.StringIO()
    assert tcli.run_tune_config(setting[0], tmp_path, progress=stream) == {
        "summary": None,
        "files": [],
    }
    assert stream.getvalue() == "" and list(tmp_path.iterdir()) == []


# ------------------------------------------------------------------ the command's pieces


def test_the_training_step_timing_message():
    """Kills: the compile time not the first step's wall time less the median of the later
    steps (floored at 0), the one-step message, the rejected steps' warning."""
    from types import SimpleNamespace

    from tuning import run as tcli

    def said(walls, n_bad=0):
        out = []
        hist = [{"wall_s": w} for w in walls]
        tcli._say_timing(SimpleNamespace(history=hist, n_bad=n_bad), out.append)
        return out

    # steps of 0.5, 1.0 and 4.0 s after the first: median 1.0
    assert said([3.0, 3.5, 4.5, 8.5]) == [
        "training step compiled and run once in 3.0 s (compiling ~2.0 s); then 1 s per step"
    ]
    assert said([2.25]) == [
        "training step compiled and run once in 2.2 s (compiling ~2.2 s); one step only"
    ]
    assert said([0.5, 5.0, 9.5], n_bad=2) == [
        "training step compiled and run once in 0.5 s (compiling ~0.0 s); then 4.5 s per step",
        "warning: 2 step(s) rejected for non-finite loss/gradient/update",
    ]
    assert said([]) == []


def test_the_realised_significant_height_of_each_sea():
    """Kills: ``4 sqrt(m0)`` with ``m0 = sum a_i^2 / 2`` changed (factor, sum, axis), the
    rounding to millimetres."""
    from types import SimpleNamespace

    from tuning import run as tcli

    a = np.array([[3.0, 4.0, 0.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0], [1e-3, 0.0, 0.0]])
    got = tcli._realised_hs(SimpleNamespace(sea=SimpleNamespace(amplitude=a)))
    # 4 sqrt(25 / 2) = 14.1421..., 4 sqrt(3 / 2) = 4.898979..., 0, 4 sqrt(5e-7) = 0.0028284
    assert got == [14.142, 4.899, 0.0, 0.003]
    assert all(type(h) is float for h in got)


def test_the_path_drawn_covers_the_runs_from_before_their_start_to_past_their_reach(monkeypatch):
    """Kills: the path's parameter range (5 before the first start, 5 after the last, plus
    twice the runs' largest north or east extent, not their extent across both), its 400
    points, the north/east columns."""
    from types import SimpleNamespace

    import jax.numpy as jnp

    from tuning import run as tcli

    def point(path, coeffs, w):  # a line with a parameter of its own: (w, -2 w, 7)
        assert (path, coeffs) == ("the loop's path", "the batch's path")
        return jnp.stack([w, -2.0 * w, 7.0 + 0.0 * w])

    monkeypatch.setattr(tcli.paths, "path_point", point)
    loop = SimpleNamespace(path="the loop's path")
    batch = SimpleNamespace(varpi0=np.array([3.0, -1.0, 2.0]), path="the batch's path")
    xy_b = np.zeros((2, 4, 2))
    xy_b[1, 2] = [6.0, -1.0]  # extent 6 north, 1 east (7 across both)
    xy_a = np.zeros((2, 4, 2))
    xy_a[0, 1] = [1.0, 2.0]  # extent 1 north, 2 east
    pts = tcli._path_polyline(loop, batch, xy_b, xy_a)
    w = np.linspace(-1.0 - 5.0, 3.0 + 5.0 + 2.0 * 6.0, 400)
    np.testing.assert_allclose(pts, np.stack([w, -2.0 * w], axis=1), rtol=1e-14, atol=1e-14)


def test_distribute_shards_a_batch_that_splits_evenly_over_the_devices(monkeypatch):
    """Kills: a one-device run, or a batch whose size (its first axis) does not split evenly
    over the devices, put on a mesh; a batch that does, not sharded along the scenarios (with
    the data and the start replicated). The mesh functions are stand-ins."""
    from types import SimpleNamespace

    from tuning import run as tcli

    data, theta = object(), np.zeros(2)
    odd = SimpleNamespace(eta0=np.zeros((3, 4)))  # 3 scenarios of 4 numbers
    got = tcli.distribute(odd, data, theta)  # one device
    assert got[0] is odd and got[1] is data and got[2] is theta
    monkeypatch.setattr(tcli.jax, "device_count", lambda: 2)
    monkeypatch.setattr(
        tcli,
        "distributed",
        SimpleNamespace(
            global_mesh=lambda axis: f"mesh of {axis}",
            replicate=lambda x, mesh: tuple((v, mesh) for v in x),
            shard_batch=lambda b, mesh, axes: (b, mesh, axes),
        ),
    )
    got = tcli.distribute(odd, data, theta)
    assert got[0] is odd and got[1] is data and got[2] is theta
    even = SimpleNamespace(eta0=np.zeros((4, 3)))
    got = tcli.distribute(even, data, theta)
    assert got == (
        (even, "mesh of scenarios", tcli.SCENARIO_AXES),
        (data, "mesh of scenarios"),
        (theta, "mesh of scenarios"),
    )


def test_build_reads_a_run_json_record_and_evaluates_the_held_out_batch_hard_clipped(
    setting, monkeypatch
):
    """Kills: a plain dict (``run.json``'s record of the config) not read as a config, the
    steps ``horizon / dt``, the held-out problem's saturation (``[heldout] smooth``, default
    hard-clipped) and its surface terms (without them no ``heldout_surface_*``), a held-out
    seed below the training seed refused (only an equal one is), the two batches' seeds and
    sizes. The scenario sampler is a stand-in: no batch is drawn."""
    from tuning import run as tcli

    _, cfg, _, _, _ = setting
    drawn = []
    monkeypatch.setattr(
        tcli, "sample_scenarios", lambda seed, n, spec, **kw: drawn.append((seed, n)) or (seed, n)
    )
    record = json.loads(json.dumps(cfg.to_dict()))
    record["train"]["seed"], record["heldout"]["seed"] = 7, 3
    problem, eval_problem, data, train, heldout = tcli.build(record)
    assert drawn == [(7, 4), (3, 5)] and (train, heldout) == ((7, 4), (3, 5))
    assert problem.num_steps == 10 and problem.smooth is True and problem.surface is False
    assert eval_problem.smooth is False and eval_problem.surface is True
    assert eval_problem.num_steps == 10 and eval_problem.space is problem.space
    assert float(data.dt) == 0.1 and data.weights.eps.dtype == np.float64
    record["heldout"]["smooth"] = True
    record["problem"]["horizon"] = 2.0
    problem, eval_problem, *_ = tcli.build(record)
    assert eval_problem.smooth is True and problem.num_steps == 20
    record["heldout"]["seed"] = 7
    with pytest.raises(ValueError, match=r"\[heldout\] seed: must differ from \[train\] seed"):
        tcli.build(record)


@pytest.mark.parametrize("devices, size, n_dev", [(1, 4, 1), (2, 4, 2), (2, 5, 1)])
def test_prepare_announces_the_run_starts_off_the_symmetry_and_tiles_a_sharded_batch(
    setting, monkeypatch, devices, size, n_dev
):
    """Kills: the device count of the training batch (all devices when its size splits
    evenly, else 1), the start (the default gains' encoding plus the symmetry break: not
    minus, not times), the announcement, a robust slot attached without ``[robust]``, a batch
    sharded (or not) without the gains tiled per scenario (or with). ``build``, the held-out
    sharding and ``distribute`` are stand-ins; the device count is set."""
    from types import SimpleNamespace

    from tuning import run as tcli

    _, cfg, problem, eval_problem, data = setting
    train = SimpleNamespace(eta0=np.zeros((size, 3)))
    sharded = SimpleNamespace(eta0=np.zeros((size, 3)))
    monkeypatch.setattr(tcli, "build", lambda c: (problem, eval_problem, data, train, "held"))
    monkeypatch.setattr(tcli, "shard_scenarios", lambda b: (f"{b} (on its devices)", None))
    monkeypatch.setattr(tcli.jax, "device_count", lambda: devices)
    got = []

    def distribute(tr, d, th):
        got.append((tr, d, th))
        return (sharded if n_dev > 1 else tr), f"{d} replicated", "start replicated"

    monkeypatch.setattr(tcli, "distribute", distribute)
    said = []
    t = tcli._prepare(cfg, said.append)
    assert said == [
        "tuning infante / vcm_integral on a line: 12 parameters (P_G, P_Phi, Delta, sigma, "
        "P_int), 4 training / 5 held-out scenarios, horizon 1 s, adam x 1000 steps (reverse "
        f"mode); training batch on {n_dev} device(s)"
    ]
    assert (t.n_dev, t.heldout, t.train, t.robust) == (n_dev, "held (on its devices)", train, None)
    ((tr, d, start),) = got
    assert tr is train and d is data
    split = np.asarray(problem.space.symmetry_break(data.base))  # the defaults' equal pairs
    assert np.count_nonzero(split) > 0
    np.testing.assert_allclose(start, np.asarray(data.theta_ref) + split, rtol=1e-15)
    assert (t.train_d, t.data_d, t.start) == (
        sharded if n_dev > 1 else train,
        f"{data} replicated",
        "start replicated",
    )
    assert t.sharded is (n_dev > 1)
    assert t.problem.tile_gains is (n_dev > 1) and t.eval_problem is eval_problem
    assert dataclasses.replace(t.problem, tile_gains=False) == problem


@pytest.mark.parametrize("extra, n_dev", [(2, 3), (1, 1)])
def test_prepare_with_a_robust_slot_counts_the_devices_of_the_extended_batch(
    setting, monkeypatch, extra, n_dev
):
    """Kills: the device count not taken again after ``[robust]`` extends the batch by its
    adversarial slot (4 + 2 scenarios on 3 devices: all 3; 4 + 1: one; before, 4 on 3: one),
    or taken from another axis than the scenarios'."""
    from types import SimpleNamespace

    import tuning.robust as robust
    from tuning import run as tcli

    _, cfg, problem, eval_problem, data = setting
    train = SimpleNamespace(eta0=np.zeros((4, 3)))
    extended = SimpleNamespace(eta0=np.zeros((4 + extra, 4)))
    monkeypatch.setattr(tcli, "build", lambda c: (problem, eval_problem, data, train, "held"))
    monkeypatch.setattr(tcli, "shard_scenarios", lambda b: (b, None))
    monkeypatch.setattr(tcli.jax, "device_count", lambda: 3)
    monkeypatch.setattr(tcli, "distribute", lambda tr, d, th: (tr, d, th))
    attached = []

    def attach(t, start, say, spec):
        attached.append((t.n_dev, spec))
        return "the search", extended

    monkeypatch.setattr(robust, "attach", attach)
    t = tcli._prepare(dataclasses.replace(cfg, robust="a section"), lambda m: None)
    assert attached == [(1, tcli.config_spec)] and t.robust == "the search"
    assert t.n_dev == n_dev and t.train_d is extended and t.sharded is False


def _tune_of(setting, **kw):
    from tuning import run as tcli

    _, cfg, problem, eval_problem, data = setting
    t = tcli._Tune(cfg, problem, eval_problem, data, "train", "held", **kw)
    t.train_d, t.data_d, t.start = "train (distributed)", "data (distributed)", "start"
    return t


@pytest.mark.parametrize("ran, sharded", [(3, False), (1000, True)])
def test_train_starts_its_tuner_as_configured_and_reports(setting, monkeypatch, ran, sharded):
    """Kills: the held-out evaluation before tuning at other gains than the defaults, the loss
    not the objective's first value, the program built in its thread not waited for, the
    hooks (the gains recorded per step, the stop poll, no refresh without ``[robust]``), the
    progress bar's total, label and warm-up, the bar left open after a run that stopped early
    (or closed after one that ran every step: the tuner's last step closes it), the messages
    (the time of the held-out evaluation, the sharded batch). The tuner and the programs are
    stand-ins."""
    import threading

    from tuning import run as tcli

    _, cfg, problem, eval_problem, data = setting
    t = _tune_of(setting, sharded=sharded)
    calls = {}
    waited = threading.Event()
    future = type("F", (), {"result": lambda self: waited.set()})()

    def training_step(loss_fn, opts, c, prob, start, args):
        calls["step"] = (loss_fn, opts, c, prob, start, args)
        return "step", future

    monkeypatch.setattr(tcli, "_training_step", training_step)
    monkeypatch.setattr(tcli, "_prebuild", lambda t_, th: calls.setdefault("prebuild", th))
    monkeypatch.setattr(
        tcli,
        "_evaluate",
        lambda fn, th, d, b: calls.setdefault("eval", (th, d, b)) and {"loss": 4.25},
    )
    monkeypatch.setattr(tcli, "objective", lambda th, d, s, p: (("loss", th, d, s, p), "aux"))

    def tuner(loss_fn, start, args, opts, hooks, step_fn):
        calls["tuner"] = (loss_fn, start, args, opts, hooks, step_fn)
        for k in range(ran):
            hooks.progress(k + 1, opts.steps, {"loss": 1.0})
        return type("R", (), {"history": [{"wall_s": 1.0}] * ran, "n_bad": 0})()

    monkeypatch.setattr(tcli, "run_gradient_tuner", tuner)
    stream = io.StringIO()
    said = []
    t0 = time.perf_counter()
    res, before = tcli._train(t, stream, said.append)
    elapsed = time.perf_counter() - t0
    assert before == {"loss": 4.25} and waited.is_set()
    assert calls["prebuild"] is data.theta_ref and calls["eval"] == (data.theta_ref, data, "held")
    loss_fn, opts, c, prob, start, args = calls["step"]
    assert loss_fn(1, 2, 3) == ("loss", 1, 2, 3, problem)  # the objective's first value
    assert c is cfg and prob is problem and start == "start"
    assert args == ("data (distributed)", "train (distributed)")
    assert (opts.optimizer, opts.steps) == ("adam", 1000)
    tl, tstart, targs, topts, hooks, step_fn = calls["tuner"]
    assert tl is loss_fn and tstart == "start" and targs == args and topts == opts
    assert step_fn == "step" and hooks.should_stop is tcli.stop_requested_everywhere
    assert hooks.refresh is None
    theta = data.theta_ref + 0.5
    assert hooks.on_step(3, theta, {}) == {"gains": problem.space.describe(theta, data.base)}
    bar = hooks.progress
    assert (bar.total, bar.label, bar.warmup, bar.stream) == (1000, "tune ", 1, stream)
    assert stream.getvalue().endswith("\n") and stream.getvalue().count("\n") == 1
    assert said[0] == (
        "compiling the held-out evaluation (5 rollouts x 10 steps) and evaluating the initial "
        "gains ..."
    )
    head, tail = said[1].split(" s incl. compiling); ")
    assert head.startswith("held-out loss before: 4.25 (")
    assert 0.0 <= float(head.rsplit("(", 1)[1]) <= elapsed + 0.05
    assert tail == (
        "compiling the training step (adam: loss and reverse-mode gradient through 4 rollouts "
        "x 10 steps) - the first step includes it ..."
    )
    assert ("training batch sharded over 1 devices" in said) is sharded
    assert said[-1].startswith("training step compiled and run once in 1.0 s")


def test_train_without_progress_has_no_bar_and_a_robust_tune_refreshes(setting, monkeypatch):
    """Kills: a bar drawn without a stream (or closed when there is none), the robust hook
    not installed with ``[robust]``."""
    import tuning.robust as robust
    from tuning import run as tcli

    t = _tune_of(setting, robust="the search")
    monkeypatch.setattr(tcli, "_training_step", lambda *a: ("step", None))
    monkeypatch.setattr(tcli, "_prebuild", lambda t_, th: None)
    monkeypatch.setattr(tcli, "_evaluate", lambda *a: {"loss": 1.0})
    monkeypatch.setattr(robust, "hook", lambda t_, say, dist: ("refresh", t_, dist))
    seen = {}

    def tuner(loss_fn, start, args, opts, hooks, step_fn):
        seen["hooks"] = hooks
        return type("R", (), {"history": [], "n_bad": 0})()

    monkeypatch.setattr(tcli, "run_gradient_tuner", tuner)
    tcli._train(t, None, lambda m: None)
    assert seen["hooks"].progress is None
    assert seen["hooks"].refresh == ("refresh", t, tcli.distribute)


@pytest.mark.parametrize("processes", [1, 2])
def test_the_training_step_is_built_in_a_thread_in_one_process_only(
    setting, monkeypatch, processes
):
    """Kills: the step's program key (the tune's config and the gains' tiling), the build in a
    thread skipped in a single process (or started in a multi-process run, where every process
    must build in step), the build waited for before returning (it overlaps the held-out
    evaluation), its input (the start as the tuner will hold it), its errors not swallowed
    (the first step reports them)."""
    import threading

    import tuning.optim as optim
    from tuning import run as tcli

    _, cfg, problem, _, _ = setting
    release, built = threading.Event(), []

    class Step:
        def prebuild(self, theta, args):
            release.wait(30)  # until the test lets it go (a mutant that waits: 30 s, then fails)
            built.append((theta, args))
            raise RuntimeError("reported by the first step instead")

    made = []
    monkeypatch.setattr(optim, "make_step", lambda *a: made.append(a) or Step())
    monkeypatch.setattr(tcli.jax, "process_count", lambda: processes)
    opts = optim.TunerOptions(optimizer="adam", steps=3)
    args = ("data", "batch")
    step, future = tcli._training_step("loss", opts, cfg, problem, [0.5, 1.5], args)
    assert isinstance(step, Step) and not built  # returned while the build still runs
    (a,) = made
    assert a[0] == "loss" and a[2:4] == ("adam", "reverse")
    assert a[4] == ("vcjax tune", cfg.to_dict(), False)
    if processes > 1:
        assert future is None
        return
    release.set()
    assert future.result() is None  # the error swallowed
    ((theta, got_args),) = built
    np.testing.assert_array_equal(theta, [0.5, 1.5])
    assert got_args is args
    tiled = dataclasses.replace(problem, tile_gains=True)
    tcli._training_step("loss", opts, cfg, tiled, [0.5], args)[1].result()
    assert made[-1][4] == ("vcjax tune", cfg.to_dict(), True)


def test_a_step_without_a_prebuild_builds_at_its_first_call(setting, monkeypatch):
    import tuning.optim as optim
    from tuning import run as tcli

    _, cfg, problem, _, _ = setting
    monkeypatch.setattr(optim, "make_step", lambda *a: "a plain step")
    opts = optim.TunerOptions(optimizer="adam", steps=3)
    assert tcli._training_step("loss", opts, cfg, problem, [0.5], ()) == ("a plain step", None)


@pytest.mark.parametrize("plot_scenarios, n_plot", [(2, 2), (9, 5), (0, 0)])
def test_prebuild_builds_the_held_out_evaluation_and_the_figures_programs_together(
    setting, monkeypatch, plot_scenarios, n_plot
):
    """Kills: the jobs built (their names, programs, keys, arguments: the held-out evaluation
    at the default gains; the figures' program for ``min(plot_scenarios, held-out size)``
    scenarios, none for 0), which built program each of ``eval_fn`` and ``trajectories``
    takes, and the build in a multi-process run (skipped there). The builder is a stand-in."""
    from tuning import run as tcli

    _, cfg, problem, eval_problem, data = setting
    cfg = dataclasses.replace(
        cfg, report=dataclasses.replace(cfg.report, plot_scenarios=plot_scenarios)
    )
    t = _tune_of(setting)
    t.cfg, t.eval_fn = cfg, "jitted evaluation"
    jobs_seen = []
    monkeypatch.setattr(tcli, "_trajectory_program", lambda p, b, n: (("fn", p, b, n), ("sub", n)))
    monkeypatch.setattr(tcli, "objective", lambda th, d, s, p: ("objective", th, d, s, p))
    monkeypatch.setattr(tcli.compiler, "jit", lambda fn: ("jit", fn))

    def build_all(jobs):
        jobs_seen.extend(jobs)
        return [(f"built {name}", "other") for name, *_ in jobs]

    monkeypatch.setattr(tcli.programs, "build_all", build_all)
    monkeypatch.setattr(tcli.programs, "for_arguments_like", lambda b, a, f: (b, a, f))
    tcli._prebuild(t, "theta0")
    static = ("vcjax tune", cfg.to_dict())
    name, evaluate, key, args = jobs_seen[0]
    assert (name, key, args) == ("tune:heldout", static, ("theta0", data, "held"))
    assert evaluate(1, 2, 3) == ("objective", 1, 2, 3, eval_problem)
    assert t.eval_fn == ("built tune:heldout", args, "jitted evaluation")
    if not n_plot:
        assert len(jobs_seen) == 1 and t.trajectories is None
        return
    fn = ("fn", eval_problem, "held", n_plot)
    assert jobs_seen[1] == (
        "tune:trajectories",
        fn,
        (*static, n_plot),
        (data.base, ("sub", n_plot), data.dt),
    )
    assert t.trajectories == ("built tune:trajectories", jobs_seen[1][3], ("jit", fn))
    t.eval_fn = t.trajectories = None
    monkeypatch.setattr(tcli.jax, "process_count", lambda: 2)
    tcli._prebuild(t, "theta0")
    assert len(jobs_seen) == 2 and t.eval_fn is None and t.trajectories is None


@pytest.mark.parametrize("lb, pct", [(0.5, 100.0 * (0.5 - 0.4) / 0.5), (0.0, None), (-0.5, None)])
def test_the_summary_of_a_run_without_steps_in_a_sea(setting, lb, pct):
    """Kills: the reduction in percent for a held-out loss that is not positive (none then),
    the first and last step's values read from an empty history, the total wall time, the
    seas' realised heights (training and held-out batches each) and their note."""
    from types import SimpleNamespace

    from tuning import run as tcli
    from tuning.optim import TuneResult

    _, _, problem, eval_problem, data = setting
    waves = {"hs": 1.0}
    cfg = SimpleNamespace(
        get=lambda k: waves if k == "waves" else None, train=SimpleNamespace(size=4)
    )
    sea = lambda a: SimpleNamespace(sea=SimpleNamespace(amplitude=np.array(a)))  # noqa: E731
    t = SimpleNamespace(
        problem=problem, eval_problem=eval_problem, data=data, cfg=cfg, n_dev=1,
        train=sea([[0.25, 0.0]]), heldout=sea([[0.5, 0.0], [0.0, 1.0]]),
    )  # fmt: skip
    res = TuneResult(data.theta_ref, float("nan"), [], 0, True, "aborted: 3 steps", 0)
    ev = lambda loss: {
        "loss": loss,
        "terms": {},
        "scenario_loss_median": 1.0,
        "scenario_loss_max": 2.0,
    }  # noqa: E731
    t0 = time.perf_counter()
    s = tcli._summary(t, res, ev(lb), ev(0.4), t0 - 100.0)
    elapsed = time.perf_counter() - t0
    assert s["heldout_reduction_pct"] == (None if pct is None else pytest.approx(pct, rel=1e-14))
    assert s["train_loss_before"] is None and s["tuning_wall_s"] == 0.0
    assert s["iterations"] == 0 and s["rollouts"] == 0 and s["aborted"] is True
    assert 100.0 <= s["total_wall_s"] <= 100.0 + elapsed
    assert "heldout_surface_before" not in s and "heldout_surface_after" not in s
    # 4 sqrt(a^2 / 2) = 2 sqrt(2) a
    assert s["waves"] == {
        "train_hs": [0.707],
        "heldout_hs": [1.414, 2.828],
        "note": "realised significant height 4 sqrt(m0) of each scenario's sea [m]; the "
        "held-out seas are drawn from other keys than the training seas",
    }


def test_the_figures_trajectories_are_the_first_scenarios_of_each_gains(monkeypatch):
    """Kills: the scenarios drawn (the batch's first ``n``, the shared fields left whole), the
    positions (north and east only), the cross-track error (the second component of ``eps``),
    the times (of the first scenario), one program run per gains. ``loops.simulate`` and the
    loop's signals are stand-ins: each scenario's signals are its own numbers."""
    from types import SimpleNamespace

    import jax.numpy as jnp

    from tuning import run as tcli
    from vcjax import loops

    S, n, N = 4, 3, 5
    batch = loops.Scenario(
        eta0=jnp.arange(S * 3.0).reshape(S, 3), nu0=None, current=None, u_d=None,
        varpi0=10.0 * jnp.arange(S * 1.0), path=jnp.array([7.0, 8.0]), plant=None,
        design=None, disturbance=None, sea=None, origin_depth=None, environment=None,
    )  # fmt: skip
    k = jnp.arange(N * 1.0)

    def signals(tr, s):
        x = tr.gains * (s.eta0[0] + k)  # per scenario and step: its own numbers
        return SimpleNamespace(
            pos=jnp.stack([x, x + 100.0, x + 200.0 + s.path[1]], axis=1),
            eps=jnp.stack([x + 0.25, x + 0.5], axis=1),
            u_err=x + 1.0, psi_err=x + 2.0, cmd_ratio=jnp.stack([x, -x], axis=1),
        )  # fmt: skip

    loop = SimpleNamespace(signals=signals)

    def simulate(loop_, gains, s, cfg, dt):
        assert loop_ is loop and cfg == "the rollout config"
        return SimpleNamespace(t=dt * jnp.arange(N + 1.0) + s.varpi0, gains=gains)

    monkeypatch.setattr(tcli.loops, "simulate", simulate)
    problem = SimpleNamespace(rollout_config=lambda: "the rollout config", loop=loop)
    t, out = tcli._trajectories(problem, [1.0, 2.0], batch, 0.5, n)
    np.testing.assert_array_equal(t, 0.5 * np.arange(N + 1.0))  # the first scenario's
    assert len(out) == 2
    for g, o in zip([1.0, 2.0], out, strict=True):
        x = g * (np.arange(S * 3.0).reshape(S, 3)[:n, :1] + np.arange(N * 1.0))
        np.testing.assert_array_equal(o["xy"], np.stack([x, x + 100.0], axis=-1))
        np.testing.assert_array_equal(o["e"], x + 0.5)
        np.testing.assert_array_equal(o["eps"], np.stack([x + 0.25, x + 0.5], axis=-1))
        np.testing.assert_array_equal(o["u_err"], x + 1.0)
        np.testing.assert_array_equal(o["psi_err"], x + 2.0)
        np.testing.assert_array_equal(o["cmd_ratio"], np.stack([x, -x], axis=-1))


# ------------------------------------------------------------------ the tuners' comparison


def _curve(points):
    """A run from ``(wall_s, rollouts, held-out loss)`` points: the best so far per point."""
    best = np.minimum.accumulate([h for _, _, h in points])
    return {
        "best_heldout": float(best[-1]),
        "first_step_s": points[0][0],
        "curve": [
            {"wall_s": t, "rollouts": n, "heldout_best": float(b)}
            for (t, n, _), b in zip(points, best, strict=True)
        ],
    }


def test_time_to_target_at_each_tolerance_and_the_ratios_of_reached_times():
    """Kills: the tolerances (1 % and 5 % above the best of any run; a loss exactly at the
    level reaches it; 1.00995 is within 1 %, 1.01005 is not), the ratio of a gradient tuner's
    time to a black-box tuner's (a quotient; ``None`` when either never got there, or the
    black-box one got there at once)."""
    level5 = 2.0 * (1 + 5.0 / 100)  # exactly the 5 % level above the best, 2.0
    runs = {
        "cold": {
            "lbfgs": _curve([(1.0, 8, 9.0), (3.0, 16, 2.01990), (5.0, 24, 2.0)]),
            "adam": _curve([(1.0, 8, 9.0), (4.0, 16, level5), (8.0, 24, 2.02010)]),
            "cmaes": _curve([(0.5, 40, 9.0), (6.0, 80, 2.0199)]),
            "random": _curve([(0.0, 10, 2.001)]),
        },
        "warm": {"lbfgs": _curve([(0.5, 8, 2.5)]), "bayes": _curve([(1.0, 8, 2.1)])},
    }
    s = report.time_to_target(runs)
    assert s["target"] == 2.0
    cold = s["table"]["cold"]
    assert cold["lbfgs"] == {
        "best_heldout": 2.0, "first_step_s": 1.0, "wall_s_to_1%": 3.0, "rollouts_to_1%": 16,
        "wall_s_to_5%": 3.0, "rollouts_to_5%": 16,
    }  # fmt: skip
    assert (cold["adam"]["wall_s_to_1%"], cold["adam"]["wall_s_to_5%"]) == (None, 4.0)
    assert cold["cmaes"]["wall_s_to_1%"] == 6.0 and cold["random"]["wall_s_to_1%"] == 0.0
    assert s["table"]["warm"]["lbfgs"]["wall_s_to_5%"] is None
    assert s["ratios_wall_s_to_1%"] == {
        "cold: lbfgs/cmaes at 1%": 0.5,
        "cold: lbfgs/random at 1%": None,  # reached at once: no ratio
        "cold: adam/cmaes at 1%": None,
        "cold: adam/random at 1%": None,
        "warm: lbfgs/bayes at 1%": None,
    }
    custom = report.time_to_target(runs, (1.0, 25.0), gradient=("adam",), blackbox=("cmaes",))
    assert custom["table"]["cold"]["adam"]["wall_s_to_25%"] == 4.0
    assert custom["ratios_wall_s_to_1%"] == {"cold: adam/cmaes at 1%": None}
    # the ratios are at 1 % whatever the table's tolerances (a KeyError without the 1 % column)
    only5 = report.time_to_target(runs, (5.0,), gradient=("lbfgs",), blackbox=("cmaes",))
    assert "wall_s_to_1%" not in only5["table"]["cold"]["lbfgs"]
    assert only5["ratios_wall_s_to_1%"] == {"cold: lbfgs/cmaes at 1%": 0.5}
