"""A smoke test per figure function of :mod:`vcjax.plots`: each is called on small real data (a
short run of its experiment, a tiny sweep) and must write a non-empty PNG whose axes carry the
expected labels. The figures are caught as they are saved (:func:`vcjax.plots.save`), so their
axes are read from the figure objects themselves, not from the pixels."""

from __future__ import annotations

import os
from pathlib import Path

import jax
import pytest

from vcjax import experiments, plots, sweep
from vcjax.plots import arm as plots_arm
from vcjax.plots import remus100 as plots_remus100
from vcjax.plots import sim2 as plots_sim2
from vcjax.plots import sweep as plots_sweep

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def drawn(monkeypatch):
    """``{file name: [(xlabel, ylabel, title) of each visible axes]}`` of every figure saved
    while the test runs (the real :func:`vcjax.plots.save` still writes it)."""
    figures: dict[str, list[tuple[str, str, str]]] = {}
    real = plots.save

    def save(fig, path):
        axes = [a for a in fig.axes if a.get_visible()]
        labels = [(a.get_xlabel(), a.get_ylabel(), a.get_title()) for a in axes]
        title = fig._suptitle.get_text() if fig._suptitle is not None else ""
        figures[Path(path).name] = labels + [("", "", title)]
        return real(fig, path)

    monkeypatch.setattr(plots, "save", save)  # vcjax.plots.sim1 calls it as plots.save
    for mod in (plots_arm, plots_remus100, plots_sim2, plots_sweep):
        monkeypatch.setattr(mod, "save", save)
    return figures


def _check(files, drawn, expected: dict[str, set[str]]):
    """Every file a non-empty PNG; each figure has axes, and the labels ``expected`` names."""
    assert {Path(f).name for f in files} == set(expected)
    for f in files:
        f = Path(f)
        assert f.stat().st_size > 1000 and f.read_bytes()[:8] == PNG, f
        labels = drawn[f.name]
        assert len(labels) >= 2, f  # at least one axes besides the figure's title
        text = {s for row in labels for s in row if s}
        missing = expected[f.name] - text
        assert not missing, (f.name, missing, text)


def _run(name: str, variant: str, horizon: float, dt: float):
    """A short run of one variant of an experiment: its outcome and setup."""
    exp = experiments.get(name)
    setup = exp.setup(horizon=horizon, dt=dt)
    traj = jax.device_get(exp.simulate(variant, setup))
    return exp.outcome(variant, setup, traj), setup


def test_sim1_figures(tmp_path, drawn):
    from vcjax.plots.sim1 import sim1_figures

    run, _ = _run("sim1", "vcm_integral", 2.0, 0.1)
    files = sim1_figures({"vcm_integral": run.traj}, run.scenario, tmp_path)
    xy = {"y (east) [m]", "x (north) [m]"}
    _check(
        files,
        drawn,
        {
            "sim1_paths.png": xy | {"the approach (same scale on both axes)"},
            "sim1_speed_heading.png": {"t [s]", "u [m/s]", "heading error ψ̃ [deg]"},
            "sim1_controls.png": {"t [s]", "rudder δ [deg]", "thrust τ_u [N]"},
            "sim1_errors.png": {"t [s]", "along-track s [m]", "cross-track e [m]"},
        },
    )


@pytest.mark.slow  # 4 s; test_sim2 draws them
def test_sim2_figures(tmp_path, drawn):
    from vcjax.plots.sim2 import sim2_figures

    run, _ = _run("sim2", "underactuated", 1.0, 0.1)
    files = sim2_figures({"underactuated": run.traj}, run.scenario, run.loop.path, tmp_path)
    xy = {"y (east) [m]", "x (north) [m]"}
    _check(
        files,
        drawn,
        {
            "sim2_path_3d.png": {"Simulation 2: ODIN-class AUV on the helix"},
            "sim2_horizontal.png": xy,
            "sim2_errors.png": {"|p - p_p(w)| [m]", "t [s]"},
            "sim2_path_errors.png": {"along-track s [m]", "cross-track e [m]", "depth error [m]"},
            "sim2_thrusters.png": {"t [s]", "thrusters (underactuated)"},
        },
    )


