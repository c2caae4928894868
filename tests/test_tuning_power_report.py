"""Tests that kill the survivors of a mutation run of the tuner's figures and tables
(``tuning/report.py``; issue 31, item 8; docs/development/testing.md, "Mutation testing"),
beyond those of ``tests/test_tuning_power_run.py``: the figures draw without a warning
(matplotlib turns a grid asked off but given line properties back on, with a warning). The
figures are built from small NumPy arrays and read back before they would be written (no
layout pass, no file). Each test names the bugs it kills.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from tuning import report


@pytest.fixture
def saved(monkeypatch):
    """``tuning.report``'s ``savefig_atomic`` records ``(fig, path)`` instead of writing; no
    layout pass (it moves no data)."""
    from matplotlib.figure import Figure

    monkeypatch.setattr(Figure, "tight_layout", lambda self, *a, **kw: None)
    out = []
    monkeypatch.setattr(report, "savefig_atomic", lambda fig, path, **kw: out.append((fig, path)))
    return out


def _gridded(ax, axis):
    return all(g.get_visible() for g in getattr(ax, f"{axis}axis").get_gridlines())


def test_the_figures_draw_without_a_warning_with_their_grids_on(saved, tmp_path):
    """Kills: a grid asked off (``grid(False, alpha=...)``: matplotlib draws it anyway, with a
    ``UserWarning`` printed in the middle of a tune's output) in the loss curve, both
    before/after figures and every panel of the loss-terms figure; and a grid off."""
    rng = np.random.default_rng(0)
    history = [
        {"iter": 0, "loss": 2.0, "grad_norm": 1.0, "ok": True},
        {"iter": 1, "loss": None, "grad_norm": None, "ok": False},
    ]
    S, N, A = 1, 3, 2
    t = np.arange(N + 1.0)
    runs = [{"xy": rng.normal(size=(S, N, 2)), "e": rng.normal(size=(S, N))} for _ in (0, 1)]
    signals = [
        {
            "eps": rng.normal(size=(S, N, 2)),
            "u_err": rng.normal(size=(S, N)),
            "psi_err": rng.normal(size=(S, N)),
            "cmd_ratio": rng.normal(size=(S, N, A)),
        }
        for _ in (0, 1)
    ]
    terms = ({"a": 0.5}, {"a": 0.25})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report.plot_loss_curve(history, tmp_path / "c.png")
        report.plot_before_after(t, *runs, np.zeros((S, 2)), tmp_path)
        report.plot_loss_terms(t, *signals, terms, {"a": 1.0}, None, tmp_path / "l.png")
    curve, paths, cross, loss_terms = (fig for fig, _ in saved)
    for ax in curve.axes:  # both axes, major and minor ticks (log scale)
        assert _gridded(ax, "x") and _gridded(ax, "y")
    for fig in (paths, cross):
        (ax,) = fig.axes
        assert _gridded(ax, "x") and _gridded(ax, "y")
    panels = [ax for ax in loss_terms.axes if ax.get_visible()]
    assert len(panels) == 3 + A + 1
    for ax in panels[:-1]:
        assert _gridded(ax, "x") and _gridded(ax, "y")
    assert _gridded(panels[-1], "y") and not _gridded(panels[-1], "x")  # the bars: y only