@pytest.mark.slow  # 7 s; the REMUS 100 experiment's tests draw them
def test_remus100_figures(tmp_path, drawn):
    from vcjax.experiments.remus100 import LABELS
    from vcjax.plots.remus100 import remus100_figures

    run, _ = _run("remus100", "vcm3d_ilos", 1.0, 0.1)
    files = remus100_figures(
        {"vcm3d_ilos": run.traj}, run.loop.path, run.scenario.path, tmp_path, LABELS
    )
    _check(
        files,
        drawn,
        {
            "remus100_path3d.png": {"east [m]", "north [m]"},
            "remus100_plan.png": {"east [m]", "north [m]", "plan view"},
            "remus100_errors.png": {"t [s]", "path-frame errors at each law's path particle"},
            "remus100_actuators.png": {"t [s]", "actuators (limits dotted)"},
        },
    )


def test_arm_figure(tmp_path, drawn):
    import numpy as np

    from vcjax.plots.arm import arm_figure

    run, _ = _run("arm", "vcm", 0.2, 2e-3)
    sig = run.loop.signals(run.traj, run.scenario)
    sc, tr = run.scenario, run.traj
    center, radius = np.asarray(sc.path.center)[:2], float(sc.path.radius)
    f = arm_figure(
        tr.t,
        np.asarray(sig.pos)[:, :2],
        tr.aux.Phi,
        np.asarray(sig.eps)[:, 1],
        tr.u,
        run.gains.P_Phi,
        center,
        radius,
        tmp_path / "arm.png",
    )
    _check(
        [f],
        drawn,
        {
            "arm.png": {
                "end-effector path",
                "constraint violation vs. the exact decay (14)",
                "joint torque [N m]",
            }
        },
    )


SWEEP = """
[scenario]
vehicle = "odin"
[sweep]
num_scenarios = 4
chunk_size = 4
[simulation]
horizon = 1.0
dt = 0.1
timing = "sampled"
[current]
speed = [0.0, 0.3]
[waves]
hs = [0.5, 1.5]
tp = 8.0
origin_depth = [105.0, 110.0]
[output]
record_points = 5
"""


@pytest.mark.slow  # 16 s; the sweep tests draw the figures too
def test_sweep_figures(tmp_path, drawn):
    from vcjax.plots.sweep import sweep_figures

    cfg = tmp_path / "s.toml"
    cfg.write_text(SWEEP)
    spec, _ = sweep.load_config(cfg)
    result = sweep.run_sweep(spec, progress=False)
    files = sweep_figures(result, tmp_path / "figures")
    _check(
        files,
        drawn,
        {
            "sweep_error_vs_current.png": {
                "mean current speed [m/s]",
                "current direction (towards, from north) [deg]",
                "steady-state mean |e| [m] (last 20 %)",
            },
            "sweep_metrics.png": {"steady-state |e| [m]", "max |e| [m]", "IAE of e [m s]"},
            "sweep_error_vs_waves.png": {
                "significant wave height Hs [m]",
                "RMS cross-track error [m]",
                "RMS depth error [m]",
                "origin_depth: depth of the NED origin below the surface [m]",
            },
            "sweep_envelopes.png": {
                "cross-track error e [m]",
                "t [s]",
                "vcm (4 runs)",  # ODIN: the variants' names (equation numbers on INFANTE only)
                "vcm_full (4 runs)",
            },
            "sweep_paths.png": {
                "x (north) [m]",
                "y (east) [m]",
                "vcm_full: 4 paths (black: diverged)",
            },
        },
    )


def test_sweep_labels_carry_the_papers_equations_only_on_the_papers_vehicle():
    """The engine's ``vcm`` variant is labelled "VCM (31)/(38)" on INFANTE, the paper's vehicle;
    on any other vehicle (a user's skiff, ODIN) the paper's equation numbers would be wrong."""
    from types import SimpleNamespace

    from vcjax.plots.sweep import _style

    def result(vehicle):
        return SimpleNamespace(spec=SimpleNamespace(choice=SimpleNamespace(vehicle=vehicle)))

    assert _style("vcm", result("infante"))["label"] == "VCM (31)/(38)"
    assert _style("vcm", result("skiff"))["label"] == "vcm"
    assert _style("vcm", result("skiff"))["color"] == _style("vcm", result("infante"))["color"]
    assert _style("mine", result("skiff"))["label"] == "mine"


def _plain_sweep_result(n: int = 12, points: int = 20):
    """A sweep result of plain data (what the figures read), no sweep run: INFANTE-class
    variants, one diverged run, traces of ``points`` samples."""
    from types import SimpleNamespace

    import numpy as np

    rng = np.random.default_rng(0)
    keys = ("ss_abs_e", "ss_abs_u_err", "iae_e", "max_abs_e", "max_abs_rudder_deg")
    metrics, traces = {}, {}
    for v in ("vcm", "ilos"):
        m = {k: rng.uniform(0.01, 1.0, n) for k in keys}
        m["sat_fraction"] = rng.uniform(0.0, 0.2, n)
        m["diverged"] = np.arange(n) == 3
        metrics[v] = m
        xy = np.cumsum(rng.normal(0.0, 1.0, (n, points, 2)), axis=1).astype(np.float32)
        traces[v] = {"e": rng.normal(0.0, 0.5, (n, points)).astype(np.float32), "xy": xy}
    return SimpleNamespace(
        spec=SimpleNamespace(choice=SimpleNamespace(vehicle="infante", path=None), tail=0.2),
        metrics=metrics,
        traces=traces,
        scenarios={
            "current_speed": rng.uniform(0.0, 1.0, n),
            "current_direction": rng.uniform(0.0, 6.28, n),
        },
        trace_t=np.linspace(0.0, 10.0, points),
    )


def _drawn_here_fails(monkeypatch):
    """The two figures a helper draws raise when drawn in this process (the helper's process
    has its own module, unpatched)."""

    def here(*a, **k):
        raise AssertionError("drawn in this process, not by the helper")

    monkeypatch.setattr(plots_sweep, "_metric_boxes", here)
    monkeypatch.setattr(plots_sweep, "_paths", here)


def test_a_figure_helper_draws_the_same_files_in_its_own_process(tmp_path, monkeypatch):
    """``sweep_figures(..., helper=FigureHelper())`` (the CLI's sweep): the metrics' and paths'
    figures are drawn by the helper's process (drawing them here would fail), the files are
    the same, byte for byte, as drawn here alone, and listed in the same order."""
    from vcjax.plots.helper import FigureHelper

    result = _plain_sweep_result()
    alone = plots_sweep.sweep_figures(result, tmp_path / "alone")
    with FigureHelper() as helper, monkeypatch.context() as m:
        _drawn_here_fails(m)
        helped = plots_sweep.sweep_figures(result, tmp_path / "helped", helper=helper)
    assert (
        [p.name for p in helped]
        == [p.name for p in alone]
        == [
            "sweep_error_vs_current.png",
            "sweep_metrics.png",
            "sweep_envelopes.png",
            "sweep_paths.png",
        ]
    )
    for a, b in zip(alone, helped, strict=True):
        assert b.parent == tmp_path / "helped" and a.read_bytes() == b.read_bytes(), b.name


def test_what_a_figure_helper_fails_to_draw_is_drawn_here(tmp_path):
    """A helper that cannot load its modules answers with errors, and a closed one takes no
    work: either way every figure is drawn here, the same files."""
    from vcjax.plots.helper import FigureHelper

    result = _plain_sweep_result()
    alone = plots_sweep.sweep_figures(result, tmp_path / "alone")
    with FigureHelper(modules=("vcjax.plots.no_such_module",)) as broken:
        got = plots_sweep.sweep_figures(result, tmp_path / "broken", helper=broken)
    closed = FigureHelper()
    closed.close()
    assert not closed.submit([("vcjax.plots.sweep", "_metric_boxes", ())])
    again = plots_sweep.sweep_figures(result, tmp_path / "closed", helper=closed)
    for a, b, c in zip(alone, got, again, strict=True):
        assert a.read_bytes() == b.read_bytes() == c.read_bytes()


def test_the_figure_helper_is_wanted_on_two_cores_unless_turned_off():
    from vcjax.plots import helper

    for off in ("0", "off", "False", " no "):
        assert not helper.wanted({helper.ENV: off})
    assert helper.wanted({}) == (len(os.sched_getaffinity(0)) >= 2)


def test_a_silent_figure_helper_is_given_up_after_its_timeout(tmp_path):
    """A helper that never answers (here: asked to draw while its process is stopped) does not
    hold the command: ``result`` gives up after its timeout, and asks nothing more."""
    import signal

    from vcjax.plots.helper import FigureHelper

    helper = FigureHelper()
    try:
        helper._proc.send_signal(signal.SIGSTOP)
        view = plots_sweep._plain(_plain_sweep_result())
        assert helper.submit([("vcjax.plots.sweep", "_metric_boxes", (view, tmp_path))])
        assert helper.result(timeout=1.0) is None
        assert helper.result(timeout=1.0) is None  # nothing pending any more
    finally:
        helper._proc.send_signal(signal.SIGCONT)
        helper.close()
    assert helper._proc.poll() is not None
